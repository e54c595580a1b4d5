"""Self-tuning LQR: re-designed every step from the online identifier.

Every control step k (docs/design/control.md):

1. take the identifier's state ``xhat_{k|k-1}``: the predictor state is
   already at the current time (for the APSA variant :attr:`state` propagates
   its lagged estimate with the identified predictor);
2. re-design the gain on the current identified ``(A, B, C)`` by a Riccati
   iteration warm-started from the last solution, with
   ``Q = C^T Q_y C + eps I``;
3. act ``u_k = -G (xhat_k - x_ref) + dither`` (saturated), with ``x_ref`` the
   identified model's zero-torque equilibrium at the reference attitude, so
   slews end without steady-state error;
4. feed ``(u_k, y_k)`` (the torque actually applied, the measured outputs) to
   the identifier.

Safeguards, each counted in :attr:`AdaptiveLQR.stats`: until the identifier
is warmed up and a first gain is accepted, a PD fallback acts; a new gain is
accepted only if it is finite and stabilizes the identified model
(``rho(A - B G) < 1``), otherwise the last accepted gain is kept; a
non-finite observation is passed to the identifier, which skips and counts
it, while the action comes from the identifier's predicted state as usual.
Dither: white Gaussian torque, ``dither`` x max_torque standard deviation
per axis, from a generator seeded by ``reset(seed)``.
"""

from __future__ import annotations

import logging
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike

from controllers.base import Controller
from controllers.baselines import PD, LQRWeights, _EnvController, equilibrium_state, output_weight
from controllers.riccati import RiccatiTracker, check_weights, spectral_radius
from identifiers import OnlineIdentifier, StateSpaceModel, default_identifier
from spacecraft_conventions import single_threaded_blas

__all__ = ["AdaptiveLQR"]

log = logging.getLogger(__name__)


class AdaptiveLQR(_EnvController):
    """LQR re-designed every step on the model of an online identifier.

    Parameters
    ----------
    env : gymnasium.Env
        Environment the controller is built for (layout, torque scale).
    identifier : identifiers.OnlineIdentifier, optional
        Default: :func:`identifiers.default_identifier` for the measured
        sensor groups, n the truth model's order. At 40 dB it needs about
        150 s of data for an accurate model (docs/results/identification.md);
        a 50 s warm-up with the PD fallback and a long memory are what kept
        the loop stable in every measured run.
    weights : LQRWeights
    dither : float
        Dither standard deviation as a fraction of ``max_torque``.
    iterations : int
        Riccati iterations per re-design.
    fallback : Controller, optional
        Acts until the first gain is accepted (default PD).
    """

    name = "adaptive LQR"

    def __init__(self, env: gym.Env, identifier: OnlineIdentifier | None = None,
                 weights: LQRWeights | None = None, dither: float = 0.01, iterations: int = 4,
                 fallback: Controller | None = None) -> None:
        super().__init__(env)
        if not (np.isfinite(dither) and dither >= 0):
            raise ValueError(f"dither must be >= 0, got {dither}")
        self.weights = weights or LQRWeights()
        self.dither = float(dither)
        self.iterations = int(iterations)
        model = self.env.model
        self._qy = output_weight(self.measured_layout, self.weights)
        self._r = self.weights.torque * np.eye(3)
        check_weights(self._qy, self._r)
        self._y_att = self.measured_layout.indices("attitude")
        if identifier is None:
            identifier = default_identifier(self.measured_layout, n=model.n, dt=model.dt)
        self.identifier = identifier
        self.fallback = fallback or PD(env)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.identifier.reset()
        self.fallback.reset(seed)
        self._rng = np.random.default_rng(seed)
        self.gain: np.ndarray | None = None
        self._tracker: RiccatiTracker | None = None
        self.stats = {"steps": 0, "fallback_steps": 0, "redesigns": 0, "rejected_unstable": 0,
                      "failed_redesigns": 0, "nonfinite_observations": 0}

    def _redesign(self, model: StateSpaceModel) -> None:
        a, b, c = model.A, model.B, model.C
        q = c.T @ self._qy @ c + self.weights.eps * np.eye(a.shape[0])
        try:
            if self._tracker is None:
                self._tracker = RiccatiTracker(q, self._r, self.iterations)
            else:
                self._tracker.q = q
            gain = self._tracker.design(a, b)
        except (ValueError, np.linalg.LinAlgError) as exc:
            self.stats["failed_redesigns"] += 1
            self._tracker = None
            log.debug("redesign failed: %s", exc)
            return
        if not np.all(np.isfinite(gain)) or spectral_radius(a - b @ gain) >= 1.0:
            self.stats["rejected_unstable"] += 1
            return
        self.gain = gain
        self.stats["redesigns"] += 1

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        self.stats["steps"] += 1
        obs = self._observation(obs)
        if not np.all(np.isfinite(obs)):
            self.stats["nonfinite_observations"] += 1
        y = obs[self._meas_obs]
        x_hat = self.identifier.state
        model = self.identifier.model
        if model is not None and x_hat is not None and np.all(np.isfinite(model.A)):
            self._redesign(model)
        if self.gain is None or x_hat is None:
            self.stats["fallback_steps"] += 1
            action = self.fallback.act(obs, info)
            torque = action * self.max_torque
        else:
            x_ref = equilibrium_state(model.A, model.C[self._y_att], self._reference(info))
            torque = -self.gain @ (x_hat - x_ref)
        if self.dither > 0:
            torque = torque + self.dither * self.max_torque * self._rng.standard_normal(3)
        action = self._to_action(torque)
        # a non-finite measurement goes to the identifier too: it skips and counts it
        # and keeps its past window aligned in time
        self.identifier.update(action.astype(float) * self.max_torque, y)
        return action
