"""The state of the structure-aware identifiers: a Kalman filter on their own model.

:class:`ModelFilter` is what
:class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier` and
:class:`identifiers.physical.physical_identifier.PhysicalFitIdentifier`
share: the sensor layout's checks, the model and state they export (attitude
and body rate first), the stand-in for a skipped output (its prediction),
the filter's re-convergence after a rollback and ``x_{k|k}`` for a
controller. :class:`StateFilter`, the rigid-flexible identifier's, runs the
time-varying Kalman filter (:class:`identifiers.core.kalman.KalmanPredictor`)
whose predictor gain is
the exported model's ``K``: the sensor noise estimated from its innovations,
the unmodelled torque it assumes and the outlier guard on its normalized
innovations.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.checks import all_finite
from identifiers.core.residual_statistics import mean_square_step

__all__ = ["ATTITUDE_STATES", "RATE_STATES", "ModelFilter", "StateFilter"]

#: States of the exported model that are the attitude (its first three) and
#: the body rate (the next three); the flexible modes follow.
ATTITUDE_STATES = slice(0, 3)
RATE_STATES = slice(3, 6)

#: The diagonal of the attitude block of the state covariance.
_ATTITUDE_DIAGONAL = np.diag_indices(3)


class ModelFilter:
    """Mixin of the structure-aware identifiers: their sensor layout and a Kalman filter
    on their own model.

    The host holds ``layout`` (its :class:`spacecraft_conventions.OutputLayout`),
    ``_kf`` (a :class:`identifiers.core.kalman.KalmanPredictor`, None before it has
    a model), ``_mats`` (the normalized ``(A, B, C, D, None)``, None before a model)
    and ``_r`` (the sensors' normalized noise variances).
    """

    def _check_sizes(self, r: int, m: int) -> None:
        if r != 3:
            raise ValueError(f"u must hold the 3 body torques, got {r} inputs")
        if m != self.layout.size:
            raise ValueError(f"y must have {self.layout.size} entries as the layout "
                             f"{self.layout.names} says, got {m}")

    def _output_names(self, m: int) -> tuple[str, ...]:
        return tuple(f"{name}[{j}]" for name, sl in self.layout
                     for j in range(sl.stop - sl.start))

    def _process(self, u: np.ndarray, y: np.ndarray) -> None:
        # the base class replaces unusable samples by a stand-in and calls _step with
        # learn=False; remember whether this sample's y was real for the Kalman filter
        self._seen = np.isfinite(y)
        self._real = bool(self._seen.all())
        super()._process(u, y)

    def _state_vector(self) -> np.ndarray | None:
        return None if self._kf is None else self._kf.x

    def _held_process_noise(self, b: np.ndarray) -> np.ndarray:
        """The filter's process covariance for the normalized input matrix ``b``: an
        unmodelled torque of ``process_torque`` per axis (N m, the host's)."""
        return (self.process_torque / self._su.mean()) ** 2 * (b @ b.T) \
            + 1e-12 * np.eye(self.n)

    def _after_rollback(self) -> None:
        # the restored filter state is up to a check period old: let it re-converge
        if self._kf is not None:
            self._kf.inflate(np.diag(np.abs(np.diag(self._kf.P))) + 1e-3 * np.eye(self.n))

    def _fill_output(self) -> np.ndarray:
        if self._kf is None or self._mats is None:
            return np.zeros(self.n_outputs)
        return self._mats[2] @ self._kf.x

    def filtered_state(self, y: ArrayLike) -> np.ndarray | None:
        """``x_{k|k}``: the Kalman filter's prediction corrected by ``y_k`` (physical units).

        Returns
        -------
        (n,) ndarray or None
            ``x_{k|k}``; None before the filter has a model.
        """
        if not self.ready or self._mats is None:
            return None
        y = np.asarray(y, dtype=float).reshape(-1)
        if y.shape != (self.n_outputs,):
            raise ValueError(f"y must have {self.n_outputs} entries, got shape {y.shape}")
        with np.errstate(invalid="ignore", over="ignore"):
            y_n = y / self._sy
        y_n = np.where(np.abs(y_n) <= self.max_abs, y_n, np.nan)
        return self._kf.filtered(self._mats[2], self._r, y_n)

    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        if self._mats is None:
            return None
        a, b, c, d, _ = self._mats
        gain = self._kf.gain if self._kf.gain is not None else np.zeros((a.shape[0], c.shape[0]))
        return a, b, c, d, gain

    def _current_state(self) -> np.ndarray | None:
        return None if self._mats is None else self._kf.x

    @property
    def rigid_states(self) -> tuple[slice, slice]:
        """Slices of the model state that are the attitude and the body rate."""
        return ATTITUDE_STATES, RATE_STATES


class StateFilter(ModelFilter):
    """Mixin of :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier`:
    its Kalman filter, the noise it assumes and estimates, and the outlier guard."""

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

    def _filter_step(self, u: np.ndarray, y: np.ndarray, real: bool,
                     seen: np.ndarray | None) -> None:
        """One step of the Kalman filter on the current model, and the sensor noise
        from its innovation. A sample that is not ``real`` gives the filter the outputs
        ``seen`` marks (none if ``seen`` is None): the others are stand-ins."""
        a, b, c, _, _ = self._mats
        y_kf = y if real else (None if seen is None else np.where(seen, y, np.nan))
        self._kf.update(a, b, c, self._process_noise(), self._r, u, y_kf)
        innovation = self._kf.innovation
        if real and innovation is not None and all_finite(innovation):
            self._measurement_noise(innovation)

    def _measurement_noise(self, innovation: np.ndarray) -> None:
        """Sensor noise variance from the filter's innovations: white noise shows in
        their first difference (``E[(e_k - e_{k-1})^2] / 2 = R`` for white ``e``),
        slow model error barely does, so the filter keeps trusting the sensors
        where the model is wrong instead of mistaking model error for noise."""
        last = self._last_innovation
        self._last_innovation = innovation
        if last is None:
            return
        change = innovation - last
        if self._noise_var is None:
            self._noise_var = 0.5 * change**2
        else:       # 0.998 R + 0.002 (d^2 / 2), compiled, in place (0.001 = 0.002 / 2 exactly)
            mean_square_step(self._noise_var, change, 0.998, 0.001)
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
