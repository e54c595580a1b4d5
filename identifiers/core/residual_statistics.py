"""Running statistics of a residual: its level and how correlated it is in time.

An estimator's a-priori errors are white when the model explains all but the
noise, and strongly correlated when what is left is the model's own misfit
(on noise-free data, nothing else is left). The exponentially weighted mean
squares and lag-1 products kept here, sample by sample, give both: the level
that scales a test, and :func:`correlation_time`, the number of samples per
independent one, that says how much evidence a window of such errors holds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["MAX_CORRELATION", "correlation_time", "lag_product_step", "mean_square_step"]

#: Largest lag-1 autocorrelation :func:`correlation_time` credits (at most 1999
#: samples per independent one).
MAX_CORRELATION = 0.999


@njit(cache=True, nogil=True)
def mean_square_step(level: np.ndarray, x: np.ndarray, keep: float, weight: float) -> None:
    """``level <- keep * level + weight * x**2`` in place: one step of an exponentially
    weighted mean square (the arithmetic of the NumPy expression)."""
    for i in range(x.shape[0]):
        level[i] = keep * level[i] + weight * (x[i] * x[i])


@njit(cache=True, nogil=True)
def lag_product_step(level: np.ndarray, x: np.ndarray, previous: np.ndarray, keep: float,
                     weight: float) -> None:
    """``level <- keep * level + weight * x * previous`` in place: one step of an
    exponentially weighted mean of lag-1 products."""
    for i in range(x.shape[0]):
        level[i] = keep * level[i] + weight * (x[i] * previous[i])


def correlation_time(lag_products: np.ndarray, mean_squares: np.ndarray) -> float:
    """Samples per independent one in a residual: ``(1 + rho) / (1 - rho)``.

    ``rho`` is the pooled lag-1 autocorrelation of the residual,
    ``sum(lag_products) / sum(mean_squares)`` (the outputs pooled as a sum of
    squared residuals pools them), clipped to ``[0, MAX_CORRELATION]``. The
    result is the integrated autocorrelation time ``1 + 2 sum_k rho^k`` of a
    first-order autoregression with that ``rho``: the factor by which the
    variance of a window's mean exceeds that of as many independent samples.
    White noise gives 1; the slow misfit a model leaves on noise-free data,
    close to ``(1 + MAX_CORRELATION) / (1 - MAX_CORRELATION)``.

    Parameters
    ----------
    lag_products, mean_squares : (m,) ndarray
        Running means of ``e_k e_(k-1)`` and of ``e_k^2`` per output.

    Returns
    -------
    float
        In ``[1, (1 + MAX_CORRELATION) / (1 - MAX_CORRELATION)]``; 1 if the
        residual is zero or not finite.
    """
    total = float(np.add.reduce(mean_squares))
    lag = float(np.add.reduce(lag_products))
    if not (0.0 < total < math.inf and math.isfinite(lag)):
        return 1.0
    rho = min(max(lag / total, 0.0), MAX_CORRELATION)
    return (1.0 + rho) / (1.0 - rho)
