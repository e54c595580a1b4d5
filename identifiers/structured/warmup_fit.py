"""What the identifiers that fit once to their warm-up and then hold the fit share.

:class:`WarmupFit` records the samples until the warm-up is over, calls the
host's ``_fit`` (retried once the record is half a warm-up longer when it
fails: each attempt is a nonlinear fit of seconds), then runs a Kalman filter
on the held model (:class:`~identifiers.structured.state_filter.ModelFilter`),
its measurement noise the fit's residual per output and its process noise an
unmodelled torque.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from identifiers.core.kalman import KalmanPredictor
from identifiers.structured.state_filter import ModelFilter

__all__ = ["WarmupFit"]


class WarmupFit(ModelFilter):
    """Mixin: the record, the fit's hold and the filter on it.

    The host provides ``process_torque`` (N m per axis), ``_fit() -> bool``
    (fit the record, set ``fit`` and ``_mats``, start the filter with
    :meth:`_start_filter`; False when it failed) and may override
    :meth:`_record_item` (what each sample adds to the record) and
    :meth:`_follow` (run before the filter's update once the model is held).
    """

    _SHARED_ITEMS = ("_pending", "_record")

    def reset(self) -> None:
        super().reset()
        self.fit: Any = None
        self._record: list[tuple] = []
        self._retry_at = 0
        self._kf: KalmanPredictor | None = None
        self._mats: tuple[np.ndarray, ...] | None = None
        self._q = self._r = None
        self._seen: np.ndarray | None = None

    def restart(self) -> None:
        """A new record of the same plant: keep the fit, restart the state's filter
        (``x = 0`` with a vague covariance); before the fit, keep recording."""
        if self._kf is not None:
            self._kf = KalmanPredictor(self.n, initial_covariance=1.0)

    def _allocate(self, r: int, m: int) -> None:
        """Nothing before the fit: the record grows sample by sample."""

    def _record_item(self, u: np.ndarray, y: np.ndarray) -> tuple:
        return (u.copy(), y.copy())

    def _follow(self) -> None:
        """Hook before each filter update of the held model (default: nothing)."""

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        seen = self._seen if self._seen is not None else np.ones(y.size, dtype=bool)
        y = np.where(seen, y, np.nan)
        if self.fit is None:
            self._record.append(self._record_item(u, y))
            if len(self._record) >= max(self.warmup, self._retry_at) and not self._fit():
                # keep recording; try again once the record is half a warm-up longer
                self.fit = None
                self._retry_at = len(self._record) + max(self.warmup // 2, 1)
            return
        self._follow()
        a, b, c, _, _ = self._mats
        self._kf.update(a, b, c, self._q, self._r, u, y)

    def _process_noise(self, b: np.ndarray) -> np.ndarray:
        """The filter's process covariance for the normalized input matrix ``b``: an
        unmodelled torque of ``process_torque`` per axis."""
        return (self.process_torque / self._su.mean()) ** 2 * (b @ b.T) \
            + 1e-12 * np.eye(self.n)

    def _start_filter(self, x0: np.ndarray, u: np.ndarray, y: np.ndarray,
                      fitted: np.ndarray) -> None:
        """Empty the record and run the filter over it from the fitted initial state
        ``x0``: ``u``, ``y`` and the fit's outputs ``fitted`` normalized, (T, .)."""
        self._r = np.maximum(np.nanmean((y - fitted) ** 2, axis=0), 1e-12)
        self._record = []
        self._kf = KalmanPredictor(self.n, initial_covariance=1e-6)
        self._kf.x = x0.copy()
        a, b, c, _, _ = self._mats
        for uk, yk in zip(u, y, strict=True):
            self._kf.update(a, b, c, self._q, self._r, uk, yk)

    @property
    def ready(self) -> bool:
        """True once the model is fitted."""
        return self.fit is not None and super().ready
