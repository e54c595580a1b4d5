"""Wrappers for learning agents on the spacecraft environments.

:class:`ActionRepeat` lets an agent decide at a coarser period than the
plant's sample time (MuJoCo's ``frame_skip``, Atari's frame skipping). The
spacecraft's attitude moves on a scale of tens of seconds while the env
samples every 0.1 s, so an agent acting every sample has to assign credit
over hundreds of decisions; holding each action for 1 s brings that to tens.
Put it outermost (outside a features wrapper) so that whatever runs per
sample, such as an online identifier, still sees every sample.

:class:`NominalUnits` gives an agent its observations in fixed units: each
channel divided by its group's nominal level (1 deg, 0.1 deg/s, 1 cm), so a
policy's weights keep their meaning while it learns, where a running
normalization moves them. :class:`ObservationAverage` gives it the mean of the
last samples instead of the last one: an agent that decides once a second sees the
second's measurements with their noise averaged down (the anti-aliasing filter of a
sampled-data controller), not one noisy sample of them. :class:`ObservationGroups`
passes on some of the observation's groups: an agent that corrects a base law (which
reads the whole observation) can see the attitude error and the rate alone.
"""

from __future__ import annotations

import numbers
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["ActionRepeat", "NominalUnits", "ObservationAverage", "ObservationGroups",
           "ObservationProducts"]


def _count(name: str, value: Any) -> int:
    """``value`` as an int, if it is an integer >= 1 (not a bool); else ValueError."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


class ActionRepeat(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Apply each action for ``repeat`` consecutive env steps.

    The rewards of the repeated steps are summed (the return of an episode
    is unchanged); the observation, ``terminated``, ``truncated`` and
    ``info`` are those of the last step taken. The repetition stops early
    when the episode ends. ``info["repeated_steps"]`` is the number of env
    steps the action was held for.

    Parameters
    ----------
    env : gymnasium.Env
    repeat : int
        Env steps per action, >= 1 (10 holds an action for 1 s at the
        registered ``dt = 0.1 s``).
    """

    def __init__(self, env: gym.Env, repeat: int = 10) -> None:
        self.repeat = _count("repeat", repeat)
        gym.utils.RecordConstructorArgs.__init__(self, repeat=repeat)
        gym.Wrapper.__init__(self, env)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Hold ``action`` for up to ``repeat`` env steps (fewer when the episode ends).

        Returns
        -------
        (observation, reward, terminated, truncated, info)
            The last step's, the reward summed over the steps taken.
        """
        total, steps = 0.0, 0
        while True:
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            steps += 1
            if terminated or truncated or steps == self.repeat:
                break
        info["repeated_steps"] = steps
        return obs, total, terminated, truncated, info


class NominalUnits(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Observations in nominal units: each channel over its group's nominal level.

    The levels are :data:`spacecraft_conventions.NOMINAL_SCALE`'s (attitude,
    attitude error and reference 1 deg, rate 0.1 deg/s, deflection 1 cm) for the
    groups the environment observes (``env.unwrapped.observation_layout``), so an
    observation of 1 is one nominal level in every episode and every run. A linear
    policy's gains are then in fixed physical units (normalized torque per degree,
    per 0.1 deg/s), which a running normalization (SB3's ``VecNormalize``) would
    rescale as its statistics move.

    Channels a feature wrapper appended after the layout's (for example
    :class:`controllers.PrivilegedFeatures`' parameter vector, already in a
    normalized frame) pass unchanged.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment, or a wrapper of one that keeps its observation
        or appends channels after it.
    levels : mapping of str to float, optional
        Levels (SI units: rad, rad/s, m) that replace the nominal ones for the
        groups named, e.g. ``{"deflection": 0.1}`` for deflections in units of
        10 cm (default: the nominal levels for every group).

    Raises
    ------
    ValueError
        If the observation is shorter than the environment's layout, or a
        level names a group the layout does not hold or is not a finite
        positive number.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import spacecraft_env
    >>> env = spacecraft_env.NominalUnits(gym.make("FlexibleSpacecraft-v2",
    ...                                            outputs=("attitude_error", "rate")))
    >>> obs, _ = env.reset(seed=0)
    >>> obs.shape, obs.dtype
    ((6,), dtype('float32'))
    """

    def __init__(self, env: gym.Env, levels: dict[str, float] | None = None) -> None:
        levels = dict(levels or {})
        gym.utils.RecordConstructorArgs.__init__(self, levels=levels or None)
        gym.ObservationWrapper.__init__(self, env)
        layout = env.unwrapped.observation_layout
        scales = np.asarray(layout.scales(), dtype=np.float64)
        for group, level in levels.items():
            if group not in layout.names:
                raise ValueError(f"levels names {group!r}, not a group of the env's layout "
                                 f"{layout.names}")
            if isinstance(level, bool | np.bool_) or not (isinstance(level, numbers.Real)
                                                          and 0.0 < level < np.inf):
                raise ValueError(f"levels[{group!r}] must be a finite positive number "
                                 f"(SI units), got {level!r}")
            scales[layout.indices(group)] = float(level)
        space = env.observation_space
        if len(space.shape) != 1 or space.shape[0] < scales.size:
            raise ValueError(f"NominalUnits needs the environment's own observation (of "
                             f"shape {scales.shape}, appended channels allowed); got "
                             f"{space.shape}")
        self.scales = np.concatenate([scales, np.ones(space.shape[0] - scales.size)])
        scales = self.scales
        self.observation_space = gym.spaces.Box(
            (space.low / scales).astype(np.float32), (space.high / scales).astype(np.float32),
            dtype=np.float32)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """``observation`` over the nominal levels (float32).

        Returns
        -------
        ndarray of float32
            The observation in nominal units.
        """
        return (np.asarray(observation, dtype=np.float64) / self.scales).astype(np.float32)


