"""The compiled kernels of :class:`identifiers.core.kalman.KalmanPredictor`.

Each is one step of the filter's equations on C-contiguous float64 arrays,
compiled with numba: at the sizes of this project (6-46 states) the
interpreter's per-call overhead is most of the cost of a step done with
separate numpy calls.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

__all__: list[str] = []      # private kernels; the filter is identifiers.core.kalman's


def _f64(m: ArrayLike) -> np.ndarray:
    """``m`` as a C-contiguous float64 array (no copy when it is one): what the
    compiled kernels take."""
    return np.ascontiguousarray(m, dtype=np.float64)


@njit(cache=True, nogil=True)
def _correct_all(x: np.ndarray, p: np.ndarray, c: np.ndarray, r: np.ndarray, y: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Measurement update with every output of ``y``, compiled: ``x_{k|k}``, ``P_{k|k}``,
    the filter gain ``L``, the innovation, its covariance and whether the latter
    could be factored (if not: the prediction unchanged and a zero gain)."""
    pct = p @ c.T
    s = c @ pct
    for i in range(s.shape[0]):
        s[i, i] += r[i]
    e = y - c @ x
    try:
        gain = np.linalg.solve(s, pct.T).T
    except Exception:                  # numba raises a plain exception on a singular matrix
        return x, p, np.zeros((x.shape[0], y.shape[0])), e, s, False
    return x + gain @ e, p - gain @ pct.T, gain, e, s, True


@njit(cache=True, nogil=True)
def _predict(x: np.ndarray, p: np.ndarray, a: np.ndarray, b: np.ndarray, q: np.ndarray,
             u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Time update, compiled: ``(A x + B u, sym(A P A^T + Q))``."""
    pn = a @ p @ a.T + q
    return a @ x + b @ u, 0.5 * (pn + pn.T)


@njit(cache=True, nogil=True)
def _full_update(x: np.ndarray, p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray,
                 q: np.ndarray, r: np.ndarray, u: np.ndarray, y: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Measurement update with every output of ``y`` and the time update, compiled.

    Returns ``x_{k+1|k}``, ``P_{k+1|k}``, the predictor gain ``A L``, the innovation,
    its covariance and whether the innovation covariance could be factored."""
    xf, pf, gain, e, s, ok = _correct_all(x, p, c, r, y)
    if not ok:
        return x, p, gain, e, s, False
    xn, pn = _predict(xf, pf, a, b, q, u)
    return xn, pn, a @ gain, e, s, True


@njit(cache=True, nogil=True)
def _predict_correct(x: np.ndarray, p: np.ndarray, a: np.ndarray, b: np.ndarray,
                     q: np.ndarray, u: np.ndarray, c: np.ndarray, r: np.ndarray, y: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                np.ndarray, bool]:
    """Time update with the last step's model and input, then the measurement update
    with every output of ``y``, compiled: ``x_{k|k}``, ``P_{k|k}``, the filter gain,
    the innovation, its covariance, the prior ``P_{k|k-1}`` and whether the innovation
    covariance could be factored (the same operations as :meth:`KalmanPredictor.predict`
    then :meth:`KalmanPredictor.correct`)."""
    xp, pp = _predict(x, p, a, b, q, u)
    xf, pf, gain, e, s, ok = _correct_all(xp, pp, c, r, y)
    return xf, pf, gain, e, s, pp, ok


@njit(cache=True, nogil=True)
def _within(x: np.ndarray, p: np.ndarray, c: np.ndarray, r: np.ndarray, y: np.ndarray,
            sigmas: float) -> np.ndarray:
    """``|y - C x| <= sigmas sqrt(max(diag(C P C^T) + r, 1e-30))`` per output, compiled
    (zero entries of ``C`` skipped; a non-finite prediction or spread is outside)."""
    n, m = x.shape[0], c.shape[0]
    inside = np.empty(m, dtype=np.bool_)
    for j in range(m):
        prediction = 0.0
        variance = 0.0
        for k in range(n):
            cjk = c[j, k]
            if cjk != 0.0:
                prediction += cjk * x[k]
                pc = 0.0
                for i in range(n):
                    pc += p[k, i] * c[j, i]
                variance += cjk * pc
        variance += r[j]
        if variance < 1e-30:
            variance = 1e-30
        inside[j] = abs(y[j] - prediction) <= sigmas * math.sqrt(variance)
    return inside
