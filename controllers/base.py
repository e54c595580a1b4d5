"""One interface for every controller and for trained RL policies.

The closed-loop harness calls ``reset(seed)`` at the start of an episode and
``act(obs, info)`` every step; ``predict`` makes a controller look like a
stable-baselines3 policy (``model.predict(obs)``), and
:class:`PolicyController` makes an SB3 model look like a controller, so the
harness runs LQR designs and RL agents alike.
"""

from __future__ import annotations

import copy
import zlib
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

__all__ = ["PADDLE_ANGLE", "Controller", "PolicyController", "episode_seed"]

#: The env's ``info`` key of the paddle drive's encoder (rad): what a scheduled
#: design or a scheduled identifier reads.
PADDLE_ANGLE = "paddle_angle"


def episode_seed(first_observation: np.ndarray) -> int:
    """The seed of an episode started through :meth:`Controller.predict`.

    A function of the episode's first observation alone (CRC-32 of its float32
    bytes, the dtype the envs observe in), so an episode's dither does not depend
    on where it runs: env ``i`` of a batch, the same env alone, the first or the
    tenth episode of a stream all get the same seed for the same start.

    Parameters
    ----------
    first_observation : array_like
        The observation ``reset`` returned.

    Returns
    -------
    int
        A seed in [0, 2^32).
    """
    obs = np.ascontiguousarray(first_observation, dtype=np.float32)
    return zlib.crc32(obs.tobytes())


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
        """The action for observation ``obs``.

        Parameters
        ----------
        obs : (obs_dim,) ndarray
            The env's observation, in its layout (``env.unwrapped.observation_layout``).
        info : dict, optional
            The env's last ``info`` (the applied torque, the time, the drive angle);
            controllers that read privileged entries (the oracles) raise without it.

        Returns
        -------
        (3,) ndarray of float32
            Normalized torque per body axis, in [-1, 1] (times ``max_torque``: N m).
        """

    def predict(self, observation: np.ndarray, state: Any = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """SB3-compatible entry point: ``(action, state)``.

        Everything comes from the observation (a controller that needs the
        env's privileged ``info`` raises without it; an adaptive LQG whose
        identifier follows the paddle drive gets no drive angle and says so,
        :class:`controllers.ScheduleWarning`). A single observation
        (1-D) is acted on by this controller. A batch ``(n_envs, obs_dim)``
        is acted on by one copy of the controller per env, as SB3's recurrent
        policies keep one hidden state per env: the copies (deep copies of
        this controller when the batch first arrives, each with its own
        identifier and filter) are returned as ``state`` and kept here too,
        so callers that pass ``state`` back and callers that do not both
        work. ``episode_start[i]`` resets env i's copy.

        Episodes started here are seeded (their dither and any other
        randomness) from their first observation (:func:`episode_seed`): an
        evaluation through ``predict`` (e.g. SB3's ``evaluate_policy``) is
        reproducible, and env i of a batch scores what the same env scores
        alone (test).

        Parameters
        ----------
        observation : (obs_dim,) or (n_envs, obs_dim) ndarray
            One observation, or one per env of a vectorized env.
        state : object, optional
            The per-env copies a previous batched call returned (None: made here).
        episode_start : (n_envs,) array_like of bool, optional
            Which envs start an episode with this observation (their copies are reset).
        deterministic : bool
            Ignored (the controllers are deterministic given their seed); SB3's
            signature.

        Returns
        -------
        action : (3,) or (n_envs, 3) ndarray
            Normalized torques in [-1, 1].
        state : object
            ``state`` unchanged for a single observation; the per-env copies for a
            batch.
        """
        obs = np.asarray(observation)
        if obs.ndim == 1:
            if episode_start is not None and np.any(episode_start):
                self.reset(seed=episode_seed(obs))
            return self.act(obs), state
        if obs.ndim != 2:
            raise ValueError(f"observation must be (obs_dim,) or (n_envs, obs_dim), "
                             f"got shape {obs.shape}")
        n = obs.shape[0]
        starts = np.zeros(n, dtype=bool) if episode_start is None else \
            np.broadcast_to(np.asarray(episode_start, dtype=bool).reshape(-1), (n,))
        copies = state if isinstance(state, _PerEnv) and len(state) == n else self._per_env(n)
        for i in np.flatnonzero(starts):
            copies[i].reset(seed=episode_seed(obs[i]))
        actions = np.stack([c.act(o) for c, o in zip(copies, obs, strict=True)])
        return actions, copies

    def _per_env(self, n: int) -> _PerEnv:
        """This controller's per-env copies for a batch of ``n`` (made on first use)."""
        held = self.__dict__.get("_batch")
        if held is None or len(held) != n:
            held = _PerEnv([copy.deepcopy(self) for _ in range(n)])
            self.__dict__["_batch"] = held
        return held

    def __deepcopy__(self, memo: dict) -> Controller:
        clone = object.__new__(type(self))
        memo[id(self)] = clone
        env = self.__dict__.get("env")
        if env is not None:                     # the env is what we control, not our state
            memo.setdefault(id(env), env)
        for key, value in self.__dict__.items():
            if key != "_batch":
                clone.__dict__[key] = copy.deepcopy(value, memo)
        return clone


class _PerEnv(list):
    """Per-env controller copies: the ``state`` that batched ``predict`` returns."""


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
