"""Discrete-time LQR design: validated weights, exact and warm-started Riccati.

``u_k = -G x_k`` minimizing ``sum x^T Q x + u^T R u`` for
``x_{k+1} = A x_k + B u_k``::

    P = A^T P A - A^T P B (R + B^T P B)^-1 B^T P A + Q
    G = (R + B^T P B)^-1 B^T P A

:func:`dlqr` solves it from scratch (``scipy.linalg.solve_discrete_are``).
:class:`RiccatiTracker` re-designs every step for a slowly varying model by
a few Riccati (value) iterations warm-started from the last solution,
O(n^3) with small constants, falling back to the exact solver when the
iteration has not converged or the model jumped; a model it has already
converged on (an identifier that holds its model between changes) gets that
design back without iterating.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike
from scipy.linalg import solve_discrete_are
from scipy.linalg.lapack import dgeev as _dgeev

from controllers.kept import KeptWhileEqual
from spacecraft_conventions import single_threaded_blas

__all__ = ["RiccatiTracker", "check_model", "check_weights", "dlqr", "spectral_radius"]


def check_weights(q: ArrayLike, r: ArrayLike, n: int | None = None,
                  m: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Validate LQR weights: Q symmetric positive semidefinite, R positive definite.

    Parameters
    ----------
    q : (n, n) array_like
        State weight ``Q`` (a scalar is taken as a 1 x 1 matrix).
    r : (m, m) array_like
        Input weight ``R`` (a scalar is taken as a 1 x 1 matrix).
    n, m : int, optional
        The expected sizes of ``Q`` and ``R`` (default: not checked).

    Returns
    -------
    q : (n, n) ndarray
        ``Q`` as a float array.
    r : (m, m) ndarray
        ``R`` as a float array.

    Raises
    ------
    ValueError
        Naming the violated condition and the expected shapes.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    r = np.atleast_2d(np.asarray(r, dtype=float))
    for name, mat, size in (("Q", q, n), ("R", r, m)):
        if mat.ndim != 2 or mat.shape[0] != mat.shape[1]:
            raise ValueError(f"{name} must be a square matrix, got shape {mat.shape}")
        if size is not None and mat.shape[0] != size:
            raise ValueError(f"{name} must have shape ({size}, {size}), got {mat.shape}")
        if not np.isfinite(mat).all():
            raise ValueError(f"{name} must be finite")
        if not np.allclose(mat, mat.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(mat).max())):
            raise ValueError(f"{name} must be symmetric")
    if np.linalg.eigvalsh(q).min() < -1e-10 * max(1.0, np.abs(q).max()):
        raise ValueError("Q must be positive semidefinite")
    if np.linalg.eigvalsh(r).min() <= 0:
        raise ValueError("R must be positive definite")
    return q, r


def check_model(a: ArrayLike, b: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Validate a model for LQR design: ``A`` finite (n, n), ``B`` finite (n, m).

    Raises
    ------
    ValueError
        Naming the expected shapes, or non-finite entries.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] == 0:
        raise ValueError(f"A must be a square (n, n) matrix, got shape {a.shape}")
    n = a.shape[0]
    if b.ndim != 2 or b.shape[0] != n or b.shape[1] == 0:
        raise ValueError(f"B must have shape ({n}, m) for A of shape {a.shape}, got {b.shape} "
                         "(a single input is a column: B.reshape(-1, 1))")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("A and B must be finite")
    return a, b


def spectral_radius(a: np.ndarray) -> float:
    """Largest eigenvalue modulus.

    Parameters
    ----------
    a : (n, n) ndarray
        A square matrix (e.g. a discrete-time closed loop).

    Returns
    -------
    float
        ``max |eig(a)|`` (< 1: a stable discrete-time system).

    Raises
    ------
    numpy.linalg.LinAlgError
        For a matrix with non-finite entries, or if the QR algorithm does not
        converge (as ``numpy.linalg.eigvals``).
    """
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise np.linalg.LinAlgError(f"a must be a square matrix, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise np.linalg.LinAlgError("a must not contain infs or NaNs")
    # LAPACK's dgeev without eigenvectors, as numpy.linalg.eigvals, without its
    # per-call overhead (a third of the call at n = 17, once per adaptive step)
    wr, wi, _, _, info = _dgeev(a, compute_vl=0, compute_vr=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"eigenvalues did not converge (LAPACK info {info})")
    return float(np.hypot(wr, wi).max())


@njit(cache=True, nogil=True)
def _gain(a: np.ndarray, b: np.ndarray, r: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``G = (R + B^T P B)^-1 B^T P A``, compiled."""
    btp = b.T @ p
    return np.linalg.solve(r + btp @ b, btp @ a)


