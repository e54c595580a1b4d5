"""Offline (batch) predictor-based subspace identification, PBSID.

VARX least squares, the weighted predictor product LK, an SVD of
``LK Phi`` for the state sequence, then least squares for ``[C D]`` and
``[A B K]`` (Chiuso 2007; van Wingerden and Verhaegen; docs/design/identification.md).
Also the comparator that :class:`identifiers.subspace.windowed.WindowedPBSID`
refits on a sliding window.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import cho_factor, cho_solve, eigh, solve_discrete_are

from identifiers.core.model import StateSpaceModel
from identifiers.subspace.varx import predictor_product, regressor_gram, regressor_matrix
from spacecraft_conventions import single_threaded_blas

__all__ = ["DEFAULT_PAST", "DEFAULT_RIDGE", "PBSIDResult", "pbsid"]


class PBSIDResult:
    """Model plus by-products of :func:`pbsid`.

    Attributes
    ----------
    model : StateSpaceModel
    states : (N - p, n) ndarray
        State estimates x_k for k = p .. N-1 (model coordinates).
    next_state : (n,) ndarray
        One-step prediction of the state after the last sample.
    singular_values : ndarray
        Singular values of ``LK Phi`` (order selection).
    xi : (m, p (r + m)) ndarray
        VARX estimate.
    """

    def __init__(self, model: StateSpaceModel, states: np.ndarray, next_state: np.ndarray,
                 singular_values: np.ndarray, xi: np.ndarray) -> None:
        self.model = model
        self.states = states
        self.next_state = next_state
        self.singular_values = singular_values
        self.xi = xi


def _check_data(u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
        raise ValueError(f"U and Y must have shapes (N, r) and (N, m), got {u.shape} and "
                         f"{y.shape}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise ValueError("U and Y must be finite")
    return u, y


#: Default past window: long enough to keep the rigid body's double
#: integrators near ``z = 1`` (with p = 15 only 1-5 of the 6 survive).
DEFAULT_PAST = 40
#: Default Tikhonov term of the VARX normal equations, per sample.
DEFAULT_RIDGE = 1e-4


def _riccati_gain(a: np.ndarray, c: np.ndarray, x: np.ndarray, u: np.ndarray,
                  e: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Kalman predictor gain from the residual covariances (used when the regressed
    ``K`` leaves ``A - K C`` unstable, which makes the predictor diverge).

    ``w_k = x_{k+1} - A x_k - B u_k`` and ``v_k = e_k`` give ``Q``, ``R`` and
    ``S``; the gain is that of the filtering Riccati equation, whose predictor
    is stable whenever ``(A, C)`` is detectable.
    """
    w = x[1:] - x[:-1] @ a.T - u[:-1] @ b.T
    v = e[:-1]
    q, rr, s = w.T @ w / len(w), v.T @ v / len(v), w.T @ v / len(v)
    try:
        pr = solve_discrete_are(a.T, c.T, q, rr, s=s)
        return (a @ pr @ c.T + s) @ np.linalg.inv(c @ pr @ c.T + rr)
    except (np.linalg.LinAlgError, ValueError):
        return np.zeros_like(s)


