"""The state of :class:`~identifiers.structured.rigid_flexible.RigidFlexibleIdentifier`:
a Kalman filter on its own current model.

:class:`StateFilter` runs the time-varying Kalman filter
(:class:`~identifiers.core.kalman.KalmanPredictor`) whose predictor gain is
the exported model's ``K``: the sensor noise estimated from its innovations,
the unmodelled torque it assumes, the outlier guard on its normalized
innovations, the stand-in for a skipped output (its prediction), its
re-convergence after a rollback, and ``x_{k|k}`` for a controller.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["StateFilter"]

#: The diagonal of the attitude block of the state covariance.
_ATTITUDE_DIAGONAL = np.diag_indices(3)


class StateFilter:
    """Mixin of :class:`~identifiers.structured.rigid_flexible.RigidFlexibleIdentifier`:
    its Kalman filter, the noise it assumes and estimates, and the outlier guard."""

    def _process(self, u: np.ndarray, y: np.ndarray) -> None:
        # the base class replaces unusable samples by a stand-in and calls _step with
        # learn=False; remember whether this sample's y was real for the Kalman filter
        self._seen = np.isfinite(y)
        self._real = bool(self._seen.all())
        super()._process(u, y)

    def _admissible(self, u: np.ndarray, y: np.ndarray) -> bool | np.ndarray:
        kf = self._kf
        if self.outlier_threshold is None or kf is None or self._mats is None:
            return True
        inside = kf.within(self._mats[2], self._r, y, self.outlier_threshold)
        if not inside.all():
            # the base class counts it in n_outliers; the filter still uses the other outputs
            self._real = False
            self._seen = self._seen & inside
            return inside
        return True

    def _accept_outlier_run(self, u: np.ndarray, y: np.ndarray) -> None:
        self._real = True           # learned from after all: the filter uses it too
        self._seen = np.ones(self.n_outputs, dtype=bool)

    def _state_vector(self) -> np.ndarray | None:
        return None if self._kf is None else self._kf.x

    def _after_rollback(self) -> None:
        # the restored filter state is up to a check period old: let it re-converge
        if self._kf is not None:
            self._kf.inflate(np.diag(np.abs(np.diag(self._kf.P))) + 1e-3 * np.eye(self.n))

    def _fill_output(self) -> np.ndarray:
        if self._kf is None or self._mats is None:
            return np.zeros(self.n_outputs)
        return self._mats[2] @ self._kf.x

    def _measurement_noise(self, innovation: np.ndarray) -> None:
        """Sensor noise variance from the filter's innovations: white noise shows in
        their first difference (``E[(e_k - e_{k-1})^2] / 2 = R`` for white ``e``),
        slow model error barely does, so the filter keeps trusting the sensors
        where the model is wrong instead of mistaking model error for noise."""
        last = self._last_innovation
        self._last_innovation = innovation
        if last is None:
            return
        d2 = 0.5 * (innovation - last) ** 2
        self._noise_var = d2 if self._noise_var is None else 0.998 * self._noise_var + 0.002 * d2
        self._r = np.maximum(self._noise_var, 1e-12)

    def _process_noise(self) -> np.ndarray:
        """Unmodelled torque through B, plus an attitude random walk at half the noise.

        The matrix is rewritten in place at every call (only its attitude diagonal
        changes between exports): it is for the filter step at hand only."""
        if self._torque_noise[0] is not self._mats:      # B changes only at an export
            b = self._mats[1]
            q = (self.process_torque / self._su.mean()) ** 2 * (b @ b.T)
            self._torque_noise = (self._mats, q, q[_ATTITUDE_DIAGONAL])
        _, q, torque_diagonal = self._torque_noise
        q[_ATTITUDE_DIAGONAL] = torque_diagonal + 0.25 * self._r[self._att_rows]
        return q

    def filtered_state(self, y: ArrayLike) -> np.ndarray | None:
        """``x_{k|k}``: the Kalman filter's prediction corrected by ``y_k`` (physical units)."""
        if not self.ready or self._mats is None:
            return None
        y = np.asarray(y, dtype=float).reshape(-1)
        if y.shape != (self.n_outputs,):
            raise ValueError(f"y must have {self.n_outputs} entries, got shape {y.shape}")
        with np.errstate(invalid="ignore", over="ignore"):
            y_n = y / self._sy
        y_n = np.where(np.abs(y_n) <= self.max_abs, y_n, np.nan)
        return self._kf.filtered(self._mats[2], self._r, y_n)
