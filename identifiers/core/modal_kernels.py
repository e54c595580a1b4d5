"""Compiled per-sample kernels of the modal filter bank (:mod:`identifiers.core.modal_basis`).

A damped oscillator ``q'' + 2 zeta w q' + w^2 q = f`` sampled with a
zero-order hold has a closed-form transition (:func:`oscillator_zoh`), so
moving a resonator's frequency or damping costs a few dozen flops instead
of a matrix exponential: the bank can follow a tracked mode every second.
Its sensitivities to the log-frequency and the damping ratio
(:func:`oscillator_zoh_derivatives`) drive the derivative filters that the
modal tracker regresses on. :func:`bank_step` advances the integrators,
the resonators, their free responses and all the derivative filters by one
sample in one compiled pass, and :func:`bank_run` (with :func:`highpass_run`)
a whole record of them, for the rebuilds that replay one.

Compiled with numba (``cache=True``); ``NUMBA_DISABLE_JIT=1`` runs the same
code as plain Python.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["bank_highpassed", "bank_regressor", "bank_run", "bank_step", "highpass_run",
           "highpass_step", "oscillator_zoh", "oscillator_zoh_derivatives"]

#: Relative step of the central differences for the sensitivities.
_STEP = 1e-5


@njit(cache=True, nogil=True)
def _zoh(w: float, zeta: float, dt: float, a: np.ndarray, b: np.ndarray) -> None:
    """Closed-form ZOH of the unit-mass oscillator with natural frequency ``w`` (rad/s)."""
    sigma = zeta * w
    wd2 = w * w - sigma * sigma
    e = math.exp(-sigma * dt)
    if wd2 > 1e-12 * w * w:
        wd = math.sqrt(wd2)
        c, s = math.cos(wd * dt), math.sin(wd * dt)
        s_over = s / wd
    else:                                  # critically damped limit
        c, s_over = 1.0, dt
    a[0, 0] = e * (c + sigma * s_over)
    a[0, 1] = e * s_over
    a[1, 0] = -e * w * w * s_over
    a[1, 1] = e * (c - sigma * s_over)
    # B = A_c^-1 (Phi - I) [0; 1],  A_c^-1 = [[-2 zeta / w, -1 / w^2], [1, 0]]
    b[0] = -2.0 * zeta / w * a[0, 1] - (a[1, 1] - 1.0) / (w * w)
    b[1] = a[0, 1]


@njit(cache=True, nogil=True)
def oscillator_zoh(frequency_hz: float, damping: float, dt: float) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """ZOH sample of ``q'' + 2 zeta w q' + w^2 q = f``, state ``[q, q']``.

    Returns
    -------
    a : (2, 2) ndarray
    b : (2,) ndarray
        Response to a unit force held over one sample.
    """
    a = np.empty((2, 2))
    b = np.empty(2)
    _zoh(2.0 * math.pi * frequency_hz, damping, dt, a, b)
    return a, b


@njit(cache=True, nogil=True)
def oscillator_zoh_derivatives(frequency_hz: float, damping: float,
                               dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                   np.ndarray]:
    """The ZOH and its derivatives with respect to ``log(frequency)`` and ``damping``.

    Returns
    -------
    a : (2, 2) ndarray
    b : (2,) ndarray
    da : (2, 2, 2) ndarray
        ``da[p]``: derivative of ``a`` by parameter p (0: log-frequency, 1: damping).
    db : (2, 2) ndarray
        ``db[p]``: derivative of ``b``.
    """
    w = 2.0 * math.pi * frequency_hz
    a = np.empty((2, 2))
    b = np.empty(2)
    _zoh(w, damping, dt, a, b)
    da = np.empty((2, 2, 2))
    db = np.empty((2, 2))
    ap, bp = np.empty((2, 2)), np.empty(2)
    am, bm = np.empty((2, 2)), np.empty(2)
    h = _STEP
    _zoh(w * math.exp(h), damping, dt, ap, bp)
    _zoh(w * math.exp(-h), damping, dt, am, bm)
    da[0] = (ap - am) / (2 * h)
    db[0] = (bp - bm) / (2 * h)
    _zoh(w, damping + h, dt, ap, bp)
    _zoh(w, damping - h, dt, am, bm)
    da[1] = (ap - am) / (2 * h)
    db[1] = (bp - bm) / (2 * h)
    return a, b, da, db


@njit(cache=True, nogil=True)
def bank_step(u: np.ndarray, dt: float, ratio: float, pos: np.ndarray, vel: np.ndarray,
              q: np.ndarray, free: np.ndarray, a: np.ndarray, b: np.ndarray,
              dq: np.ndarray, dfree: np.ndarray, da: np.ndarray, db: np.ndarray,
              sensitivities: bool) -> None:
    """Advance the bank by one sample under torque ``u`` (normalized, (3,)), in place.

    Parameters
    ----------
    pos, vel : (3,) ndarray
        Double and single integrals of the torques.
    q : (M, 3, 2) ndarray
        Per resonator and torque axis, ``[q, q']``.
    free : (M, 2, 2) ndarray
        Each resonator's free responses (columns: from ``q = 1`` and from ``q' = 1``).
    a, b : (M, 2, 2), (M, 2) ndarray
        Resonator transitions.
    dq : (M, 2, 3, 2) ndarray
        Derivatives of ``q`` by the resonator's log-frequency and damping.
    dfree : (M, 2, 2, 2) ndarray
        Derivatives of ``free``.
    da, db : (M, 2, 2, 2), (M, 2, 2) ndarray
        Derivatives of ``a`` and ``b``.
    sensitivities : bool
        Whether to advance ``dq`` and ``dfree``.
    """
    for ax in range(3):
        pos[ax] += dt * ratio * vel[ax] + 0.5 * dt * dt * ratio * u[ax]
        vel[ax] += dt * u[ax]
    m = q.shape[0]
    for i in range(m):
        a00, a01, a10, a11 = a[i, 0, 0], a[i, 0, 1], a[i, 1, 0], a[i, 1, 1]
        if sensitivities:
            # d(s_{k+1}) = A d(s_k) + dA s_k + dB u_k, with s_k before its update
            for p in range(2):
                d00, d01 = da[i, p, 0, 0], da[i, p, 0, 1]
                d10, d11 = da[i, p, 1, 0], da[i, p, 1, 1]
                for ax in range(3):
                    s0, s1 = q[i, ax, 0], q[i, ax, 1]
                    g0, g1 = dq[i, p, ax, 0], dq[i, p, ax, 1]
                    force0, force1 = db[i, p, 0] * u[ax], db[i, p, 1] * u[ax]
                    dq[i, p, ax, 0] = a00 * g0 + a01 * g1 + d00 * s0 + d01 * s1 + force0
                    dq[i, p, ax, 1] = a10 * g0 + a11 * g1 + d10 * s0 + d11 * s1 + force1
                for c in range(2):
                    f0, f1 = free[i, 0, c], free[i, 1, c]
                    g0, g1 = dfree[i, p, 0, c], dfree[i, p, 1, c]
                    dfree[i, p, 0, c] = a00 * g0 + a01 * g1 + d00 * f0 + d01 * f1
                    dfree[i, p, 1, c] = a10 * g0 + a11 * g1 + d10 * f0 + d11 * f1
        for ax in range(3):
            s0, s1 = q[i, ax, 0], q[i, ax, 1]
            q[i, ax, 0] = a00 * s0 + a01 * s1 + b[i, 0] * u[ax]
            q[i, ax, 1] = a10 * s0 + a11 * s1 + b[i, 1] * u[ax]
        for c in range(2):
            f0, f1 = free[i, 0, c], free[i, 1, c]
            free[i, 0, c] = a00 * f0 + a01 * f1
            free[i, 1, c] = a10 * f0 + a11 * f1


@njit(cache=True, nogil=True)
def bank_regressor(out: np.ndarray, pos: np.ndarray, vel: np.ndarray, q: np.ndarray,
                   free: np.ndarray, since: int, dt: float) -> None:
    """Write the bank's regressor (layout of
    :meth:`identifiers.core.modal_basis.ModalFilterBank.regressor`) into ``out``."""
    m = q.shape[0]
    for ax in range(3):
        out[ax] = pos[ax]
        out[3 + ax] = vel[ax]
    j = 6
    for i in range(m):
        for ax in range(3):
            out[j] = q[i, ax, 0]
            out[j + 1] = q[i, ax, 1]
            j += 2
    for i in range(m):
        out[j] = free[i, 0, 0]
        out[j + 1] = free[i, 0, 1]
        j += 2
    out[j] = 1.0
    out[j + 1] = since * dt


@njit(cache=True, nogil=True)
def bank_highpassed(pos: np.ndarray, vel: np.ndarray, q: np.ndarray, free: np.ndarray,
                    since: int, dt: float, dq: np.ndarray, dfree: np.ndarray,
                    last: np.ndarray, out: np.ndarray, rho: float, dq_last: np.ndarray,
                    dq_out: np.ndarray, dq_rho: float, dfree_last: np.ndarray,
                    dfree_out: np.ndarray, dfree_rho: float, sensitivities: bool
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bank's regressor and (with ``sensitivities``) its derivatives ``dq`` and
    ``dfree[:, :, 0, :]``, flattened, each through its :func:`highpass_step` (whose
    states advance); empty derivatives without."""
    raw = np.empty(last.shape[1])
    bank_regressor(raw, pos, vel, q, free, since, dt)
    x = highpass_step(last, out, raw, rho)
    if not sensitivities:
        return x, np.empty(0), np.empty(0)
    m = q.shape[0]
    raw_dq = np.empty(12 * m)
    raw_dfree = np.empty(4 * m)
    j = 0
    for i in range(m):
        for p in range(2):
            for ax in range(3):
                raw_dq[j] = dq[i, p, ax, 0]
                raw_dq[j + 1] = dq[i, p, ax, 1]
                j += 2
    j = 0
    for i in range(m):
        for p in range(2):
            raw_dfree[j] = dfree[i, p, 0, 0]
            raw_dfree[j + 1] = dfree[i, p, 0, 1]
            j += 2
    return (x, highpass_step(dq_last, dq_out, raw_dq, dq_rho),
            highpass_step(dfree_last, dfree_out, raw_dfree, dfree_rho))


