"""Sliding-window SVD-based PBSID: the batch method refitted at every step.

The paper's SVD-based comparator: at each sample, :func:`identifiers.subspace.batch.pbsid`
(VARX least squares, weighted LK, SVD, least squares for the system
matrices) is run on the most recent ``window`` samples. Accurate and simple,
but O(window p^2 (r + m)^2) per step. Each refit comes out in its own SVD
basis; it is aligned to the previous refit's basis (see
:class:`WindowedPBSID`), so successive models share state coordinates.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.checks import positive_int
from identifiers.core.online import OnlineIdentifier
from identifiers.subspace.batch import pbsid

__all__ = ["WindowedPBSID"]


class WindowedPBSID(OnlineIdentifier):
    """Batch PBSID refitted on a sliding window at every step.

    Every refit returns its model in a new SVD basis; the refit is aligned to
    the previous one by the least-squares similarity ``T`` that maps the new
    state estimates onto the previous ones over the samples both windows
    share, so successive models use one state basis (``consistent_basis``).

    Parameters
    ----------
    n, p : int
        Model order and past window.
    forgetting : float
        Exponential weighting of the window rows (1.0: uniform window).
    window : int
        Samples in the sliding window (default 500 = 50 s at dt = 0.1 s).
    refit_every : int
        Refit period in samples (1: every step, the paper's comparator).
    f : int, optional
        Future window of LK (default ``p``).
    regularization : float
        VARX Tikhonov term as a fraction of the window length (0: plain LS).
    dt, warmup, input_scale, output_scale
        See :class:`identifiers.core.online.OnlineIdentifier`; warm-up defaults to
        the window length.
    """

    consistent_basis = True
    _SIGNAL_STATE = ("_phi", "_u", "_y")

    def __init__(self, n: int, p: int = 15, forgetting: float = 1.0, *, window: int = 500,
                 refit_every: int = 1, f: int | None = None, dt: float = 0.1,
                 warmup: int | None = None, input_scale: ArrayLike | None = None,
                 output_scale: ArrayLike | None = None,
                 regularization: float = 0.0) -> None:
        self.window = positive_int("window", window)
        self.refit_every = positive_int("refit_every", refit_every)
        self.f = f
        if not (np.isfinite(regularization) and regularization >= 0):
            raise ValueError(f"regularization must be >= 0, got {regularization}")
        self.regularization = float(regularization)
        super().__init__(n, p, forgetting, dt=dt, warmup=warmup or window,
                         input_scale=input_scale, output_scale=output_scale)

    def reset(self) -> None:
        super().reset()
        self._u = self._y = None
        self._result = None
        self._state = None
        self._last_refit = 0

    def _allocate(self, r: int, m: int) -> None:
        if self.window - self.p <= self.p * (r + m):
            raise ValueError(f"window must exceed p (r + m + 1) = {self.p * (r + m + 1)} samples")
        self._u = np.zeros((self.window, r))
        self._y = np.zeros((self.window, m))

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        self._u[:-1] = self._u[1:]
        self._y[:-1] = self._y[1:]
        self._u[-1] = u
        self._y[-1] = y
        self._push(u, y)
        model = None if self._result is None else self._result.model
        if model is not None:  # propagate the state between refits
            e = y - model.C @ self._state - model.D @ u
            self._state = model.A @ self._state + model.B @ u + model.K @ e
        filled = self._k + 1
        if (learn and filled >= self.window and self._quiet == 0
                and (filled - self.window) % self.refit_every == 0):
            weights = None
            if self.forgetting < 1.0:
                weights = self.forgetting ** np.arange(self.window)[::-1]
            result = pbsid(self._u, self._y, self.n, self.p, self.f, dt=self.dt,
                           weights=weights, full_output=True,
                           regularization=self.regularization * self.window)
            self._align(result)
            self._result = result
            self._last_refit = self._k + 1
            self._state = result.next_state

    def _align(self, result) -> None:
        """Express ``result`` in the previous refit's state basis (in place)."""
        prev = self._result
        if prev is None:
            return
        shift = self._k + 1 - self._last_refit
        old, new = prev.states[shift:], result.states[:len(prev.states) - shift]
        if len(new) < 2 * self.n:
            return
        t_mat = np.linalg.lstsq(new, old, rcond=None)[0].T          # x_old ~ T x_new
        if not np.all(np.isfinite(t_mat)) or np.linalg.cond(t_mat) > 1e8:
            return
        result.model = result.model.transform(t_mat)
        result.states = result.states @ t_mat.T
        result.next_state = t_mat @ result.next_state

    def _matrices(self):
        if self._result is None:
            return None
        m = self._result.model
        return m.A, m.B, m.C, m.D, m.K

    def _current_state(self):
        return self._state

    def _state_vector(self) -> np.ndarray | None:
        return self._state