@njit(cache=True, nogil=True)
def _iterate(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, p: np.ndarray,
             iterations: int, tol: float) -> tuple[np.ndarray, float]:
    """Up to ``iterations`` Riccati (value) iterations from ``p``, compiled; stops once
    P changes by less than ``tol`` relative. Returns P and its last relative change
    (inf if no iteration ran, NaN once P is not finite)."""
    change = np.inf
    for _ in range(iterations):
        btp = b.T @ p
        k = np.linalg.solve(r + btp @ b, btp @ a)
        p_new = a.T @ p @ (a - b @ k) + q
        p_new = 0.5 * (p_new + p_new.T)
        change = np.abs(p_new - p).max() / max(np.abs(p_new).max(), 1e-300)
        p = p_new
        if change < tol:
            break
    return p, change


@single_threaded_blas
def dlqr(a: ArrayLike, b: ArrayLike, q: ArrayLike,
         r: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Discrete LQR gain and Riccati solution from scratch.

    The same gain as python-control's ``control.dlqr`` (tested); this one
    adds the named input checks and the test that the closed loop is
    stable, and is the cold start of :class:`RiccatiTracker`, whose
    warm-started per-step redesign is ours for speed.

    Parameters
    ----------
    a : (n, n) ndarray
    b : (n, m) ndarray
    q : (n, n) ndarray
        Symmetric positive semidefinite.
    r : (m, m) ndarray
        Symmetric positive definite.

    Returns
    -------
    G : (m, n) ndarray
        Gain, ``u = -G x``.
    P : (n, n) ndarray
        Stabilizing solution of the discrete algebraic Riccati equation.

    Raises
    ------
    ValueError
        Wrong shapes or non-finite entries (named), invalid weights, or no
        stabilizing solution: (A, B) not stabilizable, or (A, Q) with an
        unobservable mode on the unit circle, so that ``A - B G`` keeps a
        pole with modulus >= 1.
    """
    a, b = check_model(a, b)
    q, r = check_weights(q, r, a.shape[0], b.shape[1])
    try:
        p = solve_discrete_are(a, b, q, r)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(f"no stabilizing Riccati solution: {exc}") from None
    gain = _gain(*(np.ascontiguousarray(m) for m in (a, b, r, p)))
    rho = spectral_radius(a - b @ gain)
    if not rho < 1.0 - 1e-12:
        raise ValueError(f"no stabilizing Riccati solution: the closed loop A - B G keeps a "
                         f"pole at |z| = {rho:.6g} (a mode on the unit circle that (A, B) "
                         "cannot stabilize or Q does not observe)")
    return gain, p


class RiccatiTracker:
    """Warm-started Riccati re-design for a time-varying model.

    Parameters
    ----------
    q, r : ndarray
        LQR weights (validated).
    iterations : int
        Riccati iterations per re-design, each O(n^3).
    tol : float
        Relative change of P below which the iteration has converged.

    Attributes
    ----------
    n_exact : int
        Designs solved from scratch (:func:`dlqr`).
    n_reused : int
        Designs returned unchanged: the model and ``q`` equal to those of the
        last design, which had converged (the exact solution, or an iteration
        whose last step changed P by less than ``tol``); iterating again would
        move P by less than that tolerance.
    """

    def __init__(self, q: np.ndarray, r: np.ndarray, iterations: int = 4,
                 tol: float = 1e-6) -> None:
        self.q, self.r = check_weights(q, r)
        self.iterations = int(iterations)
        self.tol = float(tol)
        self.p: np.ndarray | None = None
        self.n_exact = 0
        self.n_reused = 0
        #: the last design's gain, for its (A, B, Q), kept only when it converged
        self._converged: KeptWhileEqual[np.ndarray] = KeptWhileEqual()

    @single_threaded_blas
    def design(self, a: ArrayLike, b: ArrayLike) -> np.ndarray:
        """Gain for the model ``(a, b)``, warm-started from the last solution.

        Raises
        ------
        ValueError
            As :func:`dlqr` (shapes, or no stabilizing solution).
        """
        a, b = check_model(a, b)
        if self._converged.holds((a, b, self.q)):
            self.n_reused += 1
            return self._converged.value
        self._converged.clear()
        if self.p is None or self.p.shape != a.shape:
            gain, self.p = dlqr(a, b, self.q, self.r)
            self.n_exact += 1
            return self._keep(a, b, gain)
        a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
        p, change = _iterate(a, b, np.ascontiguousarray(self.q), np.ascontiguousarray(self.r),
                             np.ascontiguousarray(self.p), self.iterations, self.tol)
        if not np.isfinite(p).all() or change > 0.1:
            gain, self.p = dlqr(a, b, self.q, self.r)
            self.n_exact += 1
            return self._keep(a, b, gain)
        self.p = p
        gain = _gain(a, b, np.ascontiguousarray(self.r), p)
        return self._keep(a, b, gain) if change < self.tol else gain

    def _keep(self, a: np.ndarray, b: np.ndarray, gain: np.ndarray) -> np.ndarray:
        """Remember a converged design."""
        gain.flags.writeable = False        # handed out again: nobody may change it
        return self._converged.keep((a, b, self.q), gain)
