"""The matrix exponential of a stack of small matrices, compiled.

A fit of the drive-scheduled physical model discretizes its continuous model
on every block of the drive schedule for every residual and every Jacobian
column: tens of thousands of 17 x 17 exponentials per fit. SciPy's
``expm`` loops over a stack in Python (about 20 us of overhead per matrix);
:func:`expm_stack` runs the same kind of algorithm on the whole stack in one
compiled call.

The algorithm is scaling and squaring with a diagonal Pade approximant
(Higham, "The scaling and squaring method for the matrix exponential
revisited", SIAM J. Matrix Anal. Appl. 26(4), 2005, Algorithm 2.3): the
smallest degree ``m`` in (3, 5, 7, 9, 13) whose bound ``theta_m`` covers the
matrix's 1-norm, or degree 13 on the matrix scaled by ``2^-s`` and squared
``s`` times. Its backward error is at most the unit roundoff in exact
arithmetic; results agree with SciPy's (Al-Mohy and Higham's 2009 variant) to
rounding (``tests/identifiers/test_expm.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

__all__ = ["expm_stack"]

#: Largest 1-norm for which the degree-m Pade approximant is accurate to unit
#: roundoff (Higham 2005, Table 2.3), m = 3, 5, 7, 9, 13.
_THETA = np.array([1.495585217958292e-2, 2.539398330063230e-1, 9.504178996162932e-1,
                   2.097847961257068e0, 5.371920351148152e0])
_DEGREES = np.array([3, 5, 7, 9, 13])
#: Pade coefficients b_0 .. b_m of each degree, zero padded to 14.
_COEFFICIENTS = np.zeros((5, 14))
_COEFFICIENTS[0, :4] = [120.0, 60.0, 12.0, 1.0]
_COEFFICIENTS[1, :6] = [30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0]
_COEFFICIENTS[2, :8] = [17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0,
                        1.0]
_COEFFICIENTS[3, :10] = [17643225600.0, 8821612800.0, 2075673600.0, 302702400.0, 30270240.0,
                         2162160.0, 110880.0, 3960.0, 90.0, 1.0]
_COEFFICIENTS[4, :] = [64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
                       1187353796428800.0, 129060195264000.0, 10559470521600.0,
                       670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0,
                       16380.0, 182.0, 1.0]


@njit(cache=True, nogil=True)
def _pade_ratio(a: np.ndarray, powers: np.ndarray, b: np.ndarray, m: int) -> np.ndarray:
    """``(V - U)^-1 (V + U)`` of the degree-``m`` Pade approximant, ``powers[k - 1]`` =
    ``a^(2k)``: ``U = a sum_k b_(2k+1) a^(2k)``, ``V = sum_k b_(2k) a^(2k)`` (fused sums;
    the products by BLAS)."""
    n = a.shape[0]
    odd = np.empty((n, n))
    even = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            diagonal = 1.0 if i == j else 0.0
            o = b[1] * diagonal
            e = b[0] * diagonal
            for k in range(1, m // 2 + 1):
                o += b[2 * k + 1] * powers[k - 1, i, j]
                e += b[2 * k] * powers[k - 1, i, j]
            odd[i, j] = o
            even[i, j] = e
    u = a @ odd
    minus = even - u
    plus = even + u
    return np.ascontiguousarray(np.linalg.solve(minus, plus))     # LAPACK's is Fortran-ordered


@njit(cache=True, nogil=True)
def _expm_one(a: np.ndarray, theta: np.ndarray, degrees: np.ndarray,
              coefficients: np.ndarray) -> np.ndarray:
    """``exp(a)`` of one square matrix (Higham 2005, Algorithm 2.3)."""
    n = a.shape[0]
    norm = 0.0
    for j in range(n):
        column = 0.0
        for i in range(n):
            column += abs(a[i, j])
        norm = max(norm, column)
    for level in range(4):
        if norm <= theta[level]:
            m = degrees[level]
            powers = np.empty((m // 2, n, n))
            powers[0] = a @ a
            for k in range(1, m // 2):
                powers[k] = powers[k - 1] @ powers[0]
            return _pade_ratio(a, powers, coefficients[level], m)
    s = 0
    if norm > theta[4]:
        s = max(0, math.ceil(math.log2(norm / theta[4])))
    scaled = a / (2.0 ** s)
    b = coefficients[4]
    a2 = scaled @ scaled
    a4 = a2 @ a2
    a6 = a4 @ a2
    eye = np.eye(n)
    inner_u = b[13] * a6 + b[11] * a4 + b[9] * a2
    u = scaled @ (a6 @ inner_u + b[7] * a6 + b[5] * a4 + b[3] * a2 + b[1] * eye)
    inner_v = b[12] * a6 + b[10] * a4 + b[8] * a2
    v = a6 @ inner_v + b[6] * a6 + b[4] * a4 + b[2] * a2 + b[0] * eye
    r = np.ascontiguousarray(np.linalg.solve(v - u, v + u))     # LAPACK's is Fortran-ordered
    for _ in range(s):
        r = r @ r
    return r


@njit(cache=True, nogil=True)
def _expm_all(stack: np.ndarray, theta: np.ndarray, degrees: np.ndarray,
              coefficients: np.ndarray) -> np.ndarray:
    out = np.empty_like(stack)
    for k in range(stack.shape[0]):
        out[k] = _expm_one(stack[k], theta, degrees, coefficients)
    return out


def expm_stack(matrices: ArrayLike) -> np.ndarray:
    """``exp(M)`` of each square matrix of a stack.

    Parameters
    ----------
    matrices : (..., n, n) array_like
        Real square matrices (any leading shape, including none).

    Returns
    -------
    (..., n, n) ndarray
        Their exponentials.

    Raises
    ------
    ValueError
        If the last two dimensions are not square or an entry is not finite.

    Examples
    --------
    >>> import numpy as np
    >>> from identifiers.core.expm import expm_stack
    >>> e = expm_stack(np.array([[[0.0, 1.0], [0.0, 0.0]], [[-1.0, 0.0], [0.0, 2.0]]]))
    >>> np.round(e, 6).tolist()
    [[[1.0, 1.0], [0.0, 1.0]], [[0.367879, 0.0], [0.0, 7.389056]]]
    """
    m = np.asarray(matrices, dtype=float)
    if m.ndim < 2 or m.shape[-1] != m.shape[-2]:
        raise ValueError(f"matrices must be (..., n, n), got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("matrices must be finite")
    flat = np.ascontiguousarray(m.reshape(-1, m.shape[-1], m.shape[-1]))
    return _expm_all(flat, _THETA, _DEGREES, _COEFFICIENTS).reshape(m.shape)
