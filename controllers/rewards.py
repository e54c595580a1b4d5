"""An agent's reward on the window the harness scores.

:func:`controllers.episode_metrics` scores an episode by the common quadratic
cost averaged from :data:`controllers.harness.SCORED_FROM_S` (100 s) on, and
counts an episode that leaves the attitude bound as a failure whenever that
happens. An agent trained on the env's whole-episode return is trained on
something else: on the slew task the first 100 s (the slew and its settling)
hold most of the return, and what makes a slew fast (high gains) is not what
holds the spacecraft still afterwards (gains that do not pass the sensor noise
on to the torque). :class:`ScoredWindowReward` gives the agent the reward of
the scored window alone, with the crash penalty wherever it falls.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym

from controllers.harness import SCORED_FROM_S

__all__ = ["ScoredWindowReward", "check_window_start"]


def check_window_start(start_s: float, name: str = "start_s") -> float:
    """Validate the start of a rewarded window: a finite time >= 0 s.

    Parameters
    ----------
    start_s : float
        Start of the window, s.
    name : str
        The argument's name in the error message.

    Returns
    -------
    float
        ``start_s`` as a float.

    Raises
    ------
    ValueError
        If ``start_s`` is not a finite number >= 0 (a bool is not a number here).
    """
    if isinstance(start_s, bool) or not isinstance(start_s, int | float) \
            or not math.isfinite(start_s) or start_s < 0:
        raise ValueError(f"{name} must be a finite time >= 0 s, got {start_s!r}")
    return float(start_s)


class ScoredWindowReward(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Reward the steps the harness scores, and a crash whenever it comes.

    A step's reward is the env's (minus its stage cost, with ``reward="cost"``)
    when the step ends at or after ``start_s``, and 0 before; the step that
    leaves the attitude bound (``terminated``) keeps its reward, the env's
    termination penalty included, at any time. Put it inside
    :class:`spacecraft_env.ActionRepeat` (it reads each env step's
    ``info["time"]``).

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment (or a wrapper of one) whose ``info`` carries
        ``"time"`` (s).
    start_s : float
        Start of the rewarded window, s (default :data:`SCORED_FROM_S`, the
        harness's 100 s).

    Raises
    ------
    ValueError
        If ``start_s`` is negative or not finite.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import spacecraft_env
    >>> from controllers import ScoredWindowReward
    >>> env = ScoredWindowReward(gym.make("FlexibleSpacecraft-v2", reward="cost"))
    >>> _ = env.reset(seed=0)
    >>> env.step(np.zeros(3, dtype=np.float32))[1]     # t = 0.1 s: not scored
    0.0
    """

    def __init__(self, env: gym.Env, start_s: float = SCORED_FROM_S) -> None:
        self.start_s = check_window_start(start_s)
        gym.utils.RecordConstructorArgs.__init__(self, start_s=start_s)
        gym.Wrapper.__init__(self, env)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """One env step; its reward if it ends in the window or leaves the bound, else 0.

        Returns
        -------
        tuple
            The env's (observation, reward, terminated, truncated, info), the reward
            replaced as above.
        """
        obs, reward, terminated, truncated, info = self.env.step(action)
        # the env's clock is k * dt: a step that ends at start_s is in the window
        if not terminated and info["time"] < self.start_s - 1e-9:
            reward = 0.0
        return obs, reward, terminated, truncated, info
