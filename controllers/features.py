"""The online identifier as a model-learning component for RL agents.

:class:`IdentifiedModelFeatures` runs an identifier from :mod:`identifiers`
alongside any of the spacecraft environments and appends identified-model
features to every observation, so an agent (stable-baselines3 or any other)
sees what the identifier has learned about the current plant.

Appended features, in order (all float32, clipped to [-10, 10]):

========================  =====  ==============================================
feature                   size   scaling
========================  =====  ==============================================
state estimate            n      identifier state (its internal coordinates,
                                 already normalized by the nominal sensor
                                 ranges) divided by ``state_scale`` (10);
                                 absent with ``include_state=False``
rigid-body gain           6      upper triangle (xx, xy, xz, yy, yz, zz) of the
                                 identified ``J^-1``
                                 (:func:`identifiers.rigid_body_gain`, from
                                 torque to body rate) times the nominal
                                 inertia's mean diagonal (so about 1);
                                 refreshed every ``gain_every`` steps
modal frequencies         k      identified natural frequencies (Hz) of the k
                                 slowest oscillatory poles, divided by 1 Hz
damping ratios            k      of the same poles (dimensionless)
prediction error          m      ``y_k - C xhat_{k|k-1}`` per measured output,
                                 divided by the nominal range (1 deg,
                                 0.1 deg/s, 1 cm)
model ready               1      1 once the identifier has a model, else 0
========================  =====  ==============================================

Before warm-up every feature but the flag is 0 (in every episode, unless
``keep_identifier`` carries the identifier over episode resets).

:class:`OracleModelFeatures` appends the same rigid-body gain, frequencies
and damping ratios computed from the true current plant: the ceiling of
what model features can give an agent (privileged; for comparisons only).
"""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike

from identifiers import OnlineIdentifier, default_identifier, rigid_body_gain
from spacecraft_conventions import match_groups, single_threaded_blas

__all__ = ["PHYSICAL_FEATURE_NAMES", "IdentifiedModelFeatures", "OracleModelFeatures",
           "PhysicalFeatures", "PrivilegedFeatures"]

_CLIP = 10.0
#: Entries of a symmetric 3x3 matrix that the features carry (upper triangle).
_UPPER = np.triu_indices(3)


def _appended_space(env: gym.Env, n_features: int) -> spaces.Box:
    """The env's observation space with ``n_features`` channels in [-10, 10] appended."""
    low = np.concatenate([env.observation_space.low,
                          np.full(n_features, -_CLIP, dtype=np.float32)])
    high = np.concatenate([env.observation_space.high,
                           np.full(n_features, _CLIP, dtype=np.float32)])
    return spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)


def _put_modes(block: np.ndarray, freq: np.ndarray, zeta: np.ndarray) -> None:
    """Write the k slowest frequencies (Hz) then their damping ratios into ``block``
    (length 2k, a view); fewer modes than k leave the rest as it is (0)."""
    k = block.size // 2
    count = min(k, freq.size)
    block[:count] = freq[:count]
    block[k:k + count] = zeta[:count]


def _plant_cached(cache: dict, model: Any, t: float, compute: Any) -> np.ndarray:
    """``compute()`` for the true plant at ``t``, memoized by the plant's configuration
    key (the truth changes only with the plant; bounded to 4096 entries)."""
    key = model._key(t)
    hit = cache.get(key)
    if hit is None:
        if len(cache) > 4096:
            cache.clear()
        hit = cache[key] = compute()
    return hit


def _gain_scale(env: gym.Env) -> float:
    """Mean diagonal of the nominal inertia, kg m^2: makes ``J^-1`` about 1."""
    return float(np.mean(np.diag(env.unwrapped.model.nominal().inertia(0.0))))


