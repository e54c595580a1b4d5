"""The one recursive-least-squares primitive every identifier shares.

Exponentially weighted RLS for a matrix regression ``y_k = Theta phi_k + e_k``
(paper Eq. 23-24, 41-46, 51-55 are all instances)::

    g_k     = P_{k-1} phi_k / (lambda + phi_k^T P_{k-1} phi_k)
    Theta_k = Theta_{k-1} + (y_k - Theta_{k-1} phi_k) g_k^T
    P_k     = (P_{k-1} - g_k phi_k^T P_{k-1}) / lambda

``P`` is stored as ``s Q`` with a scalar ``s``: forgetting only rescales
``s``, and the rank-1 correction is an in-place BLAS update (``dger``) of the
Fortran-ordered ``Q``, so a step costs two O(d^2) passes (``Q phi`` and the
rank-1 update) and no d x d temporaries.

Anti-windup: when the regressor carries no new information the division by
``lambda`` would inflate ``P`` without bound (``P / lambda^k``), and later
gains along those directions would explode. The trace of ``P`` (an O(d)
diagonal sum) is checked every step and forgetting is suspended while it
exceeds ``max_trace`` (default:
the trace of ``P_0``), so the covariance never grows past the prior's and
stays bounded under zero excitation.

Regularization: with ``lambda < 1`` the prior ``P_0`` is forgotten like any
other data, and a regression with many weakly excited directions (a VARX
with p (r + m) = 195 regressors on a plant of order 22) then fits noise with
huge cancelling coefficients. ``regularization = delta > 0`` keeps a
constant information floor, ``P^-1 >= delta I`` in steady state (Tikhonov
regularized forgetting): each step adds one pseudo-observation
``0 = Theta (w e_i)`` along a coordinate ``e_i`` cycling through all d, with
``w^2 = d (1 - lambda) delta``, which over d steps adds ``(1 - lambda) delta I``
per step to the information and pulls unexcited coefficients to zero.
It costs one more O(d^2) rank-1 update per step.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import dger

__all__ = ["RecursiveLeastSquares"]


class RecursiveLeastSquares:
    """Exponentially weighted recursive least squares for ``y = Theta phi``.

    Parameters
    ----------
    n_outputs : int
        Rows q of ``Theta`` (size of ``y``).
    n_regressors : int
        Columns d of ``Theta`` (size of ``phi``).
    forgetting : float
        Forgetting factor lambda in (0, 1].
    initial_covariance : float
        ``P_0 = initial_covariance * I`` (the paper's ``I / alpha``).
    max_trace : float, optional
        Forgetting is suspended while ``trace(P)`` exceeds this; default
        ``trace(P_0) = d * initial_covariance``.
    regularization : float
        Information floor delta (0: none), see the module docstring.

    Attributes
    ----------
    theta : (q, d) ndarray
        Current estimate.
    P : (d, d) ndarray
        Current (scaled) covariance, Fortran-ordered.
    """

    def __init__(self, n_outputs: int, n_regressors: int, forgetting: float = 1.0,
                 initial_covariance: float = 1.0, max_trace: float | None = None,
                 regularization: float = 0.0) -> None:
        if n_outputs < 1 or n_regressors < 1:
            raise ValueError("n_outputs and n_regressors must be >= 1")
        if not 0.0 < forgetting <= 1.0:
            raise ValueError(f"forgetting must be in (0, 1], got {forgetting}")
        if not np.isfinite(initial_covariance) or initial_covariance <= 0:
            raise ValueError(f"initial_covariance must be positive, got {initial_covariance}")
        self.forgetting = float(forgetting)
        self.initial_covariance = float(initial_covariance)
        self.max_trace = (n_regressors * self.initial_covariance if max_trace is None
                          else float(max_trace))
        if not np.isfinite(regularization) or regularization < 0:
            raise ValueError(f"regularization must be >= 0, got {regularization}")
        self.regularization = float(regularization)
        self._pseudo_weight = float(np.sqrt(n_regressors * (1.0 - self.forgetting)
                                            * self.regularization))
        self.theta = np.zeros((n_outputs, n_regressors), order="F")
        self.reset()

    @property
    def shape(self) -> tuple[int, int]:
        """``(q, d)``."""
        return self.theta.shape

    @property
    def P(self) -> np.ndarray:
        """Current (scaled) covariance, (d, d)."""
        return self._scale * self._q

    def predict(self, phi: np.ndarray) -> np.ndarray:
        """``Theta phi``."""
        return self.theta @ phi

    def update(self, phi: np.ndarray, y: np.ndarray) -> np.ndarray:
        """One RLS step; returns the a-priori error ``y - Theta_{k-1} phi``.

        Parameters
        ----------
        phi : (d,) ndarray
            Regressor (finite; callers validate).
        y : (q,) ndarray
            Target.
        """
        scale = self._scale
        p_phi = self._q @ phi
        p_phi *= scale                                   # P phi
        denom = self.forgetting + phi @ p_phi
        gain = p_phi / denom
        err = y - self.theta @ phi
        self.theta = dger(1.0, err, gain, a=self.theta, overwrite_a=True)
        # P <- P - g (P phi)^T, i.e. Q <- Q - g (P phi)^T / s, in place
        self._q = dger(-1.0 / scale, gain, p_phi, a=self._q, overwrite_a=True)
        if self._pseudo_weight > 0.0:
            self._pseudo_update()
        if self.forgetting < 1.0 and self._scale * self._q.trace() < self.max_trace:
            self._scale /= self.forgetting
            if self._scale > 1e6:
                self._renormalize()
        return err

    def _pseudo_update(self) -> None:
        """Rank-1 pseudo-observation ``0 = Theta (w e_i)`` (regularized forgetting)."""
        i = self._cycle
        self._cycle = (i + 1) % self.theta.shape[1]
        w = self._pseudo_weight
        p_phi = self._q[:, i] * (self._scale * w)        # P (w e_i), no matvec needed
        denom = 1.0 + w * p_phi[i]
        gain = p_phi / denom
        err = -w * self.theta[:, i]
        self.theta = dger(1.0, err, gain, a=self.theta, overwrite_a=True)
        self._q = dger(-1.0 / self._scale, gain, p_phi, a=self._q, overwrite_a=True)

    def _renormalize(self) -> None:
        self._q *= self._scale
        self._scale = 1.0

    def symmetrize(self) -> None:
        """Restore exact symmetry of ``P`` (round-off drifts it slowly)."""
        self._renormalize()
        self._q = np.asfortranarray(0.5 * (self._q + self._q.T))

    def reset(self) -> None:
        """Back to ``Theta = 0``, ``P = P_0``."""
        d = self.theta.shape[1]
        self.theta[:] = 0.0
        self._q = np.asfortranarray(np.eye(d) * self.initial_covariance)
        self._scale = 1.0
        self._cycle = 0
