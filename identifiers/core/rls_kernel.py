"""Compiled kernel of the recursive-least-squares step (:mod:`identifiers.core.rls`).

The RLS updates of the rigid-flexible identifier have 20-60 regressors: a
few thousand flops, which the BLAS calls of a NumPy implementation spend
mostly in call overhead (eight calls and a dozen temporaries per update).
:func:`rls_step` does one whole update, the excitation gate, the vector
forgetting rescale, the overflow guard, the gain, the estimate, the
symmetric rank-1 correction of the stored upper triangle and the
regularized-forgetting pseudo-row, in one compiled pass with no BLAS call
(its only allocations are a few work vectors of length d). The arithmetic
is that of :class:`identifiers.core.rls.RecursiveLeastSquares` (whose
docstring states the algorithm); only the order of the additions differs
from a BLAS implementation, so results agree to rounding
(``tests/identifiers/test_rls.py`` checks the pass against the dense
recursion).

Compiled with numba (``cache=True``: compiled once per machine and loaded
from ``__pycache__`` afterwards). With ``NUMBA_DISABLE_JIT=1`` the same
code runs as plain Python, for debugging.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["rls_step", "rls_steps"]


@njit(cache=True, nogil=True)
def _symv_upper(q: np.ndarray, x: np.ndarray, alpha: float, out: np.ndarray) -> None:
    """``out = alpha * Q x`` with ``Q`` symmetric, read from its upper triangle
    (column-major loops: ``q`` is Fortran-ordered)."""
    d = x.shape[0]
    for i in range(d):
        out[i] = 0.0
    for j in range(d):
        xj = x[j]
        acc = 0.0
        for i in range(j):
            qij = q[i, j]
            out[i] += qij * xj
            acc += qij * x[i]
        out[j] += acc + q[j, j] * xj
    for i in range(d):
        out[i] *= alpha


@njit(cache=True, nogil=True)
def _syr_upper(q: np.ndarray, v: np.ndarray, alpha: float) -> None:
    """``Q += alpha v v^T`` on the upper triangle."""
    d = v.shape[0]
    for j in range(d):
        avj = alpha * v[j]
        for i in range(j + 1):
            q[i, j] += v[i] * avj


@njit(cache=True, nogil=True)
def _rescale_upper(q: np.ndarray, r: np.ndarray, inverse: bool) -> None:
    """``Q <- Q * outer(r, r)`` (or divided by it) on the upper triangle."""
    d = r.shape[0]
    for j in range(d):
        for i in range(j + 1):
            if inverse:
                q[i, j] /= r[i] * r[j]
            else:
                q[i, j] *= r[i] * r[j]


@njit(cache=True, nogil=True)
def rls_step(theta: np.ndarray, q: np.ndarray, phi: np.ndarray, y: np.ndarray,
             lam: np.ndarray, vector: bool, gate_level: float, pseudo_weights: np.ndarray,
             hold: np.ndarray, scale: float, cycle: int, guard: float,
             err: np.ndarray, drift: np.ndarray) -> tuple[bool, float, int]:
    """One RLS update in place (see :meth:`RecursiveLeastSquares.update`).

    Parameters
    ----------
    theta : (q, d) ndarray, Fortran order
        Estimate, updated in place.
    q : (d, d) ndarray, Fortran order
        Upper triangle of the scaled covariance (``P = scale * Q``), updated in place.
    phi : (d,) ndarray
        Regressor.
    y : (q,) ndarray
        Target.
    lam : (d,) ndarray
        Forgetting factor of every regressor.
    vector : bool
        Whether the factors differ (vector forgetting: ``Q`` is rescaled).
    gate_level : float
        ``phi^T P phi`` of a sample as informative as the data (the
        excitation gate); <= 0 turns the gate off.
    pseudo_weights : (d,) ndarray
        Weight ``w_i`` of the floor's pseudo-row of each coordinate.
    hold : (d,) ndarray of bool
        Coordinates the pseudo-row bounds without pulling toward 0.
    scale : float
        Current scalar of ``P``.
    cycle : int
        Coordinate whose pseudo-row comes next.
    guard : float
        Products above this are refused (overflow).
    err : (q,) ndarray
        Receives the a-priori error ``y - Theta phi``.
    drift : (d,) ndarray
        Random-walk variance added to the diagonal of ``P`` after the update
        (the Kalman filter of a drifting parameter); all zeros for none.

    Returns
    -------
    accepted : bool
        False if the update was refused (nothing changed).
    scale : float
        The new scalar of ``P``.
    cycle : int
        The new pseudo-row coordinate.
    """
    d = phi.shape[0]
    p_phi = np.empty(d)
    share = 1.0
    if gate_level > 0.0:
        _symv_upper(q, phi, scale, p_phi)
        share = min(1.0, (phi @ p_phi) / gate_level)
    # effective forgetting of this sample, the largest one as the scalar of P
    lam_eff = 1.0 - (1.0 - lam) * share
    lam_max = lam_eff.max()
    r = np.sqrt(lam_max / lam_eff)
    if vector:
        _rescale_upper(q, r, False)
    if vector or gate_level <= 0.0:
        _symv_upper(q, phi, scale, p_phi)
    denom = lam_max + phi @ p_phi
    for a in range(err.shape[0]):
        acc = 0.0
        for j in range(d):
            acc += theta[a, j] * phi[j]
        err[a] = y[a] - acc
    peak_p = np.abs(p_phi).max()
    peak_e = np.abs(err).max()
    safe = (np.isfinite(denom) and denom > 0.0 and np.isfinite(peak_p) and np.isfinite(peak_e)
            and peak_p * peak_p / denom < guard and peak_e * peak_p / denom < guard)
    if not safe:
        if vector:
            _rescale_upper(q, r, True)
        return False, scale, cycle
    for j in range(d):
        g = p_phi[j] / denom
        for a in range(err.shape[0]):
            theta[a, j] += err[a] * g
    _syr_upper(q, p_phi, -1.0 / (scale * denom))
    if lam_max < 1.0:
        scale /= lam_max
    i = cycle
    cycle = (i + 1) % d
    w = pseudo_weights[i] * np.sqrt(share)
    if pseudo_weights[i] > 0.0:
        # pseudo-observation 0 = Theta (w e_i): P (w e_i) is column i of P times w
        for k in range(i):
            p_phi[k] = q[k, i] * (scale * w)
        for k in range(i, d):
            p_phi[k] = q[i, k] * (scale * w)
        denom_i = 1.0 + w * p_phi[i]
        if not hold[i]:                 # pull toward 0; a held coordinate keeps its value
            pull = -w * theta[:, i]                     # the pseudo-row's error (a copy)
            for j in range(d):
                g = p_phi[j] / denom_i
                for a in range(theta.shape[0]):
                    theta[a, j] += pull[a] * g
        _syr_upper(q, p_phi, -1.0 / (scale * denom_i))
    if scale > 1e8:
        for j in range(d):
            for k in range(j + 1):
                q[k, j] *= scale
        scale = 1.0
    for j in range(d):
        if drift[j] > 0.0:
            q[j, j] += drift[j] / scale
    return True, scale, cycle


@njit(cache=True, nogil=True)
def rls_steps(theta: np.ndarray, q: np.ndarray, phis: np.ndarray, ys: np.ndarray,
              lam: np.ndarray, vector: bool, gate_level: float, pseudo_weights: np.ndarray,
              hold: np.ndarray, scale: float, cycle: int, guard: float,
              errs: np.ndarray, drift: np.ndarray, use: np.ndarray
              ) -> tuple[np.ndarray, float, int]:
    """:func:`rls_step` on the rows of ``phis`` and ``ys`` in order, in one compiled loop.

    Rows where ``use`` is False are not applied. ``errs`` (J, q) receives each
    applied row's a-priori error. Returns which rows were accepted (False also for
    rows not used), the new ``scale`` and ``cycle``. Each row's arithmetic is exactly
    that of one :func:`rls_step` call."""
    accepted = np.zeros(phis.shape[0], dtype=np.bool_)
    for k in range(phis.shape[0]):
        if use[k]:
            ok, scale, cycle = rls_step(theta, q, phis[k], ys[k], lam, vector, gate_level,
                                        pseudo_weights, hold, scale, cycle, guard, errs[k],
                                        drift)
            accepted[k] = ok
    return accepted, scale, cycle
