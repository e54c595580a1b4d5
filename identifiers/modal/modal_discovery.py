"""Finding a spacecraft's flexible modes from data, without a structural model.

:func:`discover_resonators` fits batch PBSID models to a record of torques
and the rate and deflection measurements (the attitude adds nothing the
rates do not carry, and its double integrators make the fit harder) with
several past windows, keeps the lightly damped oscillatory poles in the
structural band that every fit agrees on (noise modes move with the
window), merges modes closer than the record can resolve into one
:class:`identifiers.core.modal_basis.Resonator` of higher rank, and keeps the
strongest within a budget of modes.

:func:`merge_resonators` applies the same merging to any list (a prior
finite-element model, say).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from identifiers.core.modal_basis import Resonator
from identifiers.subspace.batch import pbsid

__all__ = ["discover_resonators", "merge_resonators"]


def merge_resonators(frequencies_hz: Sequence[float], damping: Sequence[float],
                     weights: Sequence[float] | None = None, resolution: float = 0.012,
                     budget: int | None = None) -> list[Resonator]:
    """Group modes closer than ``resolution`` (relative) into shared resonators.

    Parameters
    ----------
    frequencies_hz, damping : sequence of float
        Mode frequencies (Hz) and damping ratios.
    weights : sequence of float, optional
        Importance of each mode (e.g. its residue); the budget keeps the
        heaviest groups. Default: equal.
    resolution : float
        Relative frequency spacing below which modes share a resonator.
    budget : int, optional
        Largest total rank (number of modes kept).

    Returns
    -------
    list of Resonator
        Sorted by frequency; a group's frequency is the weighted mean, its
        rank the number of modes merged (at most 3).
    """
    f = np.asarray(frequencies_hz, dtype=float)
    z = np.asarray(damping, dtype=float)
    w = np.ones_like(f) if weights is None else np.asarray(weights, dtype=float)
    order = np.argsort(f)
    groups: list[list[int]] = []
    for i in order:
        if groups and f[i] <= f[groups[-1][0]] * (1 + resolution) and len(groups[-1]) < 3:
            groups[-1].append(i)
        else:
            groups.append([i])
    merged = [(float(np.average(f[g], weights=w[g] + 1e-30)),
               float(np.clip(np.average(z[g], weights=w[g] + 1e-30), 0.0, 0.5)),
               len(g), float(w[g].sum())) for g in groups]
    if budget is not None:
        merged.sort(key=lambda item: -item[3])
        kept, total = [], 0
        for item in merged:
            if total + item[2] <= budget:
                kept.append(item)
                total += item[2]
        merged = kept
    return [Resonator(fr, ze, rank) for fr, ze, rank, _ in sorted(merged)]


def _pbsid_modes(u: np.ndarray, y: np.ndarray, order: int, p: int, dt: float,
                 band_hz: tuple[float, float], max_damping: float) -> np.ndarray:
    """``(frequency, damping, residue)`` rows of one PBSID fit's structural poles."""
    model = pbsid(u, y, min(order, p * y.shape[1]), p, dt=dt,
                  regularization=1e-4 * u.shape[0])
    vals, vecs = np.linalg.eig(model.A)
    left = np.linalg.pinv(vecs)
    rows = []
    for j in np.flatnonzero(vals.imag > 1e-9):
        s = np.log(vals[j]) / dt
        freq, zeta = abs(s) / (2 * np.pi), -s.real / abs(s)
        if band_hz[0] <= freq <= min(band_hz[1], 0.4 / dt) and -0.02 < zeta < max_damping:
            residue = np.linalg.norm(np.outer(model.C @ vecs[:, j], left[j] @ model.B))
            rows.append((freq, zeta, residue))
    return np.array(rows).reshape(-1, 3)


def discover_resonators(inputs: np.ndarray, outputs: np.ndarray, budget: int, dt: float,
                        band_hz: tuple[float, float] = (0.02, 2.0),
                        max_damping: float = 0.1, pasts: Sequence[int] = (25, 35, 45),
                        agreement: float = 0.015, resolution: float = 0.012) -> list[Resonator]:
    """Flexible modes from a record of torques and rate/deflection outputs.

    Batch PBSID fits with several past windows; a mode is kept only if it
    appears (within ``agreement``, relative) in at least two of them: modes
    fitted to noise move with the window, structural ones do not.

    Parameters
    ----------
    inputs : (N, 3) ndarray
        Torques (normalized).
    outputs : (N, q) ndarray
        Rate and deflection channels (normalized).
    budget : int
        Largest number of modes (total rank) to return.
    dt : float
        Sample time, s.
    band_hz : (float, float)
        Frequencies outside this band are not structural modes.
    max_damping : float
        Poles more damped than this are not kept.
    pasts : sequence of int
        PBSID past windows (shortened when the record is short).
    agreement : float
        Relative frequency tolerance for a mode to count as reproduced.
    resolution : float
        See :func:`merge_resonators`.

    Returns
    -------
    list of Resonator
        Possibly fewer than ``budget`` modes (what the data show).
    """
    u, y = np.asarray(inputs, dtype=float), np.asarray(outputs, dtype=float)
    n_samples, zr = u.shape[0], u.shape[1] + y.shape[1]
    longest = max(4, (n_samples - 20) // (zr + 1))
    windows = sorted({int(min(p, longest)) for p in pasts})
    order = 3 + 2 * budget                  # rate integrators plus the flexible modes
    fits = [_pbsid_modes(u, y, order, p, dt, band_hz, max_damping) for p in windows]
    pool = np.vstack(fits) if fits else np.zeros((0, 3))
    fit_of = np.concatenate([np.full(len(f), i) for i, f in enumerate(fits)]) if fits else []
    need = min(2, len(fits))
    kept: list[tuple[float, float, float]] = []
    used = np.zeros(len(pool), dtype=bool)
    for i in np.argsort(-pool[:, 2]) if len(pool) else []:
        if used[i]:
            continue
        close = np.flatnonzero(~used & (np.abs(pool[:, 0] / pool[i, 0] - 1.0) <= agreement))
        if len(set(np.asarray(fit_of)[close])) >= need:
            kept.append((float(np.median(pool[close, 0])), float(np.median(pool[close, 1])),
                         float(np.mean(pool[close, 2]))))
        used[close] = True
    if not kept:
        return []
    freq, zeta, weight = (np.array(v) for v in zip(*kept, strict=True))
    return merge_resonators(freq, zeta, weight, resolution, budget)
