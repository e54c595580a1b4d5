"""Recursive PBSID that refits the system matrices from exponentially weighted data moments.

The state is ``x_k = M phi_k`` with ``M = W LK(Xi)`` built from the current
VARX. Instead of regressing by RLS on a sequence of states that were each
computed with a different, older VARX (whose basis therefore drifts), it
keeps the exponentially weighted second moments of the extended window
``[z_k; phi_k]`` (one in-place rank-1 update per sample) and every
``refit_every`` samples solves ``C`` and ``[A B K]`` by least squares over
the forgetting window with every state defined by the *current* VARX: the
batch PBSID solution on that window. No Hankel matrix, no SVD per step:
O(p (r + m)^2) per sample plus O(n p^2 (r + m)^2) per refit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg.blas import dger

from identifiers.core.checks import positive_int
from identifiers.subspace.recursive import RecursiveVARXIdentifier, state_horizon
from identifiers.subspace.varx import predictor_product

__all__ = ["MomentRefitRPBSID"]


def _ridged(gram: np.ndarray) -> np.ndarray:
    """``gram`` plus a ridge of 1e-9 of its mean diagonal, and at least 1e-12
    (normalized units): solvable even when the data carried no excitation."""
    size = gram.shape[0]
    return gram + (1e-9 * np.trace(gram) / size + 1e-12) * np.eye(size)


class MomentRefitRPBSID(RecursiveVARXIdentifier):
    """Recursive PBSID with batch-equivalent refits from data moments.

    Parameters
    ----------
    n : int
        Model order.
    p : int
        Past window (VARX lags).
    forgetting : float
        Forgetting of the VARX and of the data moments.
    refit_every : int
        Samples between least-squares refits of the system matrices.
    f : int, optional
        Prediction horizon of the state (default ``2 ceil(n / m)``).
    **kwargs
        ``dt``, ``warmup``, ``regularization``, ``varx_forgetting``,
        ``varx_init`` and the scales of
        :class:`identifiers.subspace.recursive.RecursiveVARXIdentifier`.
    """

    _SIGNAL_STATE = ("_phi", "_ext")

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.9995, *,
                 refit_every: int = 10, f: int | None = None, **kwargs: Any) -> None:
        if isinstance(refit_every, bool) or not isinstance(refit_every, (int, np.integer)) \
                or refit_every < 1:
            raise ValueError(f"refit_every must be a positive int, got {refit_every!r}")
        self.refit_every = int(refit_every)
        self.f = None if f is None else positive_int("f", f)
        super().__init__(n, p, forgetting, **kwargs)
        if self.warmup - self.p < self.n:
            raise ValueError(f"the state basis needs warmup >= p + n = {self.p + self.n}")

    def reset(self) -> None:
        super().reset()
        self._moments = None
        self._mats = None
        self._w = None
        self._x = None

    def _allocate(self, r: int, m: int) -> None:
        super()._allocate(r, m)
        self._horizon = state_horizon(self.f, self.n, m, "svd")
        dim = (self.p + 1) * (r + m)
        self._moments = np.zeros((dim, dim), order="F")   # R = scale * moments
        self._moment_scale = 1.0
        self._ext = np.zeros(dim)                         # [z_k; phi_k]

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        """VARX step, data moments, and a batch-equivalent refit every few samples.

        ``x_k = M phi_k`` with ``M = W LK(Xi)`` is linear in the extended
        window ``phi~_k = [z_k; phi_k]``, and so are ``x_{k+1}`` (``M`` applied
        to the shifted window), ``u_k``, ``y_k`` and ``e_k = y_k - C x_k``.
        The least-squares ``C`` and ``[A B K]`` over the exponentially weighted
        window therefore follow from the second moments ``R`` of ``phi~``
        alone, with every state defined by the *current* VARX.
        """
        zr = self._zr
        ext = self._ext
        ext[zr:] = self._phi
        ext[:self.n_inputs] = u
        ext[self.n_inputs:zr] = y
        if learn:
            self._varx.update(self._phi, y)
            lam = self.varx_forgetting
            self._moment_scale *= lam
            self._moments = dger(1.0 / self._moment_scale, ext, ext, a=self._moments,
                                 overwrite_a=True)
            if self._moment_scale < 1e-6:
                self._moments *= self._moment_scale
                self._moment_scale = 1.0
        self._push(u, y)
        if self._w is None:
            if self._k + 1 >= self.warmup:
                self._fix_basis()
            else:
                return
        if learn and (self._k + 1 - self.warmup) % self.refit_every == 0:
            self._refit()
        self._x = self._m_state @ self._phi if self._mats is not None else None

    def _state_map(self) -> np.ndarray:
        """LK of the current VARX over the state horizon, (f m, p (r + m))."""
        return predictor_product(self._varx.theta, self.n_inputs, self._horizon)

    def _fix_basis(self) -> None:
        """W: leading eigenvectors of the prediction covariance LK R_phi LK^T (once)."""
        zr = self._zr
        lk = self._state_map()
        r_phi = self._moments[zr:, zr:]
        cov = lk @ r_phi @ lk.T
        w, v = np.linalg.eigh(0.5 * (cov + cov.T))
        self._w = v[:, np.argsort(w)[::-1][:self.n]].T.copy()

    def _refit(self) -> None:
        n, r, m, zr = self.n, self.n_inputs, self.n_outputs, self._zr
        d = self._phi.shape[0]
        m_state = self._w @ self._state_map()                      # (n, d)
        rr = self._moments                                          # scale cancels
        dim = rr.shape[0]
        mx = np.zeros((n, dim))
        mx[:, zr:] = m_state                                        # x_k from phi_k
        mx1 = np.zeros((n, dim))
        mx1[:, :d] = m_state                                        # x_{k+1} from [z_k; phi_k]
        su = np.zeros((r, dim))
        su[:, :r] = np.eye(r)
        sy = np.zeros((m, dim))
        sy[:, r:zr] = np.eye(m)
        r_mx = rr @ mx.T                                            # (dim, n)
        gram_x = mx @ r_mx
        try:
            c = np.linalg.solve(_ridged(gram_x), (sy @ r_mx).T).T   # (m, n)
            me = sy - c @ mx
            g = np.vstack([mx, su, me])                             # regressor map
            r_g = rr @ g.T
            theta = np.linalg.solve(_ridged(g @ r_g), (mx1 @ r_g).T).T   # (n, n + r + m)
        except np.linalg.LinAlgError:      # no excitation at all: keep the last model
            return
        if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(c))):
            return
        a, b, k = theta[:, :n], theta[:, n:n + r], theta[:, n + r:]
        self._m_state = m_state
        self._mats = (a, b, c, np.zeros((m, r)), k)

    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        return self._mats

    def _current_state(self) -> np.ndarray | None:
        return self._x
