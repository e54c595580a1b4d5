"""Baseline attitude controllers: PD, fixed LQG (t = 0 design), oracle LQR.

All read the observation layout, ``max_torque`` and the truth model from the
environment they are built for (``env.unwrapped``), and return normalized
torques in [-1, 1] (saturated).

Weights (:class:`LQRWeights`) penalize outputs, ``Q = C^T Q_y C + eps I``
(docs/design/control.md), relative to the nominal sensor levels that the
environments' reward uses (1 deg, 0.1 deg/s, 1 cm) and ``R = r I`` per
(N m)^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import solve_discrete_are

from controllers.base import Controller
from controllers.riccati import RiccatiTracker, dlqr
from spacecraft_conventions import OutputLayout, match_groups, single_threaded_blas

__all__ = ["LQR", "PD", "LQRWeights", "OracleLQR", "equilibrium_state", "output_weight"]


@dataclass(frozen=True)
class LQRWeights:
    """Output and torque weights of the LQR designs.

    ``Q_y = diag(attitude / (1 deg)^2 [x3], rate / (0.1 deg/s)^2 [x3],
    deflection / (1 cm)^2 [per sensor])``, ``Q = C^T Q_y C + eps I``,
    ``R = torque * I`` per (N m)^2. The defaults give a closed-loop attitude
    bandwidth of roughly 0.1 rad/s, below the first flexible mode (0.48 rad/s).
    """

    attitude: float = 1.0
    rate: float = 1.0
    deflection: float = 0.1
    torque: float = 0.3
    eps: float = 1e-6

    def __post_init__(self) -> None:
        for name in ("attitude", "rate", "deflection", "eps"):
            if not np.isfinite(getattr(self, name)) or getattr(self, name) < 0:
                raise ValueError(f"LQR weight {name} must be finite and >= 0")
        if not np.isfinite(self.torque) or self.torque <= 0:
            raise ValueError("LQR torque weight must be positive (R positive definite)")


def output_weight(layout: OutputLayout, weights: LQRWeights) -> np.ndarray:
    """Diagonal output weight ``Q_y`` for the sensor groups of ``layout``.

    Each channel's weight is its group's weight divided by the square of the
    group's nominal level (:meth:`OutputLayout.scales`).
    """
    per_group = {"attitude": weights.attitude, "rate": weights.rate,
                 "deflection": weights.deflection}
    sensors = layout.sensors()
    w = np.concatenate([np.full(size, per_group[g]) for g, size in sensors.groups])
    return np.diag(w / sensors.scales() ** 2)


def equilibrium_state(a: np.ndarray, c_att: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Zero-input equilibrium with attitude ``reference``: ``(A - I) x = 0``, ``C_att x = ref``.

    Least-squares solution (exact for the rigid-body equilibria of the true
    model; the closest one for an identified model).
    """
    n = a.shape[0]
    lhs = np.vstack([a - np.eye(n), c_att])
    rhs = np.concatenate([np.zeros(n), reference])
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0]


class _EnvController(Controller):
    """Shared plumbing: layout of observations, torque scaling, reference."""

    def __init__(self, env: gym.Env) -> None:
        env = getattr(env, "unwrapped", env)
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

    @staticmethod
    def _reference(info: dict[str, Any] | None) -> np.ndarray:
        if info is not None and "reference" in info:
            return np.asarray(info["reference"], dtype=float)
        return np.zeros(3)

    def _to_action(self, torque: np.ndarray) -> np.ndarray:
        action = np.clip(torque / self.max_torque, -1.0, 1.0).astype(np.float32)
        self._last = action
        return action

    def _observation(self, obs: ArrayLike) -> np.ndarray:
        """``obs`` as a float array of the env's observation shape (NaN allowed).

        Raises
        ------
        ValueError
            For any other shape.
        """
        obs = np.asarray(obs, dtype=float)
        if obs.shape != self.env.observation_space.shape:
            raise ValueError(f"observation must have shape {self.env.observation_space.shape}, "
                             f"got {obs.shape}")
        return obs

    def _check_obs(self, obs: ArrayLike) -> np.ndarray | None:
        """``obs`` if finite, else None (counted in ``n_nonfinite``)."""
        obs = self._observation(obs)
        if not np.all(np.isfinite(obs)):
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
        self.inertia = np.diag(self.env.model.inertia(0.0)).copy()
        self.kp = self.inertia * bandwidth**2
        self.kd = self.inertia * 2 * damping * bandwidth

    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        obs = self._check_obs(obs)
        if obs is None:
            return self._last
        err = obs[self._att] - self._reference(info)
        return self._to_action(-self.kp * err - self.kd * obs[self._rate])


class LQR(_EnvController):
    """Fixed LQG: LQR and a steady-state Kalman filter designed on the t = 0 true model.

    Parameters
    ----------
    env : gymnasium.Env
    weights : LQRWeights
    process_noise : float
        Torque-noise standard deviation (N m) assumed by the Kalman filter.
    """

    name = "LQR"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None,
                 process_noise: float = 0.05) -> None:
        super().__init__(env)
        self.weights = weights or LQRWeights()
        model = self.env.model
        sys_ = model.discrete(0.0)
        self.a, self.b = sys_.A, sys_.B
        self.c = sys_.C[self._meas_rows]
        q = (self.c.T @ output_weight(self.measured_layout, self.weights) @ self.c
             + self.weights.eps * np.eye(model.n))
        self.gain, _ = dlqr(self.a, self.b, q, self.weights.torque * np.eye(3))
        noise = np.maximum(self.env.noise_std[self._meas_rows], 1e-9)
        qn = process_noise**2 * self.b @ self.b.T + 1e-14 * np.eye(model.n)
        p = solve_discrete_are(self.a.T, self.c.T, qn, np.diag(noise**2))
        self.filter_gain = p @ self.c.T @ np.linalg.inv(self.c @ p @ self.c.T + np.diag(noise**2))
        self.c_att = sys_.C[model.output_layout.slice("attitude")]
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.x_pred = np.zeros(self.a.shape[0])

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        obs = self._check_obs(obs)
        if obs is None:
            self.x_pred = self.a @ self.x_pred + self.b @ (self._last * self.max_torque)
            return self._last
        y = obs[self._meas_obs]
        x = self.x_pred + self.filter_gain @ (y - self.c @ self.x_pred)
        x_ref = equilibrium_state(self.a, self.c_att, self._reference(info))
        action = self._to_action(-self.gain @ (x - x_ref))
        self.x_pred = self.a @ x + self.b @ (action * self.max_torque)
        return action


class OracleLQR(_EnvController):
    """LQR re-designed every step on the true time-varying model, full true state.

    An upper bound: it reads ``info["state"]`` and ``info["time"]``.
    Re-designs are warm-started (:class:`~controllers.riccati.RiccatiTracker`).
    """

    name = "oracle LQR"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None) -> None:
        super().__init__(env)
        self.weights = weights or LQRWeights()
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
        if info is None or "state" not in info:
            raise ValueError("OracleLQR needs the env's info dict with 'state' and 'time'")
        model = self.env.model
        sys_ = model.discrete(float(info["time"]))
        gain = self._tracker.design(sys_.A, sys_.B)
        x_ref = equilibrium_state(sys_.A, model.C[model.output_layout.slice("attitude")],
                                  self._reference(info))
        return self._to_action(-gain @ (np.asarray(info["state"]) - x_ref))
