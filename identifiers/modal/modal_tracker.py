"""Tracking a structure's modal frequencies and damping from streaming data.

Given the resonators' frequencies and damping ratios ``rho``, every output of the
rigid-flexible model is linear in its gains ``Theta`` (:mod:`identifiers.core.modal_basis`):
``y = Theta^T phi(rho) + e``. The frequencies enter nonlinearly. :class:`ModalTracker`
estimates their correction ``delta`` by *variable projection* on a forgetting window: the
gains are projected out (the least-squares ``Theta`` of the window for given ``rho``), and
``delta`` minimizes what is left,

    V(delta) = sum_k lambda^(N-k) || y_k - Theta(delta)^T phi_k(rho + delta) ||^2 .

Two facts make this cheap enough to run every second:

* **Taylor regressors.** ``phi(rho + delta) = phi(rho) + sum_j delta_j dphi/drho_j`` to
  first order, and the derivative filters of
  :class:`identifiers.core.modal_basis.ModalFilterBank` give ``dphi/drho`` at every sample.
  So the window is summarized by the exponentially weighted second moments of the extended
  regressor ``[phi; dphi]`` and the outputs, updated by one rank-1 step per sample, and
  ``V`` and its derivatives follow from these moments for any ``delta``.
* **Re-centring.** After each step the bank moves to ``rho + delta`` (its states corrected
  to first order) and the moments are transformed to the new linearization point (``phi <-
  phi + E(delta) dphi``), so ``delta`` stays small and the Taylor model accurate.

Each refinement is one Gauss-Newton step on ``V`` (Kaufman's approximation of the
variable-projection Jacobian) with a Levenberg-Marquardt damping, bounded per step, accepted
only if it lowers ``V``. Parameters the window does not inform (a mode the inputs hardly
excite) do not move. The inverse Gauss-Newton Hessian scaled by the window's residual
variance is the reported covariance of ``rho``.

The couplings change with the modes, so the projection (gains re-fitted on the window) is
what lets the frequencies move after a change: a recursive estimator that updated the
frequencies with the gains held at their old values moved them the wrong way on the docking
spacecraft (measured while designing this, docs/design/identification.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.linalg import get_lapack_funcs

from identifiers.core.change_detection import RESOLUTION
from identifiers.core.modal_basis import MAX_DAMPING, MIN_DAMPING

__all__ = ["ModalTracker", "TrackerGroup"]

#: Largest log-frequency step per refinement (0.5 %) and damping-ratio step.
MAX_STEP = (0.005, 0.005)

_TRTRS = get_lapack_funcs("trtrs", (np.zeros((1, 1)),))


def _solve_lower(chol: np.ndarray, b: np.ndarray, transpose: bool = False) -> np.ndarray:
    """``chol^-1 b`` (``chol^-T b`` with ``transpose``) for a lower-triangular ``chol``.

    The LAPACK call of ``scipy.linalg.solve_triangular(chol, b, lower=True,
    check_finite=False)``, made as it makes it (a row-major factor is passed
    transposed), without its argument handling: a refinement makes fifteen.

    Raises
    ------
    numpy.linalg.LinAlgError
        If ``chol`` is singular.
    """
    if chol.flags.f_contiguous:
        x, info = _TRTRS(chol, b, lower=1, trans=int(transpose))
    else:
        x, info = _TRTRS(chol.T, b, lower=0, trans=int(not transpose))
    if info > 0:
        raise np.linalg.LinAlgError(f"singular matrix: resolution failed at diagonal {info - 1}")
    if info < 0:
        raise ValueError(f"illegal value in {-info}-th argument of internal trtrs")
    return x


@njit(cache=True, nogil=True)
def _moments_update(s: np.ndarray, z: np.ndarray, phi: np.ndarray, columns: np.ndarray,
                    deriv: np.ndarray, y: np.ndarray, rows: np.ndarray, inv: float) -> float:
    """Add ``x x^T`` and ``x y^T`` times ``inv`` to the moments (upper triangle of ``S``),
    with ``x = [phi[columns]; deriv]``, ``y = y[rows]``; returns ``y^T y`` times ``inv``."""
    d = columns.shape[0]
    n = d + deriv.shape[0]
    x = np.empty(n)
    for j in range(d):
        x[j] = phi[columns[j]]
    for j in range(deriv.shape[0]):
        x[d + j] = deriv[j]
    q = rows.shape[0]
    yy = 0.0
    for c in range(q):
        yy += y[rows[c]] * y[rows[c]]
    for j in range(n):
        xj = x[j] * inv
        for i in range(j + 1):
            s[i, j] += x[i] * xj
        for c in range(q):
            z[j, c] += xj * y[rows[c]]
    return yy * inv


@njit(cache=True, nogil=True)
def _window_update(ss, zs, yy: np.ndarray, phi: np.ndarray, columns, components: np.ndarray,
                   dphi: np.ndarray, dfree: np.ndarray, y: np.ndarray, rows,
                   inv: float) -> None:
    """:func:`_moments_update` of every group (tuples ``ss``, ``zs``, ``columns``, ``rows``;
    ``yy`` accumulates in place) with its derivative regressors: resonator by resonator and
    parameter by parameter, the three axes' ``dphi[..., component]`` and the two ``dfree``."""
    m = dphi.shape[0]
    derivs = np.empty((2, 10 * m))
    for component in range(2):
        j = 0
        for i in range(m):
            for p in range(2):
                for a in range(3):
                    derivs[component, j] = dphi[i, p, a, component]
                    j += 1
                for c in range(2):
                    derivs[component, j] = dfree[i, p, c]
                    j += 1
    for g in range(len(ss)):
        yy[g] += _moments_update(ss[g], zs[g], phi, columns[g], derivs[components[g]], y,
                                 rows[g], inv)


