"""Improved recursive PBSID: no Hankel matrix and no SVD per step.

Three variants share the recursive VARX (paper Eq. 20-24); none forms a
Hankel matrix or computes an SVD per step.

``variant="consistent"`` (default)
    The state is ``x_k = M phi_k`` with ``M = W LK(Xi)``, computed as in the
    predictor variant. Instead of a second and third RLS on a sequence of
    states that were each computed with a different, older VARX (whose
    basis therefore drifts), it keeps the exponentially weighted second
    moments of the extended window ``[z_k; phi_k]`` (one in-place rank-1
    update per sample) and every ``refit_every`` samples solves ``C`` and
    ``[A B K]`` by least squares over the forgetting window with every state
    defined by the *current* VARX: the batch PBSID solution on that window.
    O(p (r + m)^2) per sample plus O(n p^2 (r + m)^2) per refit. Measured the
    most accurate recursive method here (README).

``variant="predictor"``
    The state is the first n entries of the VARX predictor run forward
    ``ceil(n / m)`` steps from the past window, with future inputs set to
    zero and each future output replaced by its own prediction. This equals
    the classical RPBSID state ``x = [I_n 0] LK phi`` exactly (DESIGN.md 2.4)
    without ever forming LK: O(ceil(n/m) m p (r + m)) per step instead of
    O(p^2 m^2 p (r + m)); then RLS for C and [A B K] (Eq. 47-55) as in the
    classical method, whose accuracy it shares (same ``f``, same ``W``).

``variant="apsa"`` (the paper's algorithm, Eq. 25-46)
    The future window ``ybar_k = Gamma_k x_k + H_k zbar_k`` is treated as a
    linear regression in which ``Gamma`` is tracked by RLS and the state by
    the affine projection sign algorithm::

        Sigma   = tau_{k-1} - Gamma_{k-1} x_{k-1}
        g       = Gamma_{k-1}^T sign(Sigma)
        x_k     = x_{k-1} + mu g / sqrt(g^T g + nu)
        Gamma_k = RLS(Gamma_{k-1}; regressor x_k, target tau_k; beta_2, L_0 = I)

    with ``tau_k = ybar_k - H_k zbar_k`` and ``Gamma_0 = [I_n; 0]``. The
    estimate refers to the start of the future window, p samples in the
    past; :attr:`state` propagates it to the present with the identified
    predictor. Kept as a named option for reproducing the paper: the sign
    step moves the state by at most ``mu`` per sample, as if it were a
    slowly drifting weight vector, while a real state moves with the
    dynamics every sample, so the state (and everything regressed on it)
    lags. See the README's identification table for measured figures.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.blas import dger

from identifiers.base import RecursivePBSIDBase
from identifiers.rls import RecursiveLeastSquares
from identifiers.varx import free_response, predictor_product, toeplitz_windows

__all__ = ["VARIANTS", "ImprovedRPBSID"]

#: State-update variants of :class:`ImprovedRPBSID`.
VARIANTS = ("consistent", "predictor", "apsa")


class ImprovedRPBSID(RecursivePBSIDBase):
    """Improved recursive predictor-based subspace identification.

    Parameters
    ----------
    n : int
        Model order.
    p : int
        Past window; the paper uses 15.
    forgetting : float
        Default for every forgetting factor beta_1..beta_4 (paper: 0.98).
    variant : {"consistent", "predictor", "apsa"}
        See the module docstring; default "consistent".
    refit_every : int
        Samples between least-squares refits of the system matrices
        (``"consistent"`` only).
    mu, nu : float
        APSA step size and regularization (paper: 0.01 and 1).
    state_forgetting : float, optional
        beta_2, forgetting of the RLS on Gamma (APSA only).
    **kwargs
        ``dt``, ``warmup`` and the constants of
        :class:`~identifiers.base.RecursivePBSIDBase`.
    """

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.98, *,
                 variant: str = "consistent", mu: float = 0.01, nu: float = 1.0,
                 state_forgetting: float | None = None, refit_every: int = 10,
                 **kwargs) -> None:
        if variant not in VARIANTS:
            raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")
        if not (np.isfinite(mu) and mu > 0 and np.isfinite(nu) and nu >= 0):
            raise ValueError(f"mu must be > 0 and nu >= 0, got mu={mu}, nu={nu}")
        self.variant = variant
        if isinstance(refit_every, bool) or not isinstance(refit_every, (int, np.integer)) \
                or refit_every < 1:
            raise ValueError(f"refit_every must be a positive int, got {refit_every!r}")
        self.refit_every = int(refit_every)
        self.mu, self.nu = float(mu), float(nu)
        self.state_forgetting = float(state_forgetting or forgetting)
        if not 0 < self.state_forgetting <= 1:
            raise ValueError(f"state_forgetting must be in (0, 1], got {state_forgetting}")
        super().__init__(n, p, forgetting, **kwargs)

    # ------------------------------------------------------------ set-up
    def reset(self) -> None:
        super().reset()
        self._gamma = None
        self._future = None
        self._tau = None
        self._moments = None
        self._mats = None

    def _allocate(self, r: int, m: int) -> None:
        super()._allocate(r, m)
        if self.variant == "consistent":
            dim = (self.p + 1) * (r + m)
            self._moments = np.zeros((dim, dim), order="F")   # R = scale * moments
            self._moment_scale = 1.0
            self._ext = np.zeros(dim)                         # [z_k; phi_k]
        if self.variant == "apsa":
            q = (self.p + 1) * m
            self._gamma = RecursiveLeastSquares(q, self.n, self.state_forgetting, 1.0)
            self._gamma.theta[:self.n] = np.eye(self.n)          # Gamma_0 = [I_n; 0]
            self._future = np.zeros((self.p + 2, r + m))         # z_{k-1} .. z_{k+p}
            self._x = np.zeros(self.n)
            self._tau = np.zeros(q)

    # ------------------------------------------------------------ steps
    def _predictions(self, phi: np.ndarray) -> np.ndarray:
        return free_response(self._varx.theta, phi, self.n_inputs, self._horizon)

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        if self.variant == "predictor":
            super()._step(u, y, learn)
            return
        if self.variant == "consistent":
            self._consistent_step(u, y, learn)
            return
        if learn:
            self._varx.update(self._phi, y)
        self._push(u, y)
        self._apsa_step(u, y, learn)

    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        if self.variant == "apsa" and self._k < self.warmup:
            return None
        if self.variant == "consistent":
            return self._mats
        return super()._matrices()

    # ------------------------------------------------------------ consistent
    def _consistent_step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        """VARX step, data moments, and a batch-equivalent refit every few samples.

        ``x_k = M phi_k`` with ``M = W LK(Xi)`` is linear in the extended
        window ``phi~_k = [z_k; phi_k]``, and so are ``x_{k+1}`` (``M`` applied
        to the shifted window), ``u_k``, ``y_k`` and ``e_k = y_k - C x_k``.
        The least-squares ``C`` and ``[A B K]`` over the exponentially weighted
        window therefore follow from the second moments ``R`` of ``phi~``
        alone, with every state defined by the *current* VARX (the batch
        PBSID solution on the forgetting window): no drifting state basis,
        no Hankel matrix, no SVD per step.
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
                self._fix_basis_from_moments()
            else:
                return
        if learn and (self._k + 1 - self.warmup) % self.refit_every == 0:
            self._refit()
        self._x = self._m_state @ self._phi if self._mats is not None else None

    def _state_map(self) -> np.ndarray:
        """LK of the current VARX over the state horizon, (f m, p (r + m))."""
        return predictor_product(self._varx.theta, self.n_inputs, self._horizon)

    def _fix_basis_from_moments(self) -> None:
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
        ridge = 1e-9 * np.trace(gram_x) / n * np.eye(n)
        c = np.linalg.solve(gram_x + ridge, (sy @ r_mx).T).T        # (m, n)
        me = sy - c @ mx
        g = np.vstack([mx, su, me])                                 # regressor map
        r_g = rr @ g.T
        gram = g @ r_g
        gram += 1e-9 * np.trace(gram) / gram.shape[0] * np.eye(gram.shape[0])
        theta = np.linalg.solve(gram, (mx1 @ r_g).T).T              # (n, n + r + m)
        a, b, k = theta[:, :n], theta[:, n:n + r], theta[:, n + r:]
        if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(c))):
            return
        self._m_state = m_state
        self._mats = (a, b, c, np.zeros((m, r)), k)

    def _apsa_step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        fut = self._future
        fut[:-1] = fut[1:]
        fut[-1, :self.n_inputs] = u
        fut[-1, self.n_inputs:] = y
        if self._k < self.p + 1:
            return
        r = self.n_inputs
        zbar = fut[1:]                                           # z_k .. z_{k+p}, k = K - p
        h_zbar = toeplitz_windows(zbar, self.p) @ self._varx.theta.T      # (p + 1, m)
        tau = (zbar[:, r:] - h_zbar).ravel()                     # ybar_k - H_k zbar_k
        gamma = self._gamma.theta
        x_prev = self._x
        sigma = self._tau - gamma @ x_prev                       # a-priori error (Eq. 41)
        g = gamma.T @ np.sign(sigma)
        x = x_prev + self.mu * g / math.sqrt(g @ g + self.nu)    # APSA step (Eq. 42)
        if learn:
            self._gamma.update(x, tau)                           # RLS on Gamma (Eq. 43-46)
            # system matrices from the (x_{k-1}, z_{k-1}) -> x_k pairs
            z_prev = fut[0]                                      # z_{k-1}
            self._learn_system(x_prev, z_prev[:r], z_prev[r:], x)
        self._x = x
        self._tau = tau

    def _current_state(self) -> np.ndarray | None:
        if self.variant != "apsa" or self._x is None:
            return self._x
        # propagate x_{K-p} to K + 1 with the identified predictor and stored z's
        a, b, c, d, k = self._matrices()
        x = self._x
        r = self.n_inputs
        for z in self._future[1:]:
            u, y = z[:r], z[r:]
            x = a @ x + b @ u + k @ (y - c @ x - d @ u)
        return x
