"""Validation of the identifiers' constructor arguments, with messages that name
the expected type or range (one definition for every identifier), and the
finiteness check of their per-sample arrays."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["all_finite", "forgetting_factor", "positive_float", "positive_int",
           "positive_scales", "rms_scale"]


@njit(cache=True, nogil=True)
def all_finite(x: np.ndarray) -> bool:
    """``np.isfinite(x).all()`` for a float array of any shape and layout, compiled:
    the per-sample check, about 0.7 us against 3 us for the NumPy expression on the
    identifiers' 10-22-entry arrays. True for an empty array."""
    for v in x.flat:
        if not math.isfinite(v):
            return False
    return True


def positive_int(name: str, value) -> int:
    """``value`` as an int >= 1; ``TypeError``/``ValueError`` naming ``name`` otherwise.

    Returns
    -------
    int
        ``value``, at least 1.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if value < 1:
        raise ValueError(f"{name} must be >= 1, got {value}")
    return int(value)


def positive_float(name: str, value: float) -> float:
    """``value`` as a finite float > 0; ``ValueError`` naming ``name`` otherwise.

    Returns
    -------
    float
        ``value``, finite and > 0.
    """
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be positive, got {value}")
    return value


def forgetting_factor(name: str, value: float) -> float:
    """``value`` as a forgetting factor in (0, 1]; ``ValueError`` naming ``name`` otherwise.

    Returns
    -------
    float
        ``value``, in (0, 1].
    """
    value = float(value)
    if not 0.0 < value <= 1.0:
        raise ValueError(f"{name} must be in (0, 1], got {value}")
    return value


def positive_scales(name: str, value) -> np.ndarray:
    """``value`` as a 1-D array of positive finite per-channel scales.

    Returns
    -------
    (k,) ndarray
        The scales, positive and finite.
    """
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be a 1-D array of positive finite scales")
    return arr


def rms_scale(samples: np.ndarray) -> np.ndarray:
    """Per-column RMS of the finite entries, 1 where there is none or it is 0.

    Computed relative to each column's peak, so data of any magnitude up to
    the largest float give a finite scale (no overflow in the squares).

    Returns
    -------
    (k,) ndarray
        One positive scale per column of ``samples``, in its units.
    """
    finite = np.where(np.isfinite(samples), samples, 0.0)
    count = np.isfinite(samples).sum(axis=0)
    peak = np.abs(finite).max(axis=0)
    peak = np.where(peak > 0, peak, 1.0)
    rms = peak * np.sqrt(((finite / peak) ** 2).sum(axis=0) / np.maximum(count, 1))
    return np.where((rms > 0) & np.isfinite(rms), rms, 1.0)
