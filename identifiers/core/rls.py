"""The one recursive-least-squares primitive every identifier shares.

Exponentially weighted RLS for a matrix regression ``y_k = Theta phi_k + e_k``
(paper Eq. 23-24, 41-46, 51-55 are all instances)::

    g_k     = P_{k-1} phi_k / (lambda + phi_k^T P_{k-1} phi_k)
    Theta_k = Theta_{k-1} + (y_k - Theta_{k-1} phi_k) g_k^T
    P_k     = (P_{k-1} - g_k phi_k^T P_{k-1}) / lambda

Symmetric by construction
    Only the upper triangle of ``P`` is stored and used: ``P phi`` is a
    symmetric matrix-vector product and the correction
    ``- (P phi)(P phi)^T / denom`` a symmetric rank-1 update of that
    triangle (one compiled pass per update:
    :func:`identifiers.core.rls_kernel.rls_step`). The plain update lets the
    non-symmetric part of ``P`` grow by ``1 / lambda`` per step until ``P``
    turns indefinite; with one triangle there is no non-symmetric part to
    grow, and the symmetric recursion is numerically stable for
    ``lambda < 1`` (Verhaegen, 1989). ``P`` is kept as a scalar times a
    matrix, so forgetting is a rescale.

Forgetting that really forgets, with a bounded covariance
    Forgetting is applied at every step, in every direction. Where data
    carry no excitation, plain forgetting would inflate ``P`` as
    ``P / lambda^k`` (wind-up). Instead, *regularized forgetting* keeps an
    information floor: the information matrix obeys ::

        R_k = lambda R_{k-1} + phi_k phi_k^T + (1 - lambda) delta I      (on average)

    so forgotten information is replaced by the prior ``delta I``, not by
    nothing, and ``P`` is pulled back toward the fixed bound ``I / delta``
    in unexcited directions while excited ones track the data with memory
    ``1 / (1 - lambda)``. The default ``delta = 1 / initial_covariance``
    pulls ``P`` back to ``P_0``. The floor is added one coordinate per step
    as a pseudo-observation ``0 = Theta (w e_i)`` with ``w^2 = d (1 - lambda)
    delta``, cycling through all d coordinates, which over any d steps adds
    the same information as ``(1 - lambda) delta I`` per step, at the cost of
    one more O(d^2) rank-1 update. It is exactly Tikhonov-regularized
    exponentially weighted least squares with those pseudo-rows; with
    ``regularization=0`` the primitive is plain exponentially weighted least
    squares (tests compare both with the closed form over 20,000 samples).

Forgetting per parameter
    ``forgetting`` may be a vector: parameter i then forgets at its own rate
    ``lambda_i`` (*vector forgetting*): ``R_k = L R_{k-1} L + phi_k phi_k^T``
    with ``L = diag(lambda)^(1/2)``, so fast-changing parameters (a
    spacecraft's inertia at a docking) track with a short memory while
    slowly identifiable ones (many weakly excited modal couplings) keep a
    long one. The covariance is rescaled by ``L^-1 (.) L^-1`` before each
    update (one elementwise product of the stored triangle); the floor's
    pseudo-rows then carry ``(1 - lambda_i) delta_i`` each. With equal
    entries it is the scalar recursion.

Corrupt data never enter
    An update whose gain or error is not finite, or whose products could
    overflow, is refused before anything changes (counted in
    ``n_rejected``), so ``Theta`` and ``P`` stay finite.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.rls_kernel import rls_step, rls_steps

__all__ = ["RecursiveLeastSquares"]

#: Products larger than this are refused (their sums could overflow).
_OVERFLOW_GUARD = 1e150


class RecursiveLeastSquares:
    """Exponentially weighted, regularized recursive least squares for ``y = Theta phi``.

    Parameters
    ----------
    n_outputs : int
        Rows q of ``Theta`` (size of ``y``).
    n_regressors : int
        Columns d of ``Theta`` (size of ``phi``).
    forgetting : float or (d,) array_like
        Forgetting factor lambda in (0, 1]: memory ``1 / (1 - lambda)``
        samples; a vector gives every regressor its own (vector forgetting).
    initial_covariance : float
        ``P_0 = initial_covariance * I`` (the paper's ``I / alpha``).
    regularization : float or (d,) array_like, optional
        Information floor delta (>= 0) that forgotten information is
        replaced by; ``P`` is bounded by about ``I / delta`` where the data
        carry no excitation. A vector gives each regressor its own floor
        (``diag(delta)``). Default ``1 / initial_covariance`` (pull ``P``
        back to ``P_0``); 0 gives plain exponentially weighted least squares,
        whose ``P`` grows without bound when nothing is excited.
    gate : float, optional
        Forget only as much as the sample informs (excitation-gated
        forgetting): each update's forgetting ``1 - lambda`` (and the floor's
        pseudo-row) is scaled by ``min(1, phi^T P phi / (gate d (1 - lambda)))``,
        the new sample's information relative to that of the data which set
        ``P`` (``d (1 - lambda)`` at steady state). Where the regressors fall
        quiet (a regulator holding the spacecraft still) nothing is forgotten,
        so the estimate neither drifts with the noise nor loses what it knew;
        as informative data come back, the nominal memory returns. None
        (default): plain forgetting, exactly weighted least squares.
    drift : float or (d,) array_like, optional
        Random-walk variance of each parameter per sample, added to the
        diagonal of ``P`` after every update: with ``forgetting=1`` the
        recursion is then the Kalman filter of parameters that drift as a
        random walk (``Theta_k = Theta_{k-1} + w_k``, ``cov(w_k) =
        noise_variance * diag(drift)``), which tracks change in the
        parameters that are expected to change and keeps a long memory for
        the others, without the bias vector forgetting has when regressors
        are correlated. ``P`` is in units of the measurement noise variance:
        the estimate's covariance is ``noise_variance * P``. Default 0.
    hold : (d,) array_like of bool, optional
        Coordinates whose floor bounds ``P`` without pulling the estimate:
        the floor is Tikhonov regularization toward 0, right for couplings
        that may be absent and wrong for a gain known to be non-zero (a
        rigid body's inverse inertia would decay toward 0 whenever the
        data stop exciting it). Default: none held.

    Attributes
    ----------
    theta : (q, d) ndarray
        Current estimate.
    n_rejected : int
        Updates refused because they would have made the estimate non-finite.
    """

    def __init__(self, n_outputs: int, n_regressors: int, forgetting: float | ArrayLike = 1.0,
                 initial_covariance: float = 1.0, regularization: float | None = None,
                 hold: ArrayLike | None = None, gate: float | None = None,
                 drift: float | ArrayLike = 0.0) -> None:
        if n_outputs < 1 or n_regressors < 1:
            raise ValueError("n_outputs and n_regressors must be >= 1")
        lam = np.asarray(forgetting, dtype=float)
        if lam.ndim > 1 or (lam.ndim == 1 and lam.shape != (n_regressors,)):
            raise ValueError(f"forgetting must be a scalar or ({n_regressors},), "
                             f"got shape {lam.shape}")
        if not (np.all(lam > 0.0) and np.all(lam <= 1.0)):
            raise ValueError(f"forgetting must be in (0, 1], got {forgetting}")
        if not (np.isfinite(initial_covariance) and initial_covariance > 0):
            raise ValueError(f"initial_covariance must be positive, got {initial_covariance}")
        lam = np.broadcast_to(lam, (n_regressors,))
        #: The scalar forgetting, or None when parameters forget at their own rates.
        self.forgetting: float | None = float(lam[0]) if np.all(lam == lam[0]) else None
        self._lam = lam.copy()
        self.initial_covariance = float(initial_covariance)
        if regularization is None:
            regularization = 1.0 / self.initial_covariance
        delta = np.broadcast_to(np.asarray(regularization, dtype=float), (n_regressors,))
        if not (np.isfinite(delta).all() and np.all(delta >= 0)):
            raise ValueError(f"regularization must be >= 0 (a scalar or ({n_regressors},)), "
                             f"got {regularization}")
        self.regularization = delta.copy()
        hold_mask = np.zeros(n_regressors, dtype=bool) if hold is None else np.asarray(hold)
        if hold_mask.shape != (n_regressors,) or hold_mask.dtype != bool:
            raise ValueError(f"hold must be a boolean array of shape ({n_regressors},)")
        self.hold = hold_mask.copy()
        self.drift = np.zeros(n_regressors)
        self.set_drift(drift)
        if gate is not None and not (np.isfinite(gate) and gate > 0):
            raise ValueError(f"gate must be a positive fraction or None, got {gate}")
        self.gate = None if gate is None else float(gate)
        # phi^T P phi of a regressor as informative as the data that set P, at steady state
        self._gate_level = (None if gate is None
                            else float(gate) * n_regressors * float((1.0 - self._lam).max()))
        self.theta = np.zeros((n_outputs, n_regressors), order="F")
        self.reset()

    @property
    def shape(self) -> tuple[int, int]:
        """``(q, d)``."""
        return self.theta.shape

    @property
    def P(self) -> np.ndarray:
        """Current covariance, (d, d), exactly symmetric (a copy)."""
        upper = np.triu(self._q)
        return self._scale * (upper + np.triu(upper, 1).T)

    def predict(self, phi: np.ndarray) -> np.ndarray:
        """``Theta phi``.

        Returns
        -------
        (q,) ndarray
            The prediction ``Theta phi``.
        """
        return self.theta @ phi

    def update(self, phi: np.ndarray, y: np.ndarray) -> np.ndarray | None:
        """One RLS step; returns the a-priori error ``y - Theta_{k-1} phi``.

        Parameters
        ----------
        phi : (d,) ndarray
            Regressor.
        y : (q,) ndarray
            Target.

        Returns
        -------
        (q,) ndarray or None
            The a-priori error, or None if the update was refused (a
            non-finite or overflowing gain or error; nothing changed).
        """
        phi = np.ascontiguousarray(phi, dtype=float)
        y = np.ascontiguousarray(y, dtype=float)
        err = np.empty(self.theta.shape[0])
        accepted, self._scale, self._cycle = rls_step(
            self.theta, self._q, phi, y, self._lam, self.forgetting is None,
            -1.0 if self._gate_level is None else self._gate_level, self._pseudo_weights,
            self.hold, self._scale, self._cycle, _OVERFLOW_GUARD, err, self.drift)
        if not accepted:
            self.n_rejected += 1
            return None
        return err

    def update_many(self, phis: np.ndarray, ys: np.ndarray,
                    use: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`update` on each row in order, in one compiled loop (a replay).

        The result is the same, bit for bit, as calling :meth:`update` on the rows
        one after another (skipping those where ``use`` is False).

        Parameters
        ----------
        phis : (J, d) ndarray
            Regressors, one row per sample.
        ys : (J, q) ndarray
            Targets.
        use : (J,) ndarray of bool, optional
            Rows to apply (default: all).

        Returns
        -------
        errors : (J, q) ndarray
            Each applied row's a-priori error; NaN where the row was not applied or
            was refused.
        accepted : (J,) ndarray of bool
            Rows applied and accepted.

        Raises
        ------
        ValueError
            If the shapes do not match ``(J, d)``, ``(J, q)`` and ``(J,)``.
        """
        phis = np.ascontiguousarray(phis, dtype=float)
        ys = np.ascontiguousarray(ys, dtype=float)
        q, d = self.theta.shape
        n_rows = phis.shape[0] if phis.ndim == 2 else -1
        use = (np.ones(max(n_rows, 0), dtype=bool) if use is None
               else np.ascontiguousarray(use, dtype=bool))
        if phis.shape != (n_rows, d) or ys.shape != (n_rows, q) or use.shape != (n_rows,):
            raise ValueError(f"phis must be (J, {d}), ys (J, {q}) and use (J,), got "
                             f"{phis.shape}, {ys.shape}, {use.shape}")
        errors = np.full((n_rows, q), np.nan)
        accepted, self._scale, self._cycle = rls_steps(
            self.theta, self._q, phis, ys, self._lam, self.forgetting is None,
            -1.0 if self._gate_level is None else self._gate_level, self._pseudo_weights,
            self.hold, self._scale, self._cycle, _OVERFLOW_GUARD, errors, self.drift, use)
        self.n_rejected += int(np.count_nonzero(use & ~accepted))
        errors[~accepted] = np.nan
        return errors, accepted

    def reset(self) -> None:
        """Back to ``Theta = 0``, ``P = P_0``."""
        d = self.theta.shape[1]
        self.theta[:] = 0.0
        self._q = np.asfortranarray(np.eye(d) * self.initial_covariance)
        self._scale = 1.0
        self._cycle = 0
        self.n_rejected = 0

    def set_drift(self, drift: float | ArrayLike) -> None:
        """Replace the random-walk variance per sample (see ``drift`` above).

        The floor's pseudo-rows follow it, so the variance of an unexcited
        coordinate still settles at ``1 / regularization``; the estimate and
        ``P`` are kept. After this call the recursion is that of an RLS
        constructed with ``drift`` and holding the present state.

        Raises
        ------
        ValueError
            For a negative or non-finite drift, or one that is neither a scalar
            nor of shape ``(d,)``.
        """
        d = self.drift.size
        try:
            value = np.broadcast_to(np.asarray(drift, dtype=float), (d,))
        except ValueError:
            raise ValueError(f"drift must be a scalar or of shape ({d},), "
                             f"got shape {np.shape(drift)}") from None
        if not (np.isfinite(value).all() and np.all(value >= 0)):
            raise ValueError(f"drift must be >= 0 (a scalar or ({d},)), got {drift}")
        self.drift[:] = value           # in place: the compiled steps read this array
        # the floor's pseudo-rows: w^2 = d (1 - lambda) delta replaces what forgetting
        # removes; under a random walk of variance q it is w^2 = d q delta^2, for which
        # the variance of an unexcited coordinate settles at 1 / delta
        delta = self.regularization
        self._pseudo_weights = np.sqrt(d * ((1.0 - self._lam) * delta + self.drift * delta**2))

    def set_covariance(self, covariance: ArrayLike) -> None:
        """Replace ``P`` (symmetric positive definite, (d, d)), e.g. to inflate it
        after a detected change.

        Raises
        ------
        ValueError
            For a wrong shape or a non-symmetric / non-finite matrix.
        """
        p = np.asarray(covariance, dtype=float)
        d = self.theta.shape[1]
        if p.shape != (d, d) or not np.isfinite(p).all() or not np.allclose(p, p.T):
            raise ValueError(f"covariance must be a finite symmetric ({d}, {d}) matrix")
        self._q = np.array(p, order="F")          # a copy: updated in place
        self._scale = 1.0