class ObservationAverage(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Each observation the mean of the last ``window`` observations (a boxcar filter).

    Averaging ``window`` samples divides the sensor noise's standard deviation by
    ``sqrt(window)`` and delays the signal by ``(window - 1) / 2`` samples. Under
    :class:`ActionRepeat` with ``repeat == window`` (put this wrapper inside it) an
    agent sees, at each decision, the mean of the samples since its last one, as a
    sampled-data controller sees its sensors through an anti-aliasing filter. The
    average restarts at every reset (the first observations average the samples
    since the reset).

    Parameters
    ----------
    env : gymnasium.Env
        An environment with a ``Box`` observation space.
    window : int
        Samples averaged, >= 1 (1: the observation unchanged).

    Raises
    ------
    ValueError
        If ``window`` is not an integer >= 1.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import spacecraft_env
    >>> env = spacecraft_env.ObservationAverage(gym.make("FlexibleSpacecraft-v2"), 10)
    >>> obs, _ = env.reset(seed=0)
    >>> obs.shape, obs.dtype
    ((10,), dtype('float32'))
    """

    def __init__(self, env: gym.Env, window: int = 10) -> None:
        self.window = _count("window", window)
        gym.utils.RecordConstructorArgs.__init__(self, window=window)
        gym.ObservationWrapper.__init__(self, env)
        self._recent: deque[np.ndarray] = deque(maxlen=self.window)

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env; the average restarts.

        Returns
        -------
        (observation, info)
            The first observation (its own mean) and the env's info.
        """
        self._recent.clear()
        return super().reset(seed=seed, options=options)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """The mean of this observation and the ``window - 1`` before it since the reset.

        Returns
        -------
        ndarray
            The average, in the env's dtype.
        """
        self._recent.append(np.asarray(observation, dtype=np.float64))
        mean = np.mean(self._recent, axis=0)
        return mean.astype(self.observation_space.dtype)


class ObservationGroups(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """The observation's channels of some of its groups, in the order named.

    The groups are those of ``env.unwrapped.observation_layout`` (the env's
    ``outputs``). Put it outside anything that reads the whole observation (a
    base law under :class:`controllers.ResidualControl`): the agent sees the
    groups named, the base the env's observation. Channels a feature wrapper
    appended after the layout's follow the groups, in their order.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment, or a wrapper of one that keeps its observation
        (for example :class:`NominalUnits`) or appends channels after it.
    groups : sequence of str
        Distinct group names of the env's layout, at least one.

    Raises
    ------
    ValueError
        If a name is not a group of the env's layout, is repeated, or none is
        given, or the observation is shorter than the layout.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import spacecraft_env
    >>> env = spacecraft_env.ObservationGroups(
    ...     gym.make("FlexibleSpacecraft-v2", outputs=("attitude", "rate", "deflection",
    ...                                                "attitude_error")),
    ...     ("attitude_error", "rate"))
    >>> obs, _ = env.reset(seed=0)
    >>> obs.shape
    (6,)
    """

    def __init__(self, env: gym.Env, groups: tuple[str, ...] | list[str]) -> None:
        groups = tuple(groups)
        gym.utils.RecordConstructorArgs.__init__(self, groups=groups)
        gym.ObservationWrapper.__init__(self, env)
        layout = env.unwrapped.observation_layout
        if not groups or len(set(groups)) != len(groups) or not set(groups) <= set(layout.names):
            raise ValueError(f"groups must be distinct names from the env's layout "
                             f"{layout.names}, at least one; got {groups}")
        space = env.observation_space
        if len(space.shape) != 1 or space.shape[0] < layout.size:
            raise ValueError(f"ObservationGroups needs the environment's own observation, "
                             f"of shape ({layout.size},) (appended channels allowed); got "
                             f"{space.shape}")
        self.groups = groups
        self.rows = np.concatenate([layout.indices(name) for name in groups]
                                   + [np.arange(layout.size, space.shape[0])])
        self.observation_space = gym.spaces.Box(space.low[self.rows], space.high[self.rows],
                                                dtype=space.dtype)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """The channels of :attr:`groups`, then any appended ones (the env's dtype).

        Returns
        -------
        ndarray
            The selected channels.
        """
        return np.asarray(observation)[self.rows]


class ObservationProducts(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """The observation's leading channels and their products with scheduling channels.

    For an observation ``[x, ..., s_j, ...]`` with ``x`` its first ``state``
    channels and ``s`` the channels ``schedule``, the wrapped observation is
    ``[x, x_1 s_1, x_1 s_2, ..., x_n s_m]`` (``x`` then ``outer(x, s)`` row by
    row); the other channels are dropped. A linear policy on it is a
    gain-scheduled linear law, ``u = (W_0 + sum_j s_j W_j) x``: its gains move
    with the scheduling channels (a parameter vector appended by a feature
    wrapper, e.g. the rigid-body gain of :class:`controllers.PrivilegedFeatures`)
    where a linear policy on ``[x, s]`` could only add a torque bias.

    Parameters
    ----------
    env : gymnasium.Env
        An environment with a one-dimensional ``Box`` observation.
    state : int
        ``n``, the leading channels that are kept and multiplied, >= 1.
    schedule : sequence of int
        Indices of the scheduling channels in the observation, distinct, at least
        one, each >= ``state``.

    Raises
    ------
    ValueError
        If ``state`` or an index is out of range, or the indices are not distinct.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import spacecraft_env
    >>> env = spacecraft_env.ObservationProducts(gym.make("FlexibleSpacecraft-v2"), 6, (8, 9))
    >>> obs, _ = env.reset(seed=0)
    >>> obs.shape                        # 6 channels, then 6 x 2 products
    (18,)
    """

    def __init__(self, env: gym.Env, state: int, schedule: tuple[int, ...] | list[int]) -> None:
        state = _count("state", state)
        schedule = tuple(int(j) for j in schedule)
        gym.utils.RecordConstructorArgs.__init__(self, state=state, schedule=schedule)
        gym.ObservationWrapper.__init__(self, env)
        space = env.observation_space
        if len(space.shape) != 1 or space.shape[0] <= state:
            raise ValueError(f"state must be below the observation's size {space.shape}, "
                             f"got {state}")
        size = space.shape[0]
        if (not schedule or len(set(schedule)) != len(schedule)
                or not all(state <= j < size for j in schedule)):
            raise ValueError(f"schedule must be distinct indices in [{state}, {size}), at "
                             f"least one; got {schedule}")
        self.state, self.schedule = state, np.asarray(schedule, dtype=int)
        x_max = np.maximum(np.abs(space.low[:state]), np.abs(space.high[:state]))
        s_max = np.maximum(np.abs(space.low[self.schedule]), np.abs(space.high[self.schedule]))
        with np.errstate(invalid="ignore"):                  # inf * 0: unbounded
            bound = np.nan_to_num(np.outer(x_max, s_max).ravel(), nan=np.inf, posinf=np.inf)
        low = np.concatenate([space.low[:state], -bound])
        high = np.concatenate([space.high[:state], bound])
        self.observation_space = gym.spaces.Box(low.astype(space.dtype),
                                                high.astype(space.dtype), dtype=space.dtype)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """``[x, outer(x, s).ravel()]`` (the env's dtype).

        Returns
        -------
        ndarray
            The observation and the products.
        """
        obs = np.asarray(observation, dtype=np.float64)
        x = obs[:self.state]
        return np.concatenate([x, np.outer(x, obs[self.schedule]).ravel()]).astype(
            self.observation_space.dtype)
