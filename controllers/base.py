"""One interface for every controller and for trained RL policies.

The closed-loop harness calls ``reset(seed)`` at the start of an episode and
``act(obs, info)`` every step; ``predict`` makes a controller look like a
stable-baselines3 policy (``model.predict(obs)``), and
:class:`PolicyController` makes an SB3 model look like a controller, so the
harness runs LQR designs and RL agents alike.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

__all__ = ["Controller", "PolicyController"]


class Controller(ABC):
    """Base class: maps an observation (and the env's ``info``) to an action.

    Actions are normalized torques in [-1, 1] (the environments' action
    space); subclasses that design in N m divide by ``max_torque``.
    """

    #: Short name used in tables and plots.
    name = "controller"

    def reset(self, seed: int | None = None) -> None:  # noqa: B027  (optional hook)
        """Start of an episode: clear internal state; ``seed`` seeds any dither."""

    @abstractmethod
    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        """Action for observation ``obs``; ``info`` is the env's last info dict."""

    def predict(self, observation: np.ndarray, state: Any = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """SB3-compatible entry point: ``(action, state)``.

        A batch of observations (2-D) is handled row by row; ``episode_start``
        resets the controller where it is true.
        """
        obs = np.asarray(observation)
        if obs.ndim == 2:
            if episode_start is not None and np.any(episode_start):
                self.reset()
            return np.stack([self.act(o) for o in obs]), state
        if episode_start is not None and np.any(episode_start):
            self.reset()
        return self.act(obs), state


class PolicyController(Controller):
    """Wrap a trained policy with an SB3 ``predict`` (e.g. a PPO or SAC model).

    Parameters
    ----------
    policy : object
        Anything with ``predict(obs, deterministic=True) -> (action, state)``.
    name : str
        Label for tables.
    """

    def __init__(self, policy: Any, name: str = "policy") -> None:
        if not callable(getattr(policy, "predict", None)):
            raise TypeError("policy must have a predict(obs, deterministic=True) method")
        self.policy = policy
        self.name = name

    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        action, _ = self.policy.predict(obs, deterministic=True)
        return np.asarray(action, dtype=np.float32)