class IdentifiedModelFeatures(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Append online-identified model features to the observation.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment (observing at least one sensor group).
    identifier : identifiers.OnlineIdentifier, optional
        Default: :func:`identifiers.default_identifier` for the observed
        sensor groups (the identifier the adaptive LQG uses).
    n_modes : int
        k, number of modal frequencies and damping ratios appended.
    state_scale : float
        Divisor of the state estimate.
    gain_every : int
        Steps between refreshes of the rigid-body gain feature (its Schur
        split costs several updates' worth; 10 steps are 1 s).
    keep_identifier : bool
        Carry the identifier over episode resets
        (:meth:`identifiers.OnlineIdentifier.restart`: modes and gains
        kept, signals and state estimate restarted), so every episode after
        the first has features from its first step, as an identifier running
        on board through successive manoeuvres would. Default False: each
        episode starts the identifier afresh, and every feature but the flag
        is 0 until its warm-up ends. With True an episode's observations
        depend on the episodes before it on the same wrapper.
    include_state : bool
        Append the identifier's state estimate (default True). Its
        coordinates are the identifier's own and change when it rebuilds
        its model (e.g. when a mode search moves the modes); without it the
        features are the gain, the modes, the prediction error and the flag.

    Examples
    --------
    >>> import gymnasium as gym
    >>> from controllers import IdentifiedModelFeatures
    >>> env = IdentifiedModelFeatures(gym.make("spacecraft_env:FlexibleSpacecraft-v2"))
    >>> obs, info = env.reset(seed=0)
    >>> env.env.observation_space.shape, env.observation_space.shape
    ((10,), (57,))
    >>> env.close()
    """

    def __init__(self, env: gym.Env, identifier: OnlineIdentifier | None = None, n_modes: int = 4,
                 state_scale: float = 10.0, gain_every: int = 10,
                 keep_identifier: bool = False, include_state: bool = True) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, identifier=identifier, n_modes=n_modes,
                                                 state_scale=state_scale, gain_every=gain_every,
                                                 keep_identifier=keep_identifier,
                                                 include_state=include_state)
        gym.ObservationWrapper.__init__(self, env)
        base = env.unwrapped
        model = base.model
        if n_modes < 1:
            raise ValueError(f"n_modes must be >= 1, got {n_modes}")
        if gain_every < 1:
            raise ValueError(f"gain_every must be >= 1, got {gain_every}")
        layout = base.observation_layout
        self._meas_obs, _ = match_groups(layout, model.output_layout)
        if self._meas_obs.size == 0:
            raise ValueError("the env must observe at least one sensor group "
                             "('attitude', 'rate' or 'deflection')")
        measured = layout.sensors()
        self._meas_scale = measured.scales()
        if identifier is None:
            identifier = default_identifier(measured, n=model.n, dt=model.dt)
        self.identifier = identifier
        self.n_modes = int(n_modes)
        self.state_scale = float(state_scale)
        self.gain_every = int(gain_every)
        self.keep_identifier = bool(keep_identifier)
        self._gain = np.zeros(6)
        self._gain_scale = _gain_scale(env)
        self._rate_rows = measured.indices("rate") if "rate" in measured.names else None
        self._max_torque = float(base.max_torque)
        self.include_state = bool(include_state)
        self._n_state = identifier.n if self.include_state else 0
        self.n_features = self._n_state + 6 + 2 * self.n_modes + self._meas_obs.size + 1
        self.observation_space = _appended_space(env, self.n_features)
        self._action = None
        self._last_y = None

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env; the identifier restarts (or is kept, with ``keep_identifier``).

        Returns
        -------
        (observation, info)
            The first observation, with this wrapper's channels, and the env's info.
        """
        if self.keep_identifier:
            self.identifier.restart()
        else:
            self.identifier.reset()
            self._gain = np.zeros(6)
        self._action = None
        self._last_y = None
        self._modes_of: np.ndarray | None = None
        self._modes: tuple[np.ndarray, np.ndarray] | None = None
        self._steps = 0
        return super().reset(seed=seed, options=options)

    def step(self, action: ArrayLike) -> tuple[np.ndarray, SupportsFloat, bool, bool,
                                              dict[str, Any]]:
        """Step the env with ``action`` (kept for the identifier's next sample).

        Returns
        -------
        (observation, reward, terminated, truncated, info)
            The env's step, the observation with this wrapper's channels.
        """
        self._action = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        return super().step(action)

    def _features(self, y: np.ndarray) -> np.ndarray:
        ident = self.identifier
        n, k = self._n_state, self.n_modes
        out = np.zeros(self.n_features)
        model, x = ident.model, ident.state
        if model is None or x is None or not np.all(np.isfinite(model.A)):
            return out
        out[:n] = x[:n] / self.state_scale
        if self._rate_rows is not None and self._steps % self.gain_every == 0:
            try:
                gain = rigid_body_gain(model, self._rate_rows)
                self._gain = (0.5 * (gain + gain.T))[_UPPER] * self._gain_scale
            except (ValueError, np.linalg.LinAlgError):
                pass                        # keep the last gain
        out[n:n + 6] = self._gain
        if self._modes_of is None or not np.array_equal(model.A, self._modes_of):
            # the model's A changes only when the identifier exports (every few
            # samples), while its eigenvalues cost as much as an update
            self._modes_of, self._modes = model.A, model.modal(unique=False)
        _put_modes(out[n + 6:n + 6 + 2 * k], *self._modes)
        pred = model.C @ x
        out[n + 6 + 2 * k:-1] = (y - pred) / self._meas_scale   # NaN where y is missing
        out[-1] = 1.0
        return out

    @staticmethod
    def _bounded(feats: np.ndarray) -> np.ndarray:
        """``feats`` clipped to [-10, 10] in place, NaN (a missing output) to 0:
        ``np.nan_to_num`` then ``np.clip``, in two cheaper calls."""
        np.clip(feats, -_CLIP, _CLIP, out=feats)
        feats[np.isnan(feats)] = 0.0
        return feats

    @single_threaded_blas
    def observation(self, observation: np.ndarray) -> np.ndarray:
        y = np.asarray(observation, dtype=float)[self._meas_obs]
        if self._action is not None and self._last_y is not None:
            # (u_k, y_k): the torque applied after y_k was measured. A non-finite
            # y_k goes in as it is: the identifier skips and counts it.
            self.identifier.update(self._action * self._max_torque, self._last_y)
        feats = self._features(y)
        self._steps += 1
        self._last_y = y
        full = np.concatenate([np.asarray(observation, dtype=float), self._bounded(feats)])
        return full.astype(np.float32)


class OracleModelFeatures(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Append the true current plant's model features (privileged: the ceiling).

    Appends, from the truth model at the current time, the rigid-body gain
    ``J(t)^-1`` (6, scaled as in :class:`IdentifiedModelFeatures`), the
    natural frequencies (Hz) of the k slowest flexible modes and their
    damping ratios: what a perfect identifier would report. For comparisons
    only; a deployed agent cannot have it.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment.
    n_modes : int
        k, number of modal frequencies and damping ratios appended.
    """

    def __init__(self, env: gym.Env, n_modes: int = 4) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, n_modes=n_modes)
        gym.ObservationWrapper.__init__(self, env)
        if n_modes < 1:
            raise ValueError(f"n_modes must be >= 1, got {n_modes}")
        self.n_modes = int(n_modes)
        self._gain_scale = _gain_scale(env)
        self.n_features = 6 + 2 * self.n_modes
        self.observation_space = _appended_space(env, self.n_features)
        self._cache: dict = {}

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env; the features of the new plant are computed afresh.

        Returns
        -------
        (observation, info)
            The first observation, with this wrapper's channels, and the env's info.
        """
        self._cache.clear()            # a randomized reset changes the plant
        return super().reset(seed=seed, options=options)

    def _truth(self) -> np.ndarray:
        base = self.env.unwrapped
        model, t = base.model, base.time

        def compute() -> np.ndarray:
            k = self.n_modes
            feats = np.zeros(self.n_features)
            feats[:6] = np.linalg.inv(model.inertia(t))[_UPPER] * self._gain_scale
            _put_modes(feats[6:6 + 2 * k], *model.modal(t))
            return feats

        return _plant_cached(self._cache, model, t, compute)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        feats = np.clip(self._truth(), -_CLIP, _CLIP)
        return np.concatenate([np.asarray(observation, dtype=float), feats]).astype(np.float32)


# --------------------------------------------------------------------------
# Physical parameters: what the identifier knows, in a fixed, normalized frame
# --------------------------------------------------------------------------

#: Window of the change flag, s: 1 while the plant changed (or a change was
#: detected) within this long.
CHANGE_WINDOW_S = 20.0
#: A truth feature that moved by more than this (relative, over the window)
#: counts as a change for the privileged flag.
_CHANGE_TOLERANCE = 0.01


def physical_feature_names(n_modes: int) -> tuple[str, ...]:
    """Names of :class:`PhysicalFeatures`' channels, in order.

    Returns
    -------
    tuple of str
        7 + 2 n_modes + 3 names: the rigid gain's, then each mode's frequency and
        damping, then the identifier's health.
    """
    modes = range(1, n_modes + 1)
    return ("log_gain_xx", "log_gain_yy", "log_gain_zz", "gain_xy", "gain_xz", "gain_yz",
            "gain_rel_std", *(f"log_freq_{i}" for i in modes), *(f"damping_{i}" for i in modes),
            *(f"log_freq_std_{i}" for i in modes), "paddle_sin", "paddle_cos", "changed",
            "ready")


#: Channel names with the default two modes.
PHYSICAL_FEATURE_NAMES = physical_feature_names(2)


class _PhysicalFrame:
    """The fixed frame both physical-feature wrappers report in.

    The nominal plant (the ETS-VIII at its 0 deg paddle angle) sets it:
    ``G0 = diag(J0^-1)`` for the gain and the frequencies ``f0`` of its
    ``n_modes`` dominant modes (largest input-output weight, in order of
    frequency) for the modes, so every channel is about 0 at the nominal
    plant and of order 1 over the family's range.
    """

    def __init__(self, env: gym.Env, n_modes: int) -> None:
        if n_modes < 1:
            raise ValueError(f"n_modes must be >= 1, got {n_modes}")
        nominal = env.unwrapped.model.nominal()
        self.k = int(n_modes)
        self.g0 = np.diag(np.linalg.inv(nominal.inertia(0.0))).copy()
        f0, _ = self.dominant_modes(nominal, 0.0)
        if f0.size < self.k:
            raise ValueError(f"the plant has {f0.size} flexible modes, n_modes={n_modes}")
        self.f0 = f0
        self.size = 7 + 3 * self.k + 4

    def dominant_modes(self, model: Any, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Frequencies (Hz) and damping of the true plant's ``k`` modes with the largest
        input-output weight (:meth:`spacecraft_env.FlexibleSpacecraftModel.modal_residues`),
        in order of frequency: the modes data can reveal, and the ones an identifier
        keeps (a mode that the torques hardly excite is invisible to both)."""
        freq, zeta, weight = model.modal_residues(t)
        keep = np.sort(np.argsort(-weight, kind="stable")[:self.k])
        return freq[keep], zeta[keep]

    def fill(self, out: np.ndarray, gain: np.ndarray, gain_rel_std: float,
             freq: np.ndarray, zeta: np.ndarray, log_f_std: np.ndarray) -> None:
        """Write the gain and mode channels of one vector (``out``, length :attr:`size`;
        the paddle angle and the flags are left to the caller)."""
        k = self.k
        diag = np.diag(gain)
        out[:3] = np.log(np.maximum(diag, 1e-3 * self.g0) / self.g0)
        norm = np.sqrt(self.g0[[0, 0, 1]] * self.g0[[1, 2, 2]])
        sym = 0.5 * (gain + gain.T)
        out[3:6] = sym[[0, 0, 1], [1, 2, 2]] / norm
        out[6] = gain_rel_std
        count = min(k, freq.size)
        order = np.argsort(freq)[:count]
        out[7:7 + count] = np.log(np.maximum(freq[order], 1e-6) / self.f0[:count])
        out[7 + k:7 + k + count] = 10.0 * zeta[order]
        out[7 + 2 * k:7 + 2 * k + count] = log_f_std[order]

    def put_paddle(self, out: np.ndarray, angle: float) -> None:
        """Write the paddle angle (rad) as its sine and cosine into ``out``."""
        out[7 + 3 * self.k:9 + 3 * self.k] = math.sin(angle), math.cos(angle)


class PhysicalFeatures(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Append the identifier's physical estimates and their uncertainty.

    The adaptation-module pattern of online system identification for RL: a
    compact vector of physical parameters, estimated online from the
    torques and the measurements and normalized against the nominal plant,
    so the same channel means the same thing in every episode and every
    model the identifier rebuilds. Appended (float32, clipped to [-10, 10];
    names in :func:`physical_feature_names`):

    ==================  ===  ================================================
    channel             size  meaning
    ==================  ===  ================================================
    log gain diagonal   3    ``log(G_ii / G0_ii)``, ``G = J^-1`` the rigid-body
                             gain (rad/s^2 per N m, including the actuator's
                             efficiency) from the identifier's rate
                             regression, ``G0`` the nominal plant's
    gain off-diagonal   3    ``G_ij / sqrt(G0_ii G0_jj)`` (xy, xz, yz)
    gain uncertainty    1    the estimate's relative standard deviation
                             (:meth:`identifiers.RigidGainEstimate.relative_std`)
    log frequencies     k    ``log(f_i / f0_i)`` of the k slowest tracked
                             modes (an identifier keeps the modes the data
                             reveal: the dominant ones)
    damping             k    their damping ratios times 10
    frequency std       k    standard deviation of ``log f_i`` in percent
                             (the modal tracker's covariance of its last
                             refinement; 0 before the first)
    paddle angle        2    sine and cosine of the solar paddles' angle
                             (the drive's reading, ``info["paddle_angle"]``;
                             present from the first step): the sign of the
                             paddles' modal input coupling turns with it
    changed             1    1 if the identifier detected a change in the
                             last 20 s (:data:`CHANGE_WINDOW_S`)
    ready               1    1 once the identifier has warmed up (50 s by default); every
                             channel but the paddle angle is 0 before
    ==================  ===  ================================================

    The identifier is fed the commanded torque the env reports
    (``info["torque"]``, N m), so the wrapper can sit outside a
    :class:`controllers.ResidualControl` and still see the whole torque.
    It restarts every episode (a new plant of the family).

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment observing attitude and rate (deflections
        are used when observed).
    identifier : identifiers.OnlineIdentifier, optional
        Anything with ``rigid_gain`` and ``mode_estimates``; default
        :func:`identifiers.default_identifier` for the observed sensors.
    n_modes : int
        k, tracked modes reported (default 2).
    every : int
        Env steps between refreshes of the vector (default 10: 1 s, one
        decision of an agent under :class:`spacecraft_env.ActionRepeat`).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> from controllers import PhysicalFeatures
    >>> from controllers.features import PHYSICAL_FEATURE_NAMES
    >>> env = PhysicalFeatures(gym.make("spacecraft_env:FlexibleSpacecraftFamily-v2"))
    >>> obs, info = env.reset(seed=0)
    >>> env.env.observation_space.shape, env.observation_space.shape
    ((10,), (27,))
    >>> PHYSICAL_FEATURE_NAMES[:3], PHYSICAL_FEATURE_NAMES[-1]
    (('log_gain_xx', 'log_gain_yy', 'log_gain_zz'), 'ready')
    >>> float(obs[-1])                   # not ready before the identifier's warm-up
    0.0
    >>> env.close()
    """

    def __init__(self, env: gym.Env, identifier: OnlineIdentifier | None = None,
                 n_modes: int = 2, every: int = 10) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, identifier=identifier, n_modes=n_modes,
                                                 every=every)
        gym.Wrapper.__init__(self, env)
        if every < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        base = env.unwrapped
        model = base.model
        layout = base.observation_layout
        self._meas_obs, _ = match_groups(layout, model.output_layout)
        measured = layout.sensors()
        if not {"attitude", "rate"} <= set(measured.names):
            raise ValueError("PhysicalFeatures needs the env to observe 'attitude' and 'rate', "
                             f"got {measured.names}")
        if identifier is None:
            identifier = default_identifier(measured, n=model.n, dt=model.dt)
        for needed in ("rigid_gain", "mode_estimates"):
            if not hasattr(identifier, needed):
                raise TypeError(f"identifier must provide {needed!r} "
                                f"(e.g. identifiers.default_identifier())")
        self.identifier = identifier
        self.frame = _PhysicalFrame(env, n_modes)
        self.n_modes = self.frame.k
        self.every = int(every)
        self.n_features = self.frame.size
        self._dt = float(model.dt)
        self.observation_space = _appended_space(env, self.n_features)
        self._feats = np.zeros(self.n_features)
        self._last_y: np.ndarray | None = None
        self._steps = 0
        self._paddle_angle = 0.0

    def _refresh(self) -> None:
        ident, out = self.identifier, np.zeros(self.n_features)
        self.frame.put_paddle(out, self._paddle_angle)
        estimate = ident.rigid_gain
        if estimate is not None and np.all(np.isfinite(estimate.gain)):
            freq, zeta, cov = ident.mode_estimates
            k = freq.size
            log_f_std = np.zeros(k)
            if cov is not None and cov.shape == (2 * k, 2 * k):
                log_f_std = 100.0 * np.sqrt(np.maximum(np.diag(cov)[0::2], 0.0))
            rel = estimate.relative_std()
            self.frame.fill(out, estimate.gain, rel if np.isfinite(rel) else _CLIP,
                            freq, zeta, log_f_std)
            now = ident.n_samples * self._dt
            events = getattr(ident, "events", [])
            out[-2] = float(bool(events) and now - events[-1].time <= CHANGE_WINDOW_S)
            out[-1] = 1.0
        np.clip(out, -_CLIP, _CLIP, out=out)
        out[~np.isfinite(out)] = 0.0
        self._feats = out

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        if self._steps % self.every == 0:
            self._refresh()
        self._steps += 1
        return np.concatenate([np.asarray(obs, dtype=float), self._feats]).astype(np.float32)

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env and the identifier.

        Returns
        -------
        (observation, info)
            The first observation, with this wrapper's channels, and the env's info.
        """
        obs, info = self.env.reset(seed=seed, options=options)
        self.identifier.reset()
        self._last_y = np.asarray(obs, dtype=float)[self._meas_obs]
        self._steps = 0
        self._paddle_angle = float(info["paddle_angle"])
        return self._observe(obs), info

    @single_threaded_blas
    def step(self, action: ArrayLike) -> tuple[np.ndarray, SupportsFloat, bool, bool,
                                              dict[str, Any]]:
        """Step the env; the identifier takes the sample.

        Returns
        -------
        (observation, reward, terminated, truncated, info)
            The env's step, the observation with this wrapper's channels.
        """
        if self._last_y is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        # (u_k, y_k): the torque applied after y_k was measured
        self.identifier.update(np.asarray(info["torque"], dtype=float), self._last_y)
        self._last_y = np.asarray(obs, dtype=float)[self._meas_obs]
        self._paddle_angle = float(info["paddle_angle"])
        return self._observe(obs), reward, terminated, truncated, info


class PrivilegedFeatures(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """The same vector as :class:`PhysicalFeatures`, from the true plant: the ceiling.

    Gain ``G = a J(t)^-1`` with the actuator efficiency ``a`` of a family
    draw, the k dominant true modes (largest input-output weight, in order
    of frequency: the ones an identifier can see), zero uncertainty, the paddle
    angle (as the drive reads it), ``changed`` = 1 when
    any gain or frequency channel moved by more than 1 % over the last
    20 s, and ``ready`` = 1 from the first step. For comparisons only: a
    deployed agent cannot have it.

    With ``source="nominal"`` the vector is the nominal plant's instead (the
    frame's origin: what a design assumes without identification), with the
    drive's paddle angle, ``changed`` = 0 and ``ready`` = 1: the third input
    of an RMA-style comparison (:mod:`controllers.adaptation`).

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment.
    n_modes : int
        k, modes reported (default 2).
    every : int
        Env steps between refreshes of the vector (default 10, as
        :class:`PhysicalFeatures`: the same instants, so an agent under
        :class:`spacecraft_env.ActionRepeat` sees both at its decisions; the
        truth's modal analysis costs as much as an identifier update).
    source : {"truth", "nominal"}
        Which plant the gain and modes describe.

    Attributes
    ----------
    nominal_vector : ndarray or None
        With ``source="nominal"``: the nominal plant's vector (paddle angle
        0 deg; the observation's paddle channels follow the drive).

    Raises
    ------
    ValueError
        For ``every < 1``, ``n_modes < 1`` or another ``source``.
    """

    def __init__(self, env: gym.Env, n_modes: int = 2, every: int = 10,
                 source: str = "truth") -> None:
        gym.utils.RecordConstructorArgs.__init__(self, n_modes=n_modes, every=every,
                                                 source=source)
        gym.ObservationWrapper.__init__(self, env)
        if every < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        if source not in ("truth", "nominal"):
            raise ValueError(f"source must be 'truth' or 'nominal', got {source!r}")
        self.source = source
        self.frame = _PhysicalFrame(env, n_modes)
        self.n_modes = self.frame.k
        self.every = int(every)
        self.n_features = self.frame.size
        self.observation_space = _appended_space(env, self.n_features)
        self._cache: dict = {}
        self._feats = np.zeros(self.n_features)
        self._steps = 0
        self.nominal_vector: np.ndarray | None = None
        if source == "nominal":
            nominal = env.unwrapped.model.nominal()
            vector = np.zeros(self.n_features)
            freq, zeta = self.frame.dominant_modes(nominal, 0.0)
            self.frame.fill(vector, np.linalg.inv(nominal.inertia(0.0)), 0.0,
                            freq, zeta, np.zeros(freq.size))
            self.frame.put_paddle(vector, 0.0)
            vector[-1] = 1.0
            vector.flags.writeable = False
            self.nominal_vector = vector

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env; the privileged features of the new plant are computed afresh.

        Returns
        -------
        (observation, info)
            The first observation, with this wrapper's channels, and the env's info.
        """
        self._cache.clear()            # a new draw changes the plant
        self._steps = 0
        return super().reset(seed=seed, options=options)

    def _truth(self, t: float) -> np.ndarray:
        base = self.env.unwrapped
        model, t = base.model, max(t, 0.0)

        def compute() -> np.ndarray:
            efficiency = base.actuator_gain
            feats = np.zeros(self.n_features)
            freq, zeta = self.frame.dominant_modes(model, t)
            self.frame.fill(feats, efficiency * np.linalg.inv(model.inertia(t)), 0.0,
                            freq, zeta, np.zeros(freq.size))
            self.frame.put_paddle(feats, model.scenario.paddle_angle(t))
            feats[-1] = 1.0
            return feats

        return _plant_cached(self._cache, model, t, compute)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        if self._steps % self.every == 0 and self.nominal_vector is not None:
            base = self.env.unwrapped
            now = self.nominal_vector.copy()
            self.frame.put_paddle(now, base.model.scenario.paddle_angle(base.time))
            self._feats = np.clip(now, -_CLIP, _CLIP)
        elif self._steps % self.every == 0:
            t = self.env.unwrapped.time
            now = self._truth(t).copy()
            before = self._truth(t - CHANGE_WINDOW_S)
            k = self.n_modes
            moved = np.abs(np.concatenate([now[:6] - before[:6],
                                           now[7:7 + k] - before[7:7 + k]]))
            now[-2] = float(moved.max() > _CHANGE_TOLERANCE)
            self._feats = np.clip(now, -_CLIP, _CLIP)
        self._steps += 1
        return np.concatenate([np.asarray(observation, dtype=float),
                               self._feats]).astype(np.float32)
