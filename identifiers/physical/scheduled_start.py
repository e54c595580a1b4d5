"""The equation-error start of the drive-scheduled model's output-error fit.

Each appendage's mode from a linear regression of its deflection's second
derivative on the deflection, its rate and the hub's angular acceleration
turned with the drive (``y_k'' = -w^2 y_k - 2 zeta w y_k' - d_k v_k^T R(a) omega'``),
then the inertia and couplings from the hub's torque balance
``u = J omega' + sum_k R(a)^T c_k y_k'' - d`` (``c_k = v_k / d_k``; the constant
disturbance ``d`` only where the problem fits one), all on signals passed
through ``1 / (tau s + 1)^3``; the couplings are shrunk until the rest inertia
``J - F F^T`` is well inside the positive definite cone, then scaled, ``J`` held,
by the factor of :data:`COUPLING_SCALES` whose model simulates the record best
(the regression pins ``J`` and the modes, not the appendages' share of ``J``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.signal

from identifiers.physical.physical_model import DAMPING_BOUNDS, FREQUENCY_BOUNDS_HZ
from identifiers.physical.scheduled_model import drive_rotation

__all__ = ["COUPLING_SCALES", "equation_error_start"]

#: Factors on the regression's modal couplings tried at the start, the hub's
#: inertia ``J = S + F F^T`` held (the one kept gives the smallest output error).
#: The torque balance pins ``J`` and the modes but not how much of ``J`` the
#: appendages carry: on solar rotation seed 0 noise-free the regression's
#: couplings were 1.6-4x too large, and every start refined from them ended
#: with two modes on their bounds and the rigid gain 67 % off; scaled by
#: 0.5-0.7 each reached the right basin (0.1-0.3 %). Nine simulations of the
#: record per start, next to the refinement's hundreds (its Jacobian columns).
COUPLING_SCALES = tuple(2.0 ** np.arange(-4.0, 0.25, 0.5))


def _filtered(x: np.ndarray, dt: float, tau: float, order: int) -> np.ndarray:
    """``s^order / (tau s + 1)^3`` applied to each column of ``x``."""
    den = np.poly1d([tau, 1.0]) ** 3
    num = np.zeros(order + 1)
    num[0] = 1.0
    system = scipy.signal.cont2discrete((num, den.coeffs), dt, method="bilinear")
    b, a = np.ravel(system[0]), np.ravel(system[1])
    return scipy.signal.lfilter(b, a, x, axis=0)


def equation_error_start(problem: Any, y: np.ndarray, tau: float) -> np.ndarray:
    """Packed parameters of the equation-error start at filter constant ``tau`` (s)
    for ``problem`` (the output-error problem of
    :mod:`identifiers.physical.scheduled_fit`: its record, layout, appendages and
    ``pack``); see the module docstring.

    Returns
    -------
    ndarray
        The packed parameter vector (``problem.pack``'s layout).
    """
    n, rot = problem.n, problem.turning
    y = np.where(np.isfinite(y), y, 0.0)
    first = [int(np.flatnonzero(problem.sensors == k)[0]) for k in range(n)]
    rows = problem.defl[first]
    r = drive_rotation(problem.axis, problem.angle)                              # (T, 3, 3)
    om1 = _filtered(y[:, problem.rate], problem.dt, tau, 1)
    d0, d1, d2 = (_filtered(y[:, rows], problem.dt, tau, o) for o in (0, 1, 2))
    uf = _filtered(problem.u, problem.dt, tau, 0)
    keep = slice(int(6 * tau / problem.dt), None)
    turned = np.einsum("tij,tj->ti", r, om1)
    w, zeta, g = np.empty(n), np.empty(n), np.empty((n, 3))
    for k in range(n):
        reg = np.column_stack([d0[:, k], d1[:, k], turned if rot[k] else om1])[keep]
        th = np.linalg.lstsq(reg, -d2[keep, k], rcond=None)[0]
        w[k] = np.sqrt(max(th[0], (2 * np.pi * FREQUENCY_BOUNDS_HZ[0]) ** 2))
        zeta[k] = np.clip(th[1] / (2 * w[k]), *DAMPING_BOUNDS)
        g[k] = th[2:]
    # hub: u = J omega' + sum_k F_k(a) eta_k'' with F_k(a) eta_k = R(a)^T c_k y_k
    sym = [np.outer(e, f) + np.outer(f, e) - (np.outer(e, e) if i == j else 0.0)
           for i, e in enumerate(np.eye(3)) for j, f in enumerate(np.eye(3)) if j >= i]
    cols = [om1 @ s.T for s in sym]
    for k in range(n):
        for e in np.eye(3):
            along = np.einsum("tji,j->ti", r, e) if rot[k] else np.tile(e, (len(y), 1))
            cols.append(along * d2[:, k:k + 1])
    if problem.disturbance:
        cols.extend(np.tile(-e, (len(y), 1)) for e in np.eye(3))
    design = np.stack([c[keep].ravel() for c in cols], axis=1)
    th = np.linalg.lstsq(design, uf[keep].ravel(), rcond=None)[0]
    d = th[6 + 3 * n:] if problem.disturbance else np.zeros(3)
    inertia = sum(t * s for t, s in zip(th[:6], sym, strict=True))
    couplings = np.empty((n, 3))
    for k in range(n):
        c = th[6 + 3 * k:9 + 3 * k]
        tip = np.sqrt(max(abs(g[k] @ c) / max(c @ c, 1e-30), 1e-12))
        couplings[k] = np.sign(g[k] @ c or 1.0) * g[k] / tip
    inertia = 0.5 * (inertia + inertia.T)
    if np.linalg.eigvalsh(inertia).min() <= 0:
        inertia = np.diag(np.maximum(np.diag(inertia), 1e3))
    lowest = np.linalg.eigvalsh(inertia).min()
    for _ in range(40):           # keep S = J - F F^T well inside the SPD cone
        rest = inertia - couplings.T @ couplings
        if np.linalg.eigvalsh(rest).min() > 0.3 * lowest:
            break
        couplings *= 0.8
    x0 = np.zeros(6 + 2 * n)
    if np.all(np.isfinite(problem.y[0])) and problem.good[0]:
        x0[0:3], x0[3:6] = problem.y[0, problem.att], problem.y[0, problem.rate]
    return _scaled_couplings(problem, inertia, w, zeta, couplings, x0, d)


def _scaled_couplings(problem: Any, inertia: np.ndarray, w: np.ndarray, zeta: np.ndarray,
                      couplings: np.ndarray, x0: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The packed start whose couplings, scaled by one of :data:`COUPLING_SCALES`
    with the inertia ``J = S + F F^T`` held, give the smallest output error."""
    best, best_cost = None, np.inf
    for scale in COUPLING_SCALES:
        scaled = scale * couplings
        rest = inertia - scaled.T @ scaled
        if np.linalg.eigvalsh(rest).min() <= 0:
            continue
        p = problem.pack(rest, np.zeros(2), w, zeta, scaled, x0, d)
        cost = float(np.mean(problem.evaluate(p)[0] ** 2))
        if cost < best_cost:
            best, best_cost = p, cost
    if best is None:
        raise np.linalg.LinAlgError("no coupling scale leaves a positive definite rest inertia")
    return best
