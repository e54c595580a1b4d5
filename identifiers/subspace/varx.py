"""VARX predictor algebra shared by the batch and recursive PBSID methods.

Conventions (docs/design/identification.md): ``z_k = [u_k; y_k]`` (size r + m); the past
window is stacked newest first, ``phi_k = [z_{k-1}; z_{k-2}; ...; z_{k-p}]``
(size p (r + m)); the VARX matrix ``Xi = [Xi_1, ..., Xi_p]`` has block
``Xi_i ~ C At^(i-1) Bt`` (m x (r + m)), so ``yhat_k = Xi phi_k``.

The predictor product ``LK phi_k`` stacks the output predictions
``[yhat_k; yhat_{k+1}; ...; yhat_{k+f-1}]`` obtained by running the VARX
forward with future inputs zero and future outputs replaced by their own
predictions (the "weighted" product of Houtzager et al.; docs/design/identification.md).
Its rows approximate ``Gamma_f x_k`` with ``Gamma_f = [C; CA; ...]`` built
on the true ``A``, so the first n of them are a state in the observability
basis (:func:`identifiers.core.model.observability_basis`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["free_response", "predictor_product", "regressor_gram", "regressor_matrix",
           "toeplitz_windows"]


def free_response(xi: np.ndarray, phi: np.ndarray, n_inputs: int, steps: int) -> np.ndarray:
    """Forward VARX predictions with zero future input: ``LK phi`` without LK.

    Parameters
    ----------
    xi : (m, p (r + m)) ndarray
        VARX matrix.
    phi : (p (r + m),) ndarray
        Past window, newest first.
    n_inputs : int
        r.
    steps : int
        f, number of predictions.

    Returns
    -------
    (steps * m,) ndarray
        ``[yhat_k; ...; yhat_{k+f-1}]``; cost O(f m p (r + m)).
    """
    m = xi.shape[0]
    zr = n_inputs + m
    d = phi.shape[0]
    # one buffer holding [future (newest first) ... past window]; each
    # prediction reads the p-block slice ending at the oldest needed sample
    buf = np.zeros(steps * zr + d)
    buf[steps * zr:] = phi
    out = np.empty(steps * m)
    for j in range(steps):
        start = (steps - j) * zr
        yhat = xi @ buf[start:start + d]
        out[j * m:(j + 1) * m] = yhat
        buf[start - m:start] = yhat  # z_{k+j} = [0; yhat] sits just before
    return out


def predictor_product(xi: np.ndarray, n_inputs: int, f: int, weighted: bool = True) -> np.ndarray:
    """The product of extended observability and controllability matrices, LK.

    Row block 0 is ``Xi``; row block j is ``Xi`` shifted by j lags (the oldest
    j blocks fall off) plus, if ``weighted``, ``sum_{i=1..j} Xi_i^y LK_{j-i}``
    (each future output replaced by its own prediction). Unweighted is the
    plain shift.

    Returns
    -------
    (f m, p (r + m)) ndarray
        Cost O(f^2 m^2 p (r + m)) when weighted.
    """
    # row-major Xi keeps the einsum operands below contiguous: a transposed Xi (the
    # batch VARX solve returns one) made every product about 3x slower
    xi = np.ascontiguousarray(xi)
    m, d = xi.shape
    zr = n_inputs + m
    p = d // zr
    lk = np.zeros((f, m, d))
    lk[0] = xi
    xi_y = xi.reshape(m, p, zr)[:, :, n_inputs:].transpose(1, 0, 2)  # (p, m, m): Xi_i^y
    newest_last = xi_y[::-1]                          # Xi_p^y, ..., Xi_1^y
    flat = lk.reshape(f * m, d)
    for j in range(1, f):
        if j < p:
            lk[j, :, :d - j * zr] = xi[:, j * zr:]
        if weighted:
            # sum_{i=1..jj} Xi_i^y LK_{j-i} as one product: [Xi_jj^y ... Xi_1^y] times
            # the row blocks LK_{j-jj} .. LK_{j-1}, contiguous in ``flat``
            jj = min(j, p)
            coefficients = newest_last[p - jj:].transpose(1, 0, 2).reshape(m, jj * m)
            lk[j] += coefficients @ flat[(j - jj) * m:j * m]
    return flat


def regressor_matrix(z: np.ndarray, p: int) -> np.ndarray:
    """Stack past windows ``phi_k`` for k = p .. N-1 as rows, newest first.

    Parameters
    ----------
    z : (N, r + m) ndarray
    p : int

    Returns
    -------
    (N - p, p (r + m)) ndarray
    """
    n_samples, zr = z.shape
    windows = np.lib.stride_tricks.sliding_window_view(z, (p, zr))[:, 0]  # (N-p+1, p, zr)
    return windows[:-1, ::-1, :].reshape(n_samples - p, p * zr)


def regressor_gram(z: np.ndarray, p: int, phi: np.ndarray | None = None) -> np.ndarray:
    """``Phi^T Phi`` for ``Phi = regressor_matrix(z, p)``, from its block-Toeplitz structure.

    Block ``(i, j)`` of the Gram is ``sum_k z_{k-1-i} z_{k-1-j}^T`` over the rows
    ``k = p .. N-1``; block ``(i + 1, j + 1)`` sums the same products one sample
    earlier, so it is block ``(i, j)`` plus the product that enters at the start
    and minus the one that leaves at the end:
    ``G_{i+1, j+1} = G_{i, j} + z_{p-2-i} z_{p-2-j}^T - z_{N-2-i} z_{N-2-j}^T``.
    Only the first block row is a sum over the record, so the cost is
    ``O(N p (r + m)^2 + p^2 (r + m)^2)`` instead of the direct product's
    ``O(N p^2 (r + m)^2)``; the result equals the direct product to rounding
    (the recursion adds at most ``p`` rounding steps per entry).

    Parameters
    ----------
    z : (N, r + m) ndarray
        ``[u_k, y_k]`` rows, oldest first.
    p : int
        VARX lags.
    phi : (N - p, p (r + m)) ndarray, optional
        The regressor matrix, if the caller has it (built otherwise): its first
        block column gives the first block row in one product.

    Returns
    -------
    (p (r + m), p (r + m)) ndarray
        Symmetric.
    """
    n_samples, zr = z.shape
    d = p * zr
    if phi is None:
        phi = regressor_matrix(z, p)
    g = np.empty((p, zr, d))
    g[0] = phi[:, :zr].T @ phi
    if p > 1:
        enters = z[p - 2::-1][:p - 1].ravel()              # z_{p-2-i}, i = 0 .. p-2
        leaves = z[n_samples - p:n_samples - 1][::-1].ravel()    # z_{N-2-i}
        step = (np.outer(enters, enters) - np.outer(leaves, leaves)).reshape(p - 1, zr, -1)
        for i in range(p - 1):
            np.add(g[i, :, :-zr], step[i], out=g[i + 1, :, zr:])
            g[i + 1, :, :zr] = g[0, :, (i + 1) * zr:(i + 2) * zr].T
    g = g.reshape(d, d)
    return 0.5 * (g + g.T)


def toeplitz_windows(zbar: np.ndarray, p: int) -> np.ndarray:
    """Rows ``[z_{k+i-1}; ...; z_k; 0 ...]`` for i = 0..q-1 (newest first, zero padded).

    ``Xi @ rows.T`` gives ``H zbar``, the Markov-parameter Toeplitz product
    of the future window (paper Eq. 28-31), without forming H.

    Parameters
    ----------
    zbar : (q, r + m) ndarray
        ``[z_k, ..., z_{k+q-1}]`` oldest first.
    p : int
        VARX lags (window length of each row).

    Returns
    -------
    (q, p (r + m)) ndarray
        The stacked windows, one row per step of the future window.
    """
    q, zr = zbar.shape
    padded = np.zeros((q + p - 1, zr))
    padded[p - 1:] = zbar
    # row i: z_{k+i-1} ... z_{k+i-p} (newest first), i.e. padded[i-1+p-1 :: -1] over p
    windows = np.lib.stride_tricks.sliding_window_view(padded, (p, zr))[:, 0]  # (q, p, zr)
    rows = np.zeros((q, p, zr))
    rows[1:] = windows[:-1, ::-1, :]
    return rows.reshape(q, p * zr)