@dataclass
class TrackerGroup:
    """One sensor group's part of the tracking problem.

    Attributes
    ----------
    rows : (r,) ndarray of int
        Outputs of the group.
    columns : (d,) ndarray of int
        Regressor columns the group's outputs depend on.
    flexible : (M, 3) ndarray of int
        Position, within ``columns``, of resonator i's column for torque axis a
        (its ``q`` for a displacement sensor, ``q'`` for a velocity sensor).
    free : (M, 2) ndarray of int
        Position, within ``columns``, of resonator i's two free-response columns.
    component : int
        0 (``q``, displacement sensors) or 1 (``q'``, velocity sensors).
    """

    rows: np.ndarray
    columns: np.ndarray
    flexible: np.ndarray
    free: np.ndarray
    component: int

    @property
    def positions(self) -> np.ndarray:
        """(M, 5): the columns a resonator's parameters move: three axes, two free
        responses."""
        return np.concatenate((self.flexible, self.free), axis=1)


class ModalTracker:
    """Variable-projection tracking of resonator frequencies and damping ratios.

    Parameters
    ----------
    groups : sequence of TrackerGroup
    n_resonators : int
        M.
    forgetting : float
        Forgetting of the window moments (memory ``1 / (1 - forgetting)`` samples).
    damping : bool
        Track the damping ratios too (default True).

    Attributes
    ----------
    covariance : (2 M, 2 M) ndarray or None
        Covariance of ``[log f_1, zeta_1, ..., log f_M, zeta_M]`` from the last
        refinement (None before one).
    n_steps, n_rejected : int
        Refinements that moved the resonators, and steps refused because they
        did not lower the window's residual.
    """

    def __init__(self, groups: list[TrackerGroup], n_resonators: int,
                 forgetting: float = 0.998, damping: bool = True,
                 step_std: tuple[float, float] = (0.0005, 0.001),
                 min_samples: float = 400.0) -> None:
        if not 0.0 < forgetting < 1.0:
            raise ValueError(f"forgetting must be in (0, 1), got {forgetting}")
        self.groups = list(groups)
        self.m = int(n_resonators)
        self.forgetting = float(forgetting)
        self.damping = bool(damping)
        self.step_std = tuple(float(v) for v in step_std)
        self.min_samples = float(min_samples)
        self.covariance: np.ndarray | None = None
        self.n_steps = 0
        self.n_rejected = 0
        self._derivs = 10 * self.m           # per group: (resonator, parameter, column)
        self._columns = tuple(np.ascontiguousarray(g.columns, dtype=np.int64)
                              for g in self.groups)
        self._rows = tuple(np.ascontiguousarray(g.rows, dtype=np.int64) for g in self.groups)
        self._components = np.array([g.component for g in self.groups], dtype=np.int64)
        self.reset()

    def reset(self) -> None:
        """Forget the window (after a detected change: only data after it inform)."""
        self._s = [np.zeros((g.columns.size + self._derivs,) * 2, order="F")
                   for g in self.groups]
        self._z = [np.zeros((g.columns.size + self._derivs, g.rows.size)) for g in self.groups]
        self._yy = np.zeros(len(self.groups))
        self._scale = 1.0
        self._count = 0.0                     # effective number of samples in the window

    def update(self, phi: np.ndarray, dphi: np.ndarray, dfree: np.ndarray,
               y: np.ndarray) -> None:
        """Add one sample to the window.

        Parameters
        ----------
        phi : (size,) ndarray
            The (high-passed, scaled) regressor.
        dphi : (M, 2, 3, 2) ndarray
            Its flexible columns' derivatives by each resonator's log-frequency
            and damping ratio (high-passed and scaled like ``phi``).
        dfree : (M, 2, 2) ndarray
            The derivatives of its free-response columns.
        y : (m,) ndarray
            The (high-passed) outputs.
        """
        lam = self.forgetting
        new = self._scale * lam
        inv = 1.0 / new
        _window_update(tuple(self._s), tuple(self._z), self._yy,
                       np.ascontiguousarray(phi, dtype=float), self._columns, self._components,
                       np.ascontiguousarray(dphi, dtype=float),
                       np.ascontiguousarray(dfree, dtype=float),
                       np.ascontiguousarray(y, dtype=float), self._rows, inv)
        self._scale = new
        self._count = lam * self._count + 1.0
        if self._scale < 1e-8:
            for gi in range(len(self.groups)):
                self._s[gi] *= self._scale
                self._z[gi] *= self._scale
                self._yy[gi] *= self._scale
            self._scale = 1.0

    @property
    def samples(self) -> float:
        """Effective number of samples in the window."""
        return self._count

    def _blocks(self, gi: int) -> tuple[np.ndarray, ...]:
        g = self.groups[gi]
        d = g.columns.size
        upper = np.triu(self._s[gi])
        s = (upper + np.triu(upper, 1).T) * self._scale
        z = self._z[gi] * self._scale
        return s[:d, :d], s[:d, d:], s[d:, d:], z[:d], z[d:], self._yy[gi] * self._scale

    def _projected(self, gi: int, delta: np.ndarray | None = None, blocks: tuple | None = None
                   ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Window residual ``V`` at ``delta`` (first order), the gains, the residual's
        moments with the derivative regressors, and the factor of the gains' Gram."""
        sff, sfd, sdd, zf, zd, yy = blocks if blocks is not None else self._blocks(gi)
        if delta is not None and np.any(delta):
            # phi_delta = phi + T dphi:  S_ff <- S_ff + T S_df + S_fd T^T + T S_dd T^T
            t_sdf = self._apply_t(gi, delta, sfd.T)
            t_sdd = self._apply_t(gi, delta, sdd)
            sff = sff + t_sdf + t_sdf.T + self._apply_t(gi, delta, t_sdd.T)
            zf = zf + self._apply_t(gi, delta, zd)
        return self._solve(sff, sfd, zf, zd, yy)

    def _apply_t(self, gi: int, delta: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``T(delta) @ x`` for ``x`` with one row per derivative regressor: row
        ``positions[i, c]`` gets ``sum_p delta[i, p] x[(i, p, c)]``."""
        g = self.groups[gi]
        rows = x.reshape(self.m, 2, 5, -1)
        moved = np.einsum("ip,ipcn->icn", delta, rows)
        out = np.zeros((g.columns.size, x.shape[1]))
        out[g.positions.ravel()] = moved.reshape(self.m * 5, -1)     # distinct positions
        return out

    @staticmethod
    def _solve(sff: np.ndarray, sfd: np.ndarray, zf: np.ndarray, zd: np.ndarray,
               yy: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        ridge = 1e-9 * np.trace(sff) / max(sff.shape[0], 1) + 1e-12
        chol = np.linalg.cholesky(sff + ridge * np.eye(sff.shape[0]))
        theta = _solve_lower(chol, _solve_lower(chol, zf), transpose=True)
        v = yy - float(np.sum(zf * theta))
        return v, theta, zd - sfd.T @ theta, chol

    def refine(self, correlation_time: float = 1.0) -> np.ndarray | None:
        """One Gauss-Newton step on the window; updates :attr:`covariance`.

        Parameters
        ----------
        correlation_time : float
            Samples (>= 1) per independent one in the residual, which divides the
            window's evidence (a correlated residual is the model's misfit, not noise).

        Returns
        -------
        (M, 2) ndarray or None
            The correction ``delta`` to ``[log f, zeta]`` of each resonator; None when
            the window is too short or the step did not lower the residual.
        """
        if not correlation_time >= 1.0 or not np.isfinite(correlation_time):
            raise ValueError(f"correlation_time must be finite and >= 1, got {correlation_time}")
        if self._count < self.min_samples or self.m == 0:
            return None
        npar = 2 * self.m
        grad = np.zeros(npar)
        hess = np.zeros((npar, npar))
        v0 = 0.0
        m = self.m
        yy = 0.0
        all_blocks = [self._blocks(gi) for gi in range(len(self.groups))]
        try:
            for gi, g in enumerate(self.groups):
                sff, sfd, sdd, zf, zd, yy_g = all_blocks[gi]
                v, theta, resid, chol = self._solve(sff, sfd, zf, zd, yy_g)
                v0 += v
                yy += yy_g
                # derivative Gram with the gains' columns projected out (Kaufman)
                w = _solve_lower(chol, sfd)
                sp = (sdd - w.T @ w).reshape(m, 2, 5, m, 2, 5)
                coef = theta[g.positions]                        # (M, 5, r)
                # d V / d delta_(i,p) = -2 sum_(c, o) Theta[(i, c), o] resid[(i, p, c), o]
                grad += -2.0 * np.einsum("ico,ipco->ip", coef,
                                         resid.reshape(m, 2, 5, -1)).ravel()
                hess += 2.0 * np.einsum("ico,ipcjqd,jdo->ipjq", coef, sp,
                                        coef).reshape(npar, npar)
        except np.linalg.LinAlgError:
            return None
        if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(hess))):
            return None
        n_out = sum(g.rows.size for g in self.groups)
        # residual variance, floored at RESOLUTION^2 of the signal: below that the
        # residual is the model's own structural error, not evidence about rho
        sigma2 = correlation_time * max(v0, RESOLUTION**2 * yy) / max(self._count * n_out, 1.0)
        # maximum a posteriori step: the window's evidence against a prior on how far
        # the resonators move in one refinement (random walk)
        prior = np.tile(np.array(self.step_std) ** -2, self.m)
        if not self.damping:
            prior[1::2] = 1e12
        h = hess / sigma2 + 2.0 * np.diag(prior)
        gf = grad / sigma2
        try:
            step = -np.linalg.solve(h, gf)
            self.covariance = 2.0 * np.linalg.inv(h)
        except np.linalg.LinAlgError:
            return None
        delta = step.reshape(self.m, 2)
        limit = np.array(MAX_STEP)
        biggest = np.max(np.abs(delta) / limit) if delta.size else 0.0
        if biggest > 1.0:
            delta = delta / biggest
        if not np.any(delta):
            return None
        try:
            v1 = sum(self._projected(gi, delta, all_blocks[gi])[0]
                     for gi in range(len(self.groups)))
        except np.linalg.LinAlgError:
            return None
        # the step must explain more of the window than a model with that many more
        # parameters would by chance (an information criterion: one unit per parameter)
        moved = int(np.count_nonzero(delta))
        gain = (v0 - v1) / sigma2 - float(np.sum(delta.ravel() ** 2 * prior))
        if not gain > moved:
            self.n_rejected += 1
            return None
        self.n_steps += 1
        return delta

    def recenter(self, delta: np.ndarray) -> None:
        """Move the window's linearization point by ``delta`` (the bank moved too):
        ``phi <- phi + T(delta) dphi`` in every moment (first order)."""
        for gi, g in enumerate(self.groups):
            d = g.columns.size
            upper = np.triu(self._s[gi])
            s = upper + np.triu(upper, 1).T
            sfd, sdd = s[:d, d:], s[d:, d:]
            t_sdf = self._apply_t(gi, delta, sfd.T)
            t_sdd = self._apply_t(gi, delta, sdd)
            s[:d, :d] += t_sdf + t_sdf.T + self._apply_t(gi, delta, t_sdd.T)
            s[:d, d:] += t_sdd
            self._s[gi] = np.asfortranarray(np.triu(s))
            self._z[gi][:d] += self._apply_t(gi, delta, self._z[gi][d:])

    @staticmethod
    def clip(frequency_hz: float, damping: float, dlogf: float, dzeta: float
             ) -> tuple[float, float]:
        """A resonator moved by ``(dlogf, dzeta)``, damping kept in range.

        Returns
        -------
        (float, float)
            The moved frequency, Hz, and damping ratio.
        """
        return (frequency_hz * float(np.exp(dlogf)),
                float(np.clip(damping + dzeta, MIN_DAMPING, MAX_DAMPING)))
