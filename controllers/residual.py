"""Residual RL: an agent's action corrects a model-based controller's.

:class:`ResidualControl` puts a controller (by default the self-tuning
:class:`controllers.adaptive.AdaptiveLQG`, which runs the online
identifier) inside the environment. At every env step the controller acts
on the current observation and the agent's action, scaled by ``scale``, is
added to it:

    u_k = clip(u_base(y_0..y_k) + scale * clip(a_k, -1, 1), -1, 1)

so the agent starts from the controller's performance and learns what the
law misses, instead of learning attitude control from scratch (residual
policy learning, Silver et al. 2018; Johannink et al. 2019). This is the
second way the identifier serves an agent, beside
:class:`controllers.features.IdentifiedModelFeatures`: through the
controller it feeds. The base controller learns from the torque the env
reports as applied (``info["torque"]``), residual included.

Wrapper order: ``ActionRepeat(ResidualControl(env), repeat)``. Inside
:class:`spacecraft_env.ActionRepeat` the base controller still acts every
sample while the agent's correction is held for ``repeat`` samples.
"""

from __future__ import annotations

import copy
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike

from controllers.adaptive import AdaptiveLQG
from controllers.base import Controller
from controllers.loop_identifiers import fast_identifier

__all__ = ["BaseRelativeReward", "ResidualControl", "ResidualObservations"]

#: Seeds of the base controller's episodes (its excitation) are drawn below this.
_SEED_BOUND = 2**31
#: Bound of the channels :class:`ResidualObservations` appends (physical units: rad,
#: normalized torque, the base's model coordinates; all far inside it).
_EXTRA_BOUND = 100.0


