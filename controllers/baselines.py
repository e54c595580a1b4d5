"""Baseline attitude controllers: PD, fixed, robust and scheduled LQG, and the oracles.

All read the observation layout, ``max_torque`` and the truth model from the
environment they are built for (``env.unwrapped``), and return normalized
torques in [-1, 1] (saturated). The LQG designs share one control law
(:class:`controllers.lqg.LQGLaw`: LQR with integral action on the
attitude error) and differ in the model they design on and the state
estimate they feed it (docs/design/control.md):

==================  ==============================================  ===========================
class               model                                           state
==================  ==============================================  ===========================
``PD``              none (per-axis inertia of the nominal design)   measured attitude and rate
``FixedLQG``        true model in the nominal configuration         steady-state Kalman filter
                    (paddles at 0 deg, nothing docked)
``RobustLQG``       rigid body only, nominal inertia; notch on the  steady-state Kalman filter
                    sensors at the first flexible modes             on the rigid model
``ScheduledLQG``    true model at the measured paddle angle         Kalman filter of that design
                    (drive encoder), nominal mass
``OracleLQG``       true model at every step                        Kalman filter on it (the
                                                                    fair reference)
``OracleLQR``       true model at every step                        the true state (a bound)
==================  ==============================================  ===========================
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike
from scipy.signal import iirnotch

from controllers.base import PADDLE_ANGLE, Controller
from controllers.lqg import LQGLaw, LQRWeights, equilibrium_state, output_weight
from controllers.riccati import RiccatiTracker
from identifiers import KalmanPredictor, RigidGainEstimate, StateSpaceModel, steady_state_gain
from spacecraft_conventions import match_groups, single_threaded_blas

__all__ = ["PD", "FixedLQG", "OracleLQG", "OracleLQR", "RobustLQG", "ScheduledLQG",
           "TrueModelIdentifier", "nominal_model"]

#: Torque-noise standard deviation (N m) the Kalman filters of the baselines assume.
PROCESS_NOISE = 0.05


def process_noise(b: np.ndarray, level: float = PROCESS_NOISE) -> np.ndarray:
    """The state noise covariance of the LQG filters here: ``level`` N m (default
    :data:`PROCESS_NOISE`) of white torque per axis through ``b`` (n, 3), plus a
    regularizer on the diagonal so the covariance stays positive definite: 1e-14 at
    :data:`PROCESS_NOISE`, scaled with ``level**2`` below it down to 1e-20 (a 1e-10
    rad attitude), so a filter that assumes a quiet plant is not held noisy by it.

    Returns
    -------
    (n, n) ndarray
        The state noise covariance, state units squared.
    """
    return level**2 * b @ b.T + regularizer(level) * np.eye(b.shape[0])


def regularizer(level: float) -> float:
    """The diagonal term of :func:`process_noise` at ``level`` N m, state units squared.

    Returns
    -------
    float
        The diagonal term, state units squared (1e-14 at PROCESS_NOISE, at least 1e-20).
    """
    return max(1e-14 * (level / PROCESS_NOISE) ** 2, 1e-20)


def nominal_model(model: Any, paddle_angle_deg: float = 0.0) -> Any:
    """The design model of a fixed controller: ``model``'s spacecraft (an env's truth
    model, :class:`spacecraft_env.FlexibleSpacecraftModel`) with nothing docked and
    the paddles at ``paddle_angle_deg`` (0: the nominal configuration).

    Parameters
    ----------
    model : FlexibleSpacecraftModel
        The truth model (``env.unwrapped.model``).
    paddle_angle_deg : float
        Paddle angle of the design configuration, deg.

    Returns
    -------
    FlexibleSpacecraftModel
        ``model.nominal(paddle_angle_deg)``: a constant model of the same
        spacecraft.
    """
    return model.nominal(paddle_angle_deg)


class _EnvController(Controller):
    """Shared plumbing: layout of observations, torque scaling, reference."""

    def __init__(self, env: gym.Env) -> None:
        env = getattr(env, "unwrapped", env)
        if not all(hasattr(env, a) for a in ("model", "observation_layout", "max_torque")):
            raise TypeError(f"{type(self).__name__} flies a flexible-spacecraft environment "
                            f"(spacecraft_env, e.g. gym.make('spacecraft_env:"
                            f"FlexibleSpacecraft-v2')); got {type(env).__name__}")
        self.env = env
        self.max_torque = float(env.max_torque)
        self.dt = float(env.model.dt)
        layout = env.observation_layout
        missing = [g for g in ("attitude", "rate") if g not in layout]
        if missing:
            raise ValueError(f"controllers need the observation groups {missing}; "
                             f"the env observes {layout.names}")
        self._att = layout.indices("attitude")
        self._rate = layout.indices("rate")
        #: The sensor groups the controller sees, in observation order.
        self.measured_layout = layout.sensors()
        # observation entries of the plant outputs, and their rows of model.C
        self._meas_obs, self._meas_rows = match_groups(layout, env.model.output_layout)
        self._last = np.zeros(3, dtype=np.float32)
        self.n_nonfinite = 0
        # an observed reference (the "reference" group) serves predict(obs) without info
        self._ref_obs = layout.indices("reference") if "reference" in layout.names else None
        self._obs = None

    def _reference(self, info: dict[str, Any] | None) -> np.ndarray:
        """The reference attitude (rad): ``info["reference"]``, else the observed
        ``"reference"`` group of the last observation, else zero."""
        if info is not None and "reference" in info:
            return np.asarray(info["reference"], dtype=float)
        if self._ref_obs is not None and self._obs is not None:
            ref = self._obs[self._ref_obs]
            if np.isfinite(ref).all():
                return ref
        return np.zeros(3)

    def _to_action(self, torque: np.ndarray) -> np.ndarray:
        # np.clip costs more than the two ufuncs on three numbers (same result, NaN kept)
        action = np.minimum(np.maximum(torque / self.max_torque, -1.0), 1.0).astype(np.float32)
        self._last = action
        return action

    def _observation(self, obs: ArrayLike) -> np.ndarray:
        """``obs`` as a float array of the env's observation shape (NaN allowed).

        Raises
        ------
        TypeError
            For non-numeric data (strings, objects): a numeric string is not
            an observation.
        ValueError
            For any other shape.
        """
        obs = np.asarray(obs)
        if obs.dtype.kind not in "fiu":
            raise TypeError(f"observation must be a real numeric array of shape "
                            f"{self.env.observation_space.shape}, got dtype {obs.dtype}")
        obs = obs.astype(float, copy=False)
        if obs.shape != self.env.observation_space.shape:
            raise ValueError(f"observation must have shape {self.env.observation_space.shape}, "
                             f"got {obs.shape}")
        self._obs = obs
        return obs

    def _check_obs(self, obs: ArrayLike) -> np.ndarray | None:
        """``obs`` if finite, else None (counted in ``n_nonfinite``)."""
        obs = self._observation(obs)
        if not np.isfinite(obs).all():
            self.n_nonfinite += 1
            return None
        return obs

    def reset(self, seed: int | None = None) -> None:
        self._last = np.zeros(3, dtype=np.float32)
        self.n_nonfinite = 0


class PD(_EnvController):
    """Attitude PD: ``u = -J (wc^2 (psi - ref) + 2 zeta wc omega)`` per axis.

    Parameters
    ----------
    env : gymnasium.Env
    bandwidth : float
        wc, rad/s (default 0.05, a decade below the first flexible mode).
    damping : float
        zeta.
    """

    name = "PD"

    def __init__(self, env: gym.Env, bandwidth: float = 0.05, damping: float = 0.7) -> None:
        super().__init__(env)
        if not bandwidth > 0 or not damping > 0:
            raise ValueError("bandwidth and damping must be positive")
        self.inertia = np.diag(nominal_model(self.env.model).inertia(0.0)).copy()
        self.kp = self.inertia * bandwidth**2
        self.kd = self.inertia * 2 * damping * bandwidth

    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        obs = self._check_obs(obs)
        if obs is None:
            return self._last
        err = obs[self._att] - self._reference(info)
        return self._to_action(-self.kp * err - self.kd * obs[self._rate])


class _LQGController(_EnvController):
    """Shared plumbing of the LQG controllers: the law, the integral, saturation."""

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None) -> None:
        super().__init__(env)
        self.weights = weights or LQRWeights()
        self.kf: KalmanPredictor | None = None
        model = self.env.model
        self._c = model.C[self._meas_rows]
        self._c_att = model.C[model.output_layout.slice("attitude")]
        self._noise_var = np.maximum(self.env.noise_std[self._meas_rows], 1e-9) ** 2
        self.law = LQGLaw(output_weight(self.measured_layout, self.weights), self.weights,
                          self.dt)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.law.reset()
        self.kf = None
        self._pending: tuple[np.ndarray, ...] | None = None
        #: The action actually sent last, when a wrapping controller changed ours (an
        #: excitation added); the filter's time update uses it when ``info`` is absent.
        self.applied_action: np.ndarray | None = None

    def _filter(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, qn: np.ndarray,
                noise_var: np.ndarray, y: np.ndarray | None,
                info: dict[str, Any] | None) -> np.ndarray:
        """``x_{k|k}`` from the controller's Kalman filter on the model ``(a, b, c)``.

        The time update of the previous step is done here, with the torque the
        env reports as applied (``info["torque"]``: after saturation, and with
        anything another controller added, such as an excitation); without it,
        with this controller's own last action.
        """
        pending, self._pending = self._pending, (a, b, qn)
        if self.kf is None or self.kf.n != a.shape[0]:
            # initial attitudes of a few degrees: 1e-3 rad^2 of prior variance
            self.kf = KalmanPredictor(a.shape[0], initial_covariance=1e-3)
        elif pending is not None:
            return self.kf.advance(*pending, self._applied_torque(info), c, noise_var, y,
                                   a_now=a)
        return self.kf.correct(c, noise_var, y, a=a)

    def _applied_torque(self, info: dict[str, Any] | None) -> np.ndarray:
        """The torque (N m, (3,)) applied after this controller's last action.

        What the env reports (``info["torque"]``: after saturation, actuator
        delay and rate limit, and with anything a wrapper added to our
        action, such as an excitation or an agent's residual); without
        ``info``, what a wrapping controller says it sent
        (:attr:`applied_action`), else our own last action.
        """
        if info is not None and "torque" in info:
            return np.asarray(info["torque"], dtype=float)
        sent = self.applied_action if self.applied_action is not None else self._last
        return sent.astype(float) * self.max_torque

    def _loop_radius(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, gain: np.ndarray,
                     qn: np.ndarray, noise_var: np.ndarray, truth: Any, t: float
                     ) -> float | None:
        """Spectral radius of this design's closed loop with the true plant frozen at ``t``
        (:meth:`_closed_loop`); None without a steady-state filter."""
        loop = self._closed_loop(a, b, c, gain, qn, noise_var, truth, t)
        return None if loop is None else float(np.abs(np.linalg.eigvals(loop)).max())

    def _closed_loop(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, gain: np.ndarray,
                     qn: np.ndarray, noise_var: np.ndarray, truth: Any, t: float
                     ) -> np.ndarray | None:
        """Transition matrix of this design's closed loop with the true plant frozen at
        ``t``, state ``[x; xhat; z]``.

        The loop: plant ``x+ = A_t x + B_t u``; the design's steady-state Kalman
        filter ``xf = xhat + L (y - C xhat)``, ``xhat+ = A xf + B u``, with
        ``y = C_t x`` (the measured rows); ``u = -G_x xf - G_z z`` and the
        integral ``z+ = z + dt C_att,t x`` (integrating, as near the reference).
        None when the design has no steady-state filter (noise-free sensors).
        """
        key = (id(a), id(c))
        cached = self.__dict__.get("_filter_gains", {})
        if key not in cached:
            try:
                cached[key] = steady_state_gain(a, c, qn, np.diag(noise_var))[0]
            except ValueError:        # e.g. noise-free sensors: no steady-state filter
                cached[key] = None
            self.__dict__["_filter_gains"] = cached
        filt = cached[key]
        if filt is None:
            return None
        true = truth.discrete(t)
        b_true = self.env.actuator_gain * true.B        # the torque the plant receives
        c_t = truth.C[self._meas_rows] if c.shape[0] == len(self._meas_rows) else \
            truth.C[self._meas_rows][self._rows]
        c_att = truth.C[truth.output_layout.slice("attitude")]
        nt, n = true.A.shape[0], a.shape[0]
        gx, gz = gain[:, :n], gain[:, n:]
        to_u = np.hstack([-gx @ filt @ c_t, -gx @ (np.eye(n) - filt @ c), -gz])
        top = np.hstack([true.A, np.zeros((nt, n + 3))]) + b_true @ to_u
        mid = np.hstack([a @ filt @ c_t, a @ (np.eye(n) - filt @ c), np.zeros((n, 3))]) \
            + b @ to_u
        bottom = np.hstack([self.dt * c_att, np.zeros((3, n)), np.eye(3)])
        return np.vstack([top, mid, bottom])

    def _apply(self, gain: np.ndarray, x: np.ndarray, a: np.ndarray, obs: np.ndarray,
               info: dict[str, Any] | None) -> np.ndarray:
        """Torque from the law for state ``x`` (model ``a``), integral advanced; the action."""
        ref = self._reference(info)
        torque = self.law.torque(gain, x, self.law.equilibrium(a, self._c_att, ref))
        action = self._to_action(torque)
        saturated = bool((np.abs(torque) > self.max_torque).any())
        self.law.integrate(obs[self._att] - ref, saturated)
        return action


class FixedLQG(_LQGController):
    """Fixed LQG: LQR with integral action and a steady-state Kalman filter, both
    designed once on the nominal configuration (paddles at 0 deg, nothing docked),
    as a fixed design is.

    Parameters
    ----------
    env : gymnasium.Env
    weights : LQRWeights
    paddle_angle_deg : float
        Paddle angle of the design configuration (default 0: nominal).
    """

    name = "fixed LQG"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None,
                 paddle_angle_deg: float = 0.0) -> None:
        super().__init__(env, weights)
        design = nominal_model(self.env.model, paddle_angle_deg).discrete(0.0)
        self.a, self.b = design.A, design.B
        self.gain = self.law.design(self.a, self.b, self._c, self._c_att)
        self.qn = process_noise(self.b)
        self.reset()

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        obs = self._observation(obs)
        x = self._filter(self.a, self.b, self._c, self.qn, self._noise_var, obs[self._meas_obs],
                         info)
        action = (self._apply(self.gain, x, self.a, obs, info)
                  if np.isfinite(obs[self._att]).all() else self._last)
        return action

    @single_threaded_blas
    def closed_loop_radius(self, truth: Any, t: float) -> float | None:
        """Spectral radius of the fixed design's loop with the true plant frozen at ``t``
        (> 1: the loop grows there, however slowly).

        Returns
        -------
        float or None
            The spectral radius; None when the design has no steady-state filter (noise-
            free sensors).
        """
        return self._loop_radius(self.a, self.b, self._c, self.gain, self.qn, self._noise_var,
                                 truth, t)


class ScheduledLQG(_LQGController):
    """Gain-scheduled LQG on the measured paddle angle (``info["paddle_angle"]``).

    Fixed LQG designs (nominal mass, nothing docked) at paddle angles every
    ``step_deg`` over a full turn; each step flies the design nearest the
    measured angle. All designs share the truth model's coordinates, so the
    Kalman state carries over from one to the next.

    Parameters
    ----------
    env : gymnasium.Env
    weights : LQRWeights
    step_deg : float
        Spacing of the design angles, deg.
    """

    name = "scheduled LQG"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None,
                 step_deg: float = 15.0) -> None:
        super().__init__(env, weights)
        if not 0 < step_deg <= 180:
            raise ValueError(f"step_deg must be in (0, 180], got {step_deg}")
        self.angles = np.deg2rad(np.arange(0.0, 360.0, step_deg))
        self.designs = []
        for angle in self.angles:
            design = nominal_model(self.env.model, float(np.rad2deg(angle))).discrete(0.0)
            self.law.tracker = None                     # each design from scratch
            gain = self.law.design(design.A, design.B, self._c, self._c_att)
            qn = process_noise(design.B)
            self.designs.append((design.A, design.B, gain, qn))
        self.reset()

    def _design(self, info: dict[str, Any] | None) -> tuple[np.ndarray, ...]:
        if info is None or PADDLE_ANGLE not in info:
            raise ValueError(f"ScheduledLQG needs the env's info dict with {PADDLE_ANGLE!r}")
        angle = float(info[PADDLE_ANGLE]) % (2 * np.pi)
        gap = np.abs((self.angles - angle + np.pi) % (2 * np.pi) - np.pi)
        return self.designs[int(np.argmin(gap))]

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        a, b, gain, qn = self._design(info)
        obs = self._observation(obs)
        x = self._filter(a, b, self._c, qn, self._noise_var, obs[self._meas_obs],
                         info)
        action = (self._apply(gain, x, a, obs, info)
                  if np.isfinite(obs[self._att]).all() else self._last)
        return action

    @single_threaded_blas
    def closed_loop_radius(self, truth: Any, t: float) -> float | None:
        """Spectral radius of the design in use at ``t`` (the true paddle angle's) with
        the true plant frozen at ``t``.

        Returns
        -------
        float or None
            The spectral radius; None when the design has no steady-state filter (noise-
            free sensors).
        """
        a, b, gain, qn = self._design({"paddle_angle": truth.scenario.paddle_angle(t)})
        return self._loop_radius(a, b, self._c, gain, qn, self._noise_var, truth, t)


class _Notch:
    """Second-order notch (biquad, transposed direct form II) on several channels."""

    def __init__(self, frequency_hz: float, quality: float, dt: float, channels: int) -> None:
        self.b, self.a = iirnotch(frequency_hz, quality, fs=1.0 / dt)
        self.z = np.zeros((2, channels))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        b, a, z = self.b, self.a, self.z
        y = b[0] * x + z[0]
        z[0] = b[1] * x - a[1] * y + z[1]
        z[1] = b[2] * x - a[2] * y
        return y

    def reset(self) -> None:
        self.z[:] = 0.0


class RobustLQG(_LQGController):
    """A fixed design that no paddle angle can destabilize: rigid-body LQG behind notches.

    The flexible modes' coupling changes sign with the paddle angle, so no
    fixed design can count on it. This one leaves them alone: the LQG is
    designed on the rigid body only (nominal inertia; attitude and rate
    measurements), the measurements pass a notch at the first paddle and
    antenna modes before the filter, and the bandwidth stays a decade below
    them, as a classical design would (docs/design/control.md). It gives up
    active vibration damping in exchange.

    Parameters
    ----------
    env : gymnasium.Env
    weights : LQRWeights
    notch_hz : float
        Notch centre, Hz (default 0.083, between the 0.077 and 0.09 Hz modes).
    notch_quality : float
        Notch quality factor (centre / -3 dB width; default 2: 0.06-0.11 Hz).
    """

    name = "robust LQG"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None,
                 notch_hz: float = 0.083, notch_quality: float = 2.0) -> None:
        super().__init__(env, weights)
        inv_j = np.linalg.inv(nominal_model(self.env.model).inertia(0.0))
        dt = self.dt
        self.a = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
        self.b = np.vstack([0.5 * dt * dt * inv_j, dt * inv_j])
        layout = self.measured_layout
        rows = np.concatenate([layout.indices("attitude"), layout.indices("rate")])
        self._rows = rows
        self._c = np.zeros((rows.size, 6))
        self._c[:3, :3] = np.eye(3)
        self._c[3:, 3:] = np.eye(3)
        self._c_att = self._c[:3]
        self._noise_var = self._noise_var[rows]
        qy = output_weight(layout, self.weights)[np.ix_(rows, rows)]
        self.law = LQGLaw(qy, self.weights, dt)
        self.gain = self.law.design(self.a, self.b, self._c, self._c_att)
        self.qn = process_noise(self.b)
        self.notch = _Notch(notch_hz, notch_quality, dt, rows.size)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.notch.reset()

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        obs = self._observation(obs)
        y = obs[self._meas_obs][self._rows]
        if np.isfinite(y).all():
            y = self.notch(y)
        x = self._filter(self.a, self.b, self._c, self.qn, self._noise_var, y, info)
        action = (self._apply(self.gain, x, self.a, obs, info)
                  if np.isfinite(obs[self._att]).all() else self._last)
        return action


class OracleLQG(_LQGController):
    """LQG on the true model of every step, with a Kalman filter on the measured
    outputs: the fair reference for an adaptive controller (same law, same
    measurements, the model known instead of identified).

    It reads ``info["time"]`` for the current true model.

    Parameters
    ----------
    env : gymnasium.Env
        The environment it flies (wrappers allowed; its ``unwrapped`` truth
        model, observation layout and ``max_torque`` are read).
    weights : LQRWeights, optional
        Weights of the design (default :class:`LQRWeights`'s defaults).
    noise_intensity : float
        White torque per axis, N m, its filter assumes (default
        :data:`PROCESS_NOISE`, as every fixed design's filter). The plant's
        true statistics are ``env.unwrapped.disturbance_std`` (0 for the
        registered ids): that filter is the tight oracle, the optimum of the
        same law for what it knows.
    """

    name = "oracle LQG"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None,
                 noise_intensity: float = PROCESS_NOISE) -> None:
        super().__init__(env, weights)
        if not (np.isfinite(noise_intensity) and noise_intensity >= 0):
            raise ValueError(f"noise_intensity must be a torque >= 0 N m, got "
                             f"{noise_intensity}")
        self.noise_intensity = float(noise_intensity)
        self.reset()

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        if info is None or "time" not in info:
            raise ValueError("OracleLQG needs the env's info dict with 'time'")
        sys_ = self.env.model.discrete(float(info["time"]))
        a, b = sys_.A, self.env.actuator_gain * sys_.B      # the true plant, efficiency too
        qn = process_noise(b, self.noise_intensity)
        obs = self._observation(obs)
        x = self._filter(a, b, self._c, qn, self._noise_var, obs[self._meas_obs],
                         info)
        gain = self.law.design(a, b, self._c, self._c_att)
        action = (self._apply(gain, x, a, obs, info)
                  if np.isfinite(obs[self._att]).all() else self._last)
        return action


class OracleLQR(_EnvController):
    """LQR re-designed every step on the true time-varying model, full true state.

    An upper bound no measured loop reaches: it reads ``info["state"]`` and
    ``info["time"]``. Each step's model is solved exactly
    (:class:`controllers.riccati.RiccatiTracker`).

    Parameters
    ----------
    env : gymnasium.Env
        The environment it flies (wrappers allowed; its ``unwrapped`` truth
        model, observation layout and ``max_torque`` are read).
    weights : LQRWeights, optional
        Weights of the design (default :class:`LQRWeights`'s defaults; the
        integral weight is not used: there is no integral action).
    """

    name = "full-state oracle"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None) -> None:
        super().__init__(env)
        self.weights = weights or LQRWeights()
        self.kf: KalmanPredictor | None = None
        model = self.env.model
        self._qy = output_weight(model.output_layout, self.weights)
        self._r = self.weights.torque * np.eye(3)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        model = self.env.model
        q = model.C.T @ self._qy @ model.C + self.weights.eps * np.eye(model.n)
        self._tracker = RiccatiTracker(q, self._r)

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        if info is None or "state" not in info or "time" not in info:
            raise ValueError("OracleLQR needs the env's info dict with 'state' and 'time'")
        model = self.env.model
        sys_ = model.discrete(float(info["time"]))
        gain = self._tracker.design(sys_.A, self.env.actuator_gain * sys_.B)
        x_ref = equilibrium_state(sys_.A, model.C[model.output_layout.slice("attitude")],
                                  self._reference(info))
        return self._to_action(-gain @ (np.asarray(info["state"]) - x_ref))


class TrueModelIdentifier:
    """An identifier that knows the truth: the same-law oracle's "identifier".

    It answers the adaptive LQG's questions (:class:`controllers.adaptive.AdaptiveLQG`)
    with the environment's true model at the current time (``model``, its
    Kalman filter state, an exactly known rigid-body gain), so the adaptive
    loop's own law flown on it separates what identification costs from what
    the law costs. It reads the env's truth and time: an oracle, not an
    identifier.

    Parameters
    ----------
    env : gymnasium.Env
    """

    def __init__(self, env: gym.Env) -> None:
        self.env = getattr(env, "unwrapped", env)
        model = self.env.model
        self._rows = match_groups(self.env.observation_layout, model.output_layout)[1]
        self.dt = float(model.dt)
        self.warmup = 1
        self.events: tuple = ()
        self._noise_var = np.maximum(self.env.noise_std[self._rows], 1e-9) ** 2
        self.reset()

    def reset(self) -> None:
        """Start of an episode."""
        self._k = 0
        self.kf = KalmanPredictor(self.env.model.n, initial_covariance=1e-3)

    def restart(self) -> None:
        self.reset()

    @property
    def rigid_states(self) -> tuple[slice, slice]:
        nd = self.env.model.n_dof
        return slice(0, 3), slice(nd, nd + 3)

    def _system(self) -> Any:
        true = self.env.model.discrete(self._k * self.dt)
        gain = self.env.actuator_gain
        # the torque the plant receives per torque commanded: the family's efficiency
        return true if gain == 1.0 else SimpleNamespace(A=true.A, B=gain * true.B)

    @property
    def model(self) -> StateSpaceModel:
        true = self._system()
        c = self.env.model.C[self._rows]
        gain = self.kf.gain if self.kf.gain is not None else np.zeros((c.shape[1], c.shape[0]))
        return StateSpaceModel(true.A, true.B, c, np.zeros((c.shape[0], 3)), gain, dt=self.dt)

    @property
    def rigid_gain(self) -> RigidGainEstimate:
        gain = np.linalg.inv(self.env.model.inertia(self._k * self.dt))
        return RigidGainEstimate(self.env.actuator_gain * gain, np.zeros((9, 9)))

    def filtered_state(self, y: ArrayLike) -> np.ndarray:
        """``x_{k|k}``: the true model's Kalman filter corrected by the measurements ``y``.

        Returns
        -------
        (n,) ndarray
            The filtered true state (the filter itself unchanged).
        """
        c = self.env.model.C[self._rows]
        y = np.asarray(y, dtype=float)
        return self.kf.filtered(c, self._noise_var, np.where(np.isfinite(y), y, np.nan))

    def update(self, u: ArrayLike, y: ArrayLike) -> None:
        true = self._system()
        qn = process_noise(true.B)
        y = np.asarray(y, dtype=float)
        self.kf.update(true.A, true.B, self.env.model.C[self._rows], qn, self._noise_var,
                       np.asarray(u, dtype=float), np.where(np.isfinite(y), y, np.nan))
        self._k += 1
