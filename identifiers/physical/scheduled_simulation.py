"""Simulating a :class:`identifiers.physical.scheduled_model.ScheduledPhysicalModel`
over a record whose drive angle moves.

The model is discretized (zero-order hold) once per block of samples whose angle
stays within :data:`RESOLUTION` of the block's first one, at the block's middle
angle: all blocks' exponentials in one stacked call, the recursion in one
compiled pass (:func:`simulate_scheduled`). The output-error fit
(:mod:`identifiers.physical.scheduled_fit`) simulates the record this way at
every evaluation.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from identifiers.core.fit_jobs import cancellation_point
from identifiers.physical.scheduled_model import ScheduledPhysicalModel

__all__ = ["RESOLUTION", "segments", "simulate_scheduled"]

#: Drive travel (rad) over which the simulated model keeps one discretization
#: (0.25 deg: 0.7 s of the paddle-rotation scenario's 0.36 deg/s).
RESOLUTION = np.deg2rad(0.25)


def segments(angle: np.ndarray, resolution: float = RESOLUTION) -> list[tuple[int, int]]:
    """``[(start, stop), ...]``: consecutive samples whose angle stays within
    ``resolution`` (rad) of their block's first one.

    Returns
    -------
    list of (int, int)
        The blocks' [start, stop) sample ranges, covering the record in order.
    """
    bounds, start = [], 0
    for t in range(1, angle.size):
        if abs(angle[t] - angle[start]) > resolution:
            bounds.append((start, t))
            start = t
    if angle.size:
        bounds.append((start, angle.size))
    return bounds


def simulate_scheduled(model: ScheduledPhysicalModel, u: np.ndarray, angle: np.ndarray,
                       dt: float, x0: np.ndarray,
                       blocks: list[tuple[int, int]] | None = None) -> np.ndarray:
    """States (T, 6 + 2 N) before each torque ``u_t`` acts, from ``x0``; the model is
    discretized once per block of :func:`segments` (default), at its middle angle
    (all blocks' exponentials in one call, the recursion in one compiled pass).

    Returns
    -------
    (T, 6 + 2 N) ndarray
        The state at each sample, SI units.
    """
    cancellation_point()                  # a background fit nobody wants stops here
    bounds = _block_bounds(angle, blocks)
    states = np.empty((u.shape[0], model.order))
    if bounds.shape[0] == 0:
        return states
    ad, bd = _block_models(model, _block_angles(angle, bounds), dt)
    _run_blocks(ad, bd, np.ascontiguousarray(u, dtype=float), bounds,
                np.asarray(x0, dtype=float).reshape(-1), states)
    return states


def _block_models(model: ScheduledPhysicalModel, angles: np.ndarray, dt: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``(A_d, B_d)`` stacks at the blocks' angles, contiguous for :func:`_run_blocks`."""
    ad, bd = model.zoh(angles, dt)
    return np.ascontiguousarray(ad), np.ascontiguousarray(bd)


def _block_bounds(angle: np.ndarray, blocks: list[tuple[int, int]] | None) -> np.ndarray:
    """(B, 2) int64 ``[start, stop)`` of each block (default :func:`segments`)."""
    return np.asarray(segments(angle) if blocks is None else blocks,
                      dtype=np.int64).reshape(-1, 2)


def _block_angles(angle: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Each block's middle angle, rad, at which it is discretized."""
    return 0.5 * (angle[bounds[:, 0]] + angle[bounds[:, 1] - 1])


@njit(cache=True, nogil=True)
def _run_blocks(ad, bd, u, bounds, x0, states):  # pragma: no cover - compiled
    """``x_{t+1} = A_b x_t + B_b u_t`` over the blocks ``b``, ``states[t] = x_t``."""
    n, m = ad.shape[1], bd.shape[2]
    x = x0.copy()
    nxt = np.empty(n)
    for b in range(bounds.shape[0]):
        for t in range(bounds[b, 0], bounds[b, 1]):
            for i in range(n):
                states[t, i] = x[i]
            for i in range(n):
                acc = 0.0
                for j in range(n):
                    acc += ad[b, i, j] * x[j]
                for j in range(m):
                    acc += bd[b, i, j] * u[t, j]
                nxt[i] = acc
            for i in range(n):
                x[i] = nxt[i]
