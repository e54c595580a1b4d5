"""Discrete-time LQR design: validated weights, exact and warm-started Riccati.

``u_k = -G x_k`` minimizing ``sum x^T Q x + u^T R u`` for
``x_{k+1} = A x_k + B u_k``::

    P = A^T P A - A^T P B (R + B^T P B)^-1 B^T P A + Q
    G = (R + B^T P B)^-1 B^T P A

:func:`dlqr` solves it from scratch (``scipy.linalg.solve_discrete_are``).
:func:`doubling_dare` solves it by structure-preserving doubling, compiled:
the same solution at a fourteenth of the cost on the adaptive loop's
17-state model, with a check that the closed loop is stable.
:class:`RiccatiTracker` re-designs every step for a model that changes: each
new model is solved exactly (by default), and a model it has already solved
(an identifier that holds its model between changes) gets that design back
without solving. Its former mode, a few Riccati (value) iterations
warm-started from the last solution, is an option: it lags a changed model
(value iteration contracts by about the square of the slowest closed-loop
pole, 0.9994 in the adaptive loop), so its gain changed every step and was
judged anew every step (docs/design/control.md, "Riccati solutions").
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike
from scipy.linalg import solve_discrete_are
from scipy.linalg.lapack import dgeev as _dgeev

from spacecraft_conventions import single_threaded_blas
from spacecraft_conventions.kept import KeptWhileEqual

__all__ = ["RiccatiTracker", "check_iterations", "check_model", "check_weights", "dlqr",
           "doubling_dare", "spectral_radius"]

#: Doubling steps before :func:`doubling_dare` gives up: step k has summed the first
#: 2^k terms of the Riccati series, so 40 covers a closed-loop pole within 1e-10 of
#: the unit circle.
DOUBLING_STEPS = 40


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

    Returns
    -------
    (A, B) : ((n, n), (n, m)) ndarrays
        The model as float arrays.

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


def check_iterations(iterations: int | None) -> int | None:
    """Validate a Riccati design mode: None (each new model solved exactly) or a
    number of warm-started iterations per re-design (an integer >= 1).

    Returns
    -------
    int or None
        The mode, unchanged.

    Raises
    ------
    ValueError
        Naming the accepted values.
    """
    if iterations is None:
        return None
    if (isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer, float))
            or iterations != int(iterations) or int(iterations) < 1):
        raise ValueError(f"iterations must be None (exact) or an integer >= 1, "
                         f"got {iterations!r}")
    return int(iterations)


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


@njit(cache=True, nogil=True)
def _doubling(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, tol: float,
              steps: int) -> tuple[np.ndarray, int]:
    """Structure-preserving doubling for the DARE, compiled (see :func:`doubling_dare`).
    Returns ``H_k`` and the steps taken (-1: ``A_k`` did not vanish)."""
    n = a.shape[0]
    g = b @ np.linalg.solve(r, np.ascontiguousarray(b.T))
    g = 0.5 * (g + g.T)
    h = q.copy()
    ak = a.copy()
    scale = max(np.abs(a).max(), 1.0)
    rhs = np.empty((n, 2 * n))
    for k in range(steps):
        w = g @ h
        for i in range(n):
            w[i, i] += 1.0
        rhs[:, :n] = ak
        rhs[:, n:] = g
        if not (np.isfinite(w).all() and np.isfinite(rhs).all()):
            return h, -1                        # diverged: no stabilizing solution
        try:
            sol = np.linalg.solve(w, rhs)       # (I + G_k H_k)^-1 [A_k, G_k]
        except Exception:                       # numba's error for a singular W
            return h, -1
        wa = np.ascontiguousarray(sol[:, :n])
        wg = np.ascontiguousarray(sol[:, n:])
        akt = np.ascontiguousarray(ak.T)
        dh = akt @ (h @ wa)
        g = g + ak @ (wg @ akt)
        g = 0.5 * (g + g.T)
        h = h + 0.5 * (dh + dh.T)
        ak = ak @ wa
        if not np.isfinite(ak).all():
            return h, -1
        if np.abs(ak).max() <= tol * scale:
            return h, k + 1
    return h, -1


def doubling_dare(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray,
                  tol: float = 1e-12) -> np.ndarray | None:
    """Stabilizing DARE solution by structure-preserving doubling (SDA), or None.

    From ``A_0 = A``, ``G_0 = B R^-1 B^T``, ``H_0 = Q``::

        W_k     = I + G_k H_k
        A_{k+1} = A_k W_k^-1 A_k
        G_{k+1} = G_k + A_k W_k^-1 G_k A_k^T
        H_{k+1} = H_k + A_k^T H_k W_k^-1 A_k

    ``H_k`` is the Riccati solution of the horizon ``2^k`` and converges
    quadratically to ``P``; ``A_k`` behaves as ``(A - B G)^(2^k)``, so its
    vanishing (``max |A_k| <= tol max(1, max |A|)``) shows the closed loop
    stable without an eigenvalue computation. About 16
    steps for the adaptive loop's slowest closed-loop pole (0.9994); each
    is one LU solve and five products of ``n x n`` matrices.

    Parameters
    ----------
    a : (n, n) ndarray
    b : (n, m) ndarray
    q : (n, n) ndarray
        Symmetric positive semidefinite.
    r : (m, m) ndarray
        Symmetric positive definite.
    tol : float
        Relative size of ``A_k`` at which the iteration stops.

    Returns
    -------
    (n, n) ndarray or None
        ``P``; None when ``A_k`` did not vanish within :data:`DOUBLING_STEPS`
        steps (no stabilizing solution, or a closed-loop pole within about
        1e-10 of the unit circle): the caller then solves with :func:`dlqr`,
        which says which.

    References
    ----------
    E. K.-W. Chu, H.-Y. Fan, W.-W. Lin, C.-S. Wang, "Structure-preserving
    algorithms for periodic discrete-time algebraic Riccati equations",
    Int. J. Control 77 (2004); W.-W. Lin, S.-F. Xu, "Convergence analysis of
    structure-preserving doubling algorithms for Riccati-type matrix
    equations", SIAM J. Matrix Anal. Appl. 28 (2006): ``A_k = (I + G_k P)
    S^(2^k)`` with ``S = (I + G P)^-1 A = A - B G`` the closed loop, and
    ``P - H_k`` of the order of ``S^(2^(k+1))``.
    """
    p, steps = _doubling(np.ascontiguousarray(a, dtype=float),
                         np.ascontiguousarray(b, dtype=float),
                         np.ascontiguousarray(q, dtype=float),
                         np.ascontiguousarray(r, dtype=float), float(tol), DOUBLING_STEPS)
    return p if steps > 0 and np.isfinite(p).all() else None


@single_threaded_blas
def dlqr(a: ArrayLike, b: ArrayLike, q: ArrayLike,
         r: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Discrete LQR gain and Riccati solution from scratch.

    The same gain as python-control's ``control.dlqr`` (tested); this one
    adds the named input checks and the test that the closed loop is
    stable; :class:`RiccatiTracker` calls it where :func:`doubling_dare`
    does not converge, and for its name of the failure.

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
    """Riccati re-design for a model that changes: each new model solved once.

    Parameters
    ----------
    q, r : ndarray
        LQR weights (validated).
    iterations : int or None
        None (default): every new model's equation is solved exactly
        (:func:`doubling_dare`, :func:`dlqr` where doubling does not
        converge). An integer: that many Riccati (value) iterations per
        re-design, warm-started from the last solution, O(n^3) each, with the
        exact solver when they diverge (the mode before 2026-11-29, kept for
        reproduction; it lags a changed model: in the adaptive loop its gain
        was still 1.3x the model's change off after 14 steps).
    tol : float
        Relative change of P below which the iteration (``iterations`` set)
        has converged.

    Attributes
    ----------
    n_exact : int
        Designs solved exactly (doubling or :func:`dlqr`).
    n_reused : int
        Designs returned unchanged: the model and ``q`` equal to those of the
        last design, which had converged (the exact solution, or an iteration
        whose last step changed P by less than ``tol``); solving again would
        give the same gain (to ``tol``).
    """

    def __init__(self, q: np.ndarray, r: np.ndarray, iterations: int | None = None,
                 tol: float = 1e-6) -> None:
        self.q, self.r = check_weights(q, r)
        self.iterations = check_iterations(iterations)
        self.tol = float(tol)
        self.p: np.ndarray | None = None
        self.n_exact = 0
        self.n_reused = 0
        #: the last design's gain, for its (A, B, Q), kept only when it converged
        self._converged: KeptWhileEqual[np.ndarray] = KeptWhileEqual()

    @single_threaded_blas
    def design(self, a: ArrayLike, b: ArrayLike) -> np.ndarray:
        """Gain for the model ``(a, b)``: kept for an unchanged model, else solved
        (or iterated from the last solution, with ``iterations`` set).

        Returns
        -------
        (m, n) ndarray
            The state-feedback gain G (u = -G x).

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
        if self.iterations is None or self.p is None or self.p.shape != a.shape:
            return self._exact(a, b)
        a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
        p, change = _iterate(a, b, np.ascontiguousarray(self.q), np.ascontiguousarray(self.r),
                             np.ascontiguousarray(self.p), self.iterations, self.tol)
        if not np.isfinite(p).all() or change > 0.1:
            return self._exact(a, b)
        self.p = p
        gain = _gain(a, b, np.ascontiguousarray(self.r), p)
        return self._keep(a, b, gain) if change < self.tol else gain

    def _exact(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The exact design: doubling, else :func:`dlqr` (which names a failure)."""
        self.n_exact += 1
        p = doubling_dare(a, b, self.q, self.r)
        if p is None:
            gain, self.p = dlqr(a, b, self.q, self.r)
            return self._keep(a, b, gain)
        self.p = p
        gain = _gain(np.ascontiguousarray(a), np.ascontiguousarray(b),
                     np.ascontiguousarray(self.r), p)
        return self._keep(a, b, gain)

    def _keep(self, a: np.ndarray, b: np.ndarray, gain: np.ndarray) -> np.ndarray:
        """Remember a converged design."""
        gain.flags.writeable = False        # handed out again: nobody may change it
        return self._converged.keep((a, b, self.q), gain)