class ResidualControl(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """The agent's action is added, scaled, to a controller's action.

    Observation and action spaces are the env's. ``info`` gains
    ``"base_action"`` (the controller's action) and ``"residual_action"``
    (what was added to it after saturation: applied minus base), both
    normalized torques, (3,).

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment (the controller's observation layout).
    controller : Controller, optional
        The base law, built for ``env``. Default
        :class:`controllers.adaptive.AdaptiveLQG` on
        :func:`controllers.fast_identifier` (the structured recursive
        identifier: the loop's default, the drive-scheduled fit, computes
        11-32 s per 250 s episode, more than training can pay).
    scale : float
        Authority of the agent, as a fraction of full torque: an agent
        action of 1 adds ``scale * max_torque`` (default 0.25, 2.5 N m on
        the registered 10 N m actuators), in (0, 2].

    Notes
    -----
    ``reset(seed=s)`` resets the controller with seed s (its dither);
    an unseeded reset draws the controller's seed from a generator seeded
    by the last seeded reset, so a seeded run of episodes is reproducible.
    """

    def __init__(self, env: gym.Env, controller: Controller | None = None,
                 scale: float = 0.25) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, controller=controller, scale=scale)
        gym.Wrapper.__init__(self, env)
        if controller is None:
            controller = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env))
        if not isinstance(controller, Controller):
            raise TypeError(f"controller must be a controllers.Controller, "
                            f"got {type(controller).__name__}")
        if not (np.isfinite(scale) and 0.0 < scale <= 2.0):
            raise ValueError(f"scale must be in (0, 2], got {scale}")
        self.controller = controller
        self.scale = float(scale)
        self._seeds: np.random.Generator | None = None
        self._obs: np.ndarray | None = None
        self._info: dict[str, Any] | None = None

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env and the base controller.

        Returns
        -------
        (observation, info)
            The first observation and the env's info.
        """
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._seeds = np.random.default_rng(seed)
            controller_seed: int | None = seed
        elif self._seeds is not None:
            controller_seed = int(self._seeds.integers(_SEED_BOUND))
        else:
            controller_seed = None      # an unseeded env: unseeded dither, as Gymnasium does
        self.controller.reset(controller_seed)
        self._obs, self._info = obs, info
        return obs, info

    def step(self, action: ArrayLike) -> tuple[np.ndarray, SupportsFloat, bool, bool,
                                              dict[str, Any]]:
        """Step the env with the base controller's action plus ``scale * action`` (the
        residual, clipped to [-1, 1]; the sum clipped to the action space).

        Returns
        -------
        (observation, reward, terminated, truncated, info)
            The env's step under the base's action plus the residual.
        """
        if self._obs is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        residual = np.asarray(action, dtype=float)
        if residual.shape != (3,):
            raise ValueError(f"action must have shape (3,), got {residual.shape}")
        if not np.all(np.isfinite(residual)):
            raise ValueError(f"action must be finite, got {residual.tolist()}")
        base = np.asarray(self.controller.act(self._obs, self._info), dtype=float)
        applied = np.clip(base + self.scale * np.clip(residual, -1.0, 1.0), -1.0, 1.0)
        obs, reward, terminated, truncated, info = self.env.step(applied.astype(np.float32))
        info["base_action"] = base.astype(np.float32)
        info["residual_action"] = (applied - base).astype(np.float32)
        self._obs, self._info = obs, info
        return obs, reward, terminated, truncated, info


def _residual_layer(env: gym.Env, missing: Exception) -> ResidualControl:
    """The :class:`ResidualControl` in ``env``'s wrapper stack; ``missing`` is raised
    when there is none."""
    layer: Any = env
    while not isinstance(layer, ResidualControl):
        if not isinstance(layer, gym.Wrapper):
            raise missing
        layer = layer.env
    return layer


class BaseRelativeReward(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """The residual's reward minus what its base alone earns on the same episode.

    At every reset the wrapped env (a :class:`ResidualControl` stack: a zero
    action flies its base) is copied with its state, its random generators and
    its base controller; the copy is stepped with a zero residual beside the
    agent's env. Both meet the same plant draw and the same sensor noise, so
    the reward ``r_k - r_k^base`` loses the variance the draw and the noise put
    in the return while the base's term, which no action changes, leaves the
    optimal policy and the policy gradient's expectation as they were (a
    baseline: common random numbers). Once the copy's episode has ended its
    term is 0.

    What it buys a residual agent is measured by
    ``python benchmarks/bench_residual_reward.py`` (docs/results/rl.md). It
    costs a second env and base per training env.

    Parameters
    ----------
    env : gymnasium.Env
        An env with a :class:`ResidualControl` in its wrapper stack, whose
        action space holds the zero action.

    Raises
    ------
    ValueError
        If no :class:`ResidualControl` is in the stack (a zero action would not
        fly a base).
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        super().__init__(env)
        _residual_layer(env, ValueError("BaseRelativeReward needs a ResidualControl in the "
                                        "env's wrapper stack: a zero action must fly the base"))
        self._twin: gym.Env | None = None
        self._twin_done = True
        self._zero = np.zeros(self.action_space.shape, dtype=self.action_space.dtype)

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env and the base's twin simulation.

        Returns
        -------
        (observation, info)
            The env's first observation and info.
        """
        obs, info = self.env.reset(seed=seed, options=options)
        # the simulator is copied first: a controller's copy keeps the env it was
        # given (Controller.__deepcopy__), which must be the twin's, not this one
        memo: dict[int, Any] = {}
        copy.deepcopy(self.env.unwrapped, memo)
        self._twin = copy.deepcopy(self.env, memo)
        self._twin_done = False
        return obs, info

    def step(self, action: ArrayLike) -> tuple[np.ndarray, SupportsFloat, bool, bool,
                                              dict[str, Any]]:
        """Step the env and the base's twin.

        Returns
        -------
        (observation, reward, terminated, truncated, info)
            The env's step, the reward minus the base's on the twin.
        """
        obs, reward, terminated, truncated, info = self.env.step(action)
        base_reward = 0.0
        if not self._twin_done and self._twin is not None:
            _, twin_reward, twin_end, twin_cut, _ = self._twin.step(self._zero)
            base_reward = float(twin_reward)
            self._twin_done = bool(twin_end or twin_cut)
        info["base_reward"] = base_reward
        return obs, float(reward) - base_reward, terminated, truncated, info


class ResidualObservations(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Append what a residual agent needs to correct its base law.

    The agent of :class:`ResidualControl` sees the env's observation alone:
    one noisy sample, attitude and reference apart, no memory. This wrapper,
    put around the :class:`ResidualControl` (or anything wrapping it), appends

    * the attitude error, measured attitude minus reference (rad, 3);
    * the last torque applied (the env's ``info["torque"]``, normalized by
      ``max_torque``, 3): the base's action and the agent's correction;
    * the base controller's state estimate (its Kalman filter's state, in
      its model's coordinates, ``env.unwrapped.model.n`` entries; zeros
      while it has none or when its model has another order).

    Parameters
    ----------
    env : gymnasium.Env
        A :class:`ResidualControl`, or a wrapper chain containing one.
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        self.residual = _residual_layer(env, TypeError(
            "ResidualObservations needs a ResidualControl in the wrapped chain"))
        base = env.unwrapped
        self._att = base.observation_layout.indices("attitude")
        self._max_torque = float(base.max_torque)
        self.n_states = int(base.model.n)
        n_extra = 6 + self.n_states
        low = np.concatenate([env.observation_space.low, np.full(n_extra, -_EXTRA_BOUND)])
        high = np.concatenate([env.observation_space.high, np.full(n_extra, _EXTRA_BOUND)])
        self.observation_space = gym.spaces.Box(low.astype(np.float32),
                                                high.astype(np.float32), dtype=np.float32)

    def _extend(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        extra = np.zeros(6 + self.n_states)
        reference = np.asarray(info.get("reference", np.zeros(3)), dtype=float)
        extra[:3] = np.asarray(obs, dtype=float)[self._att] - reference
        extra[3:6] = np.asarray(info.get("torque", np.zeros(3)), dtype=float) / self._max_torque
        kf = getattr(self.residual.controller, "kf", None)
        state = None if kf is None else np.asarray(kf.x, dtype=float)
        if state is not None and state.shape == (self.n_states,):
            extra[6:] = state
        extra = np.clip(np.nan_to_num(extra, nan=0.0), -_EXTRA_BOUND, _EXTRA_BOUND)
        return np.concatenate([np.asarray(obs, dtype=np.float32), extra.astype(np.float32)])

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env.

        Returns
        -------
        (observation, info)
            The first observation with the base's channels, and the env's info.
        """
        obs, info = self.env.reset(seed=seed, options=options)
        return self._extend(obs, info), info

    def step(self, action: ArrayLike) -> tuple[np.ndarray, SupportsFloat, bool, bool,
                                              dict[str, Any]]:
        """Step the env.

        Returns
        -------
        (observation, reward, terminated, truncated, info)
            The env's step, the observation with the base's channels.
        """
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._extend(obs, info), reward, terminated, truncated, info