@njit(cache=True, nogil=True)
def bank_run(inputs: np.ndarray, dt: float, ratio: float, pos: np.ndarray, vel: np.ndarray,
             q: np.ndarray, free: np.ndarray, a: np.ndarray, b: np.ndarray,
             dq: np.ndarray, dfree: np.ndarray, da: np.ndarray, db: np.ndarray,
             sensitivities: bool, since: int, regressors: np.ndarray,
             dq_rows: np.ndarray, dfree_rows: np.ndarray) -> None:
    """Run the bank over a record of torques ``inputs`` (N, 3), in place.

    Row k of ``regressors`` (N, size) receives the regressor before torque k
    acts, and, with ``sensitivities``, rows k of ``dq_rows`` (N, 12 M) and
    ``dfree_rows`` (N, 4 M) its derivatives (``dq`` and ``dfree[:, :, 0, :]``
    flattened); then the bank advances by :func:`bank_step`. The same
    arithmetic as one :func:`bank_step` per sample; ``since`` is the ramp's
    sample count at the first row.
    """
    m = q.shape[0]
    for k in range(inputs.shape[0]):
        bank_regressor(regressors[k], pos, vel, q, free, since + k, dt)
        if sensitivities:
            j = 0
            for i in range(m):
                for p in range(2):
                    for ax in range(3):
                        dq_rows[k, j] = dq[i, p, ax, 0]
                        dq_rows[k, j + 1] = dq[i, p, ax, 1]
                        j += 2
            j = 0
            for i in range(m):
                for p in range(2):
                    dfree_rows[k, j] = dfree[i, p, 0, 0]
                    dfree_rows[k, j + 1] = dfree[i, p, 0, 1]
                    j += 2
        bank_step(inputs[k], dt, ratio, pos, vel, q, free, a, b, dq, dfree, da, db,
                  sensitivities)


@njit(cache=True, nogil=True)
def highpass_step(last: np.ndarray, out: np.ndarray, x: np.ndarray, rho: float) -> np.ndarray:
    """One sample of ``((1 - z^-1) / (1 - rho z^-1))^2`` on every entry of ``x``.

    ``last`` and ``out`` (2, size) hold each stage's previous input and output and
    are updated in place; returns the filtered sample (a new array)."""
    n = x.shape[0]
    w = np.empty(n)
    for i in range(n):
        v = x[i] - last[0, i] + rho * out[0, i]
        last[0, i] = x[i]
        out[0, i] = v
        w[i] = v - last[1, i] + rho * out[1, i]
        last[1, i] = v
        out[1, i] = w[i]
    return w


@njit(cache=True, nogil=True)
def highpass_run(last: np.ndarray, out: np.ndarray, xs: np.ndarray, rho: float) -> np.ndarray:
    """:func:`highpass_step` on every row of ``xs`` (N, size) in turn; the filtered rows."""
    ys = np.empty_like(xs)
    for k in range(xs.shape[0]):
        ys[k] = highpass_step(last, out, xs[k], rho)
    return ys