def _ridge_solve(gram: np.ndarray, regularization: float, rhs: np.ndarray) -> np.ndarray:
    """``(gram + regularization I)^-1 rhs`` by Cholesky (the matrix is symmetric positive
    definite for a positive ``regularization``); LU if rounding makes it fail."""
    matrix = gram + regularization * np.eye(gram.shape[0])
    try:
        return cho_solve(cho_factor(matrix, check_finite=False), rhs, check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.solve(matrix, rhs)


@single_threaded_blas
def pbsid(U: ArrayLike, Y: ArrayLike, n: int, p: int | None = None, f: int | None = None, *,
          dt: float = 0.1, weighted: bool = True, feedthrough: bool = False,
          regularization: float | None = None, weights: ArrayLike | None = None,
          normalize: bool = True, full_output: bool = False) -> StateSpaceModel | PBSIDResult:
    """Batch PBSID of an innovation-form model from one input-output record.

    Parameters
    ----------
    U : (N, r) array_like
        Inputs.
    Y : (N, m) array_like
        Outputs.
    n : int
        Model order.
    p : int, optional
        Past window (VARX lags); needs ``p m >= n``. Default
        :data:`DEFAULT_PAST` (40), shortened when the record is too short
        for that many regressors.
    f : int, optional
        Future window (rows of LK, in samples); default ``p``.
    dt : float
        Sample time of the returned model, s.
    weighted : bool
        Use the weighted predictor product (closed-loop consistent).
    feedthrough : bool
        Estimate D (default: D = 0, strictly proper).
    regularization : float, optional
        Tikhonov term added to the VARX normal equations (0: plain LS).
        Default ``DEFAULT_RIDGE * N`` (1e-4 per sample): without it the
        weakly excited directions of the VARX fit noise and the default
        batch call diverges on 40 dB data.
    weights : (N,) array_like, optional
        Non-negative weight of each sample's equation in every least-squares
        step (e.g. exponential forgetting over a window); default uniform.
    normalize : bool
        Scale every input and output channel to unit RMS before identifying
        (the SVD then weighs channels alike instead of by their units); the
        model is returned in physical units.
    full_output : bool
        Return a :class:`PBSIDResult` instead of the model.

    Returns
    -------
    StateSpaceModel or PBSIDResult

    Notes
    -----
    ``K`` is regressed on the innovations as PBSID prescribes; when that
    leaves the predictor ``A - K C`` unstable (it happens on short noisy
    records), ``K`` is replaced by the Kalman gain of the residual
    covariances, so the returned predictor never diverges.
    """
    u, y = _check_data(U, Y)
    r, m = u.shape[1], y.shape[1]
    if p is None:
        p = max(1, min(DEFAULT_PAST, (u.shape[0] - 1) // (r + m + 1) - 1))
    if regularization is None:
        regularization = DEFAULT_RIDGE * u.shape[0]
    f = p if f is None else int(f)
    if n < 1 or p < 1 or f < 1:
        raise ValueError("n, p and f must be >= 1")
    if f * m < n:
        raise ValueError(f"f * m = {f * m} must be >= n = {n}; increase p or f")
    n_rows = u.shape[0] - p
    if n_rows <= p * (r + m):
        raise ValueError(f"need more than p (r + m) = {p * (r + m)} samples after the first p, "
                         f"got {n_rows}")
    if weights is None:
        sw = np.ones(n_rows)
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != (u.shape[0],) or np.any(w < 0) or not np.all(np.isfinite(w)):
            raise ValueError(f"weights must be finite, >= 0, shape ({u.shape[0]},)")
        sw = np.sqrt(w[p:])
    if normalize:
        su = np.sqrt(np.mean(u**2, axis=0))
        sy = np.sqrt(np.mean(y**2, axis=0))
        su = np.where(su > 0, su, 1.0)
        sy = np.where(sy > 0, sy, 1.0)
        u, y = u / su, y / sy
    else:
        su, sy = np.ones(r), np.ones(m)
    z = np.hstack([u, y])
    phi = regressor_matrix(z, p)
    target = y[p:]
    gram = regressor_gram(z, p, phi)           # block Toeplitz: O(N p) instead of O(N p^2)
    if regularization > 0:
        wphi = phi if weights is None else phi * (sw**2)[:, None]
        wgram = gram if weights is None else phi.T @ wphi
        xi = _ridge_solve(wgram, regularization, wphi.T @ target).T
    else:
        xi = np.linalg.lstsq(phi * sw[:, None], target * sw[:, None], rcond=None)[0].T
    lk = predictor_product(xi, r, f, weighted)
    # SVD of LK Phi^T (f m x N) through its f m x f m Gram LK (Phi^T Phi) LK^T, which
    # reuses the VARX's Gram: the left vectors U and s^2 from one small symmetric
    # eigenproblem, and the states x = diag(s)^(-1/2) U^T LK Phi^T (the right vectors
    # scaled by sqrt(s)), at a third of the cost of the thin SVD of the long matrix
    # only the n leading eigenpairs are needed for the states (all of the values when
    # the caller asks for them: PBSIDResult.singular_values)
    product = lk @ gram @ lk.T
    size = product.shape[0]
    if full_output:
        eigval, eigvec = np.linalg.eigh(product)
    else:
        eigval, eigvec = eigh(product, subset_by_index=[size - n, size - 1], driver="evr",
                              check_finite=False)
    order = np.argsort(eigval)[::-1]
    s = np.sqrt(np.maximum(eigval[order], 0.0))
    # directions the data do not excite (s = 0) give zero states, as the SVD would
    floor = s[0] * 1e-12 if s[0] > 0 else 0.0
    scale = np.where(s[:n] > floor, 1.0 / np.sqrt(np.where(s[:n] > floor, s[:n], 1.0)), 0.0)
    x = phi @ (lk.T @ (eigvec[:, order[:n]] * scale[None, :]))      # (N - p, n)
    reg = np.hstack([x, u[p:]]) if feedthrough else x
    cd = np.linalg.lstsq(reg * sw[:, None], target * sw[:, None], rcond=None)[0].T
    c = cd[:, :n]
    d = cd[:, n:] if feedthrough else np.zeros((m, r))
    e = target - reg @ cd.T
    reg2 = np.hstack([x[:-1], u[p:-1], e[:-1]])
    sw2 = sw[:-1, None]
    abk = np.linalg.lstsq(reg2 * sw2, x[1:] * sw2, rcond=None)[0].T
    a, b, k = abk[:, :n], abk[:, n:n + r], abk[:, n + r:]
    if np.max(np.abs(np.linalg.eigvals(a - k @ c))) >= 1.0:
        k = _riccati_gain(a, c, x, u[p:], e, b)
    next_state = a @ x[-1] + b @ u[-1] + k @ e[-1]
    model = StateSpaceModel(a, b / su, sy[:, None] * c, sy[:, None] * d / su, k / sy, dt)
    if not full_output:
        return model
    return PBSIDResult(model, x, next_state, s, xi)
