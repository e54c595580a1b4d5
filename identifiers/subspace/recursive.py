"""The stages the recursive PBSID methods are built from.

* :class:`RecursiveVARXIdentifier`: the recursive VARX predictor (paper
  Eq. 20-24), which every recursive PBSID method updates first;
* :class:`SystemRLSIdentifier`: RLS for ``[C D]`` and ``[A B K]`` on a state
  sequence (Eq. 47-55), for the methods that regress on states
  (:class:`identifiers.subspace.improved.ImprovedRPBSID`,
  :class:`identifiers.subspace.predictor.PredictorRPBSID`,
  :class:`identifiers.subspace.classical.ClassicalRPBSID`), and
  :class:`PredictionStateIdentifier`, the state ``x = W LK phi`` of the last
  two.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.checks import forgetting_factor, positive_float, positive_int
from identifiers.core.online import OnlineIdentifier
from identifiers.core.rls import RecursiveLeastSquares

__all__ = [
    "PredictionStateIdentifier",
    "RecursiveVARXIdentifier",
    "SystemRLSIdentifier",
    "state_horizon",
]


def state_horizon(f: int | None, n: int, m: int, basis: str) -> int:
    """Prediction horizon (samples) of a state built from stacked output predictions.

    Default ``2 ceil(n / m)`` for a basis fitted to the predictions (twice
    the minimum, which measured best on the ETS-VIII model) and
    ``ceil(n / m)`` for the plain selection ``W = [I_n 0]``.

    Returns
    -------
    int
        The horizon f, in samples.

    Raises
    ------
    ValueError
        If ``f m < n``: the predictions cannot span an n-dimensional state.
    """
    horizon = (2 * -(-n // m) if basis == "svd" else -(-n // m)) if f is None else f
    if horizon * m < n:
        raise ValueError(f"f * m = {horizon * m} must be >= n = {n}; increase f")
    return horizon


class RecursiveVARXIdentifier(OnlineIdentifier):
    """An online identifier whose first stage is the recursive VARX predictor.

    ``y_k = Xi phi_k + e_k`` by exponentially weighted RLS (paper Eq. 20-24),
    ``Xi = [Xi_1, ..., Xi_p]`` with ``Xi_i ~ C At^(i-1) Bt``. Every recursive
    PBSID method builds its state from ``Xi``.

    The defaults are the best settings measured on the spacecraft at 40 dB
    (docs/results/identification.md): a long memory (forgetting 0.9995), a
    small Tikhonov floor on the VARX (1e-4 of the memory) and a 50 s warm-up.
    :meth:`paper` gives the source paper's constants instead.

    Parameters
    ----------
    n, p, forgetting, dt, input_scale, output_scale
        See :class:`OnlineIdentifier`; ``forgetting`` is the default of
        every stage's forgetting factor.
    warmup : int, optional
        Samples before a model is given; None: ``max(4 p, p + 2 n)``.
    varx_forgetting : float, optional
        beta_1, forgetting of the VARX (default ``forgetting``).
    varx_init : float
        alpha_1: the VARX covariance starts at ``I / alpha_1`` (normalized
        signals; paper: 0.9).
    regularization : float
        Tikhonov floor of the VARX as a fraction c of its effective memory:
        ``delta = c / (1 - beta_1)`` in normalized units (see
        :class:`identifiers.core.rls.RecursiveLeastSquares`). A VARX with
        p (r + m) regressors on an order-n plant has many weakly excited
        directions in which noise is fitted with huge cancelling
        coefficients; the floor keeps its Markov parameters sane. With 0 the
        floor is the RLS default, the prior ``1 / P_0 = alpha_1``, which
        only keeps the covariance bounded where nothing is excited.
    outlier_threshold : float or None
        Reject samples whose one-step innovation exceeds this many running
        RMS on any channel (see :meth:`_admissible`); default 30 (Gaussian
        noise never gets there; a run of more than
        :data:`OUTLIER_RUN` rejections is learned from as a change). None
        turns the guard off.
    max_abs : float
        See :class:`OnlineIdentifier`.
    """

    #: The source paper's constants for the ETS-VIII runs (see :meth:`paper`):
    #: p = 15, every forgetting factor 0.98, initial covariances I / 0.9, no
    #: regularization, the short warm-up ``max(4 p, p + 2 n)``.
    PAPER_SETTINGS: ClassVar[Mapping[str, Any]] = MappingProxyType({
        "p": 15, "forgetting": 0.98, "regularization": 0.0, "warmup": None, "varx_init": 0.9})

    @classmethod
    def paper(cls, n: int, **overrides: Any) -> RecursiveVARXIdentifier:
        """The method with the source paper's constants (:attr:`PAPER_SETTINGS`), to
        reproduce its tables; ``overrides`` change single settings (e.g. ``dt``).

        Returns
        -------
        RecursiveVARXIdentifier
            A new identifier of order ``n`` with the paper's settings.
        """
        return cls(n, **{**cls.PAPER_SETTINGS, **overrides})

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.9995, *, dt: float = 0.1,
                 warmup: int | None = 500, regularization: float = 1e-4,
                 varx_forgetting: float | None = None, varx_init: float = 0.9,
                 outlier_threshold: float | None = 30.0,
                 input_scale: ArrayLike | None = None,
                 output_scale: ArrayLike | None = None, max_abs: float = 1e6) -> None:
        forgetting = forgetting_factor("forgetting", forgetting)
        if not (np.isfinite(regularization) and regularization >= 0):
            raise ValueError(f"regularization must be >= 0, got {regularization}")
        self.regularization = float(regularization)
        self.varx_forgetting = forgetting_factor(
            "varx_forgetting", forgetting if varx_forgetting is None else varx_forgetting)
        self.varx_init = positive_float("varx_init", varx_init)
        self.outlier_threshold = (None if outlier_threshold is None
                                  else positive_float("outlier_threshold", outlier_threshold))
        if warmup is None:
            warmup = max(4 * positive_int("p", p), p + 2 * positive_int("n", n))
        super().__init__(n, p, forgetting, dt=dt, warmup=warmup, input_scale=input_scale,
                         output_scale=output_scale, max_abs=max_abs)

    def reset(self) -> None:
        super().reset()
        self._varx = None
        self._innovation_ms: np.ndarray | None = None    # running mean square, per channel

    def _allocate(self, r: int, m: int) -> None:
        # information floor of the VARX: c / (1 - beta_1), or the prior 1 / P_0
        floor = (self.regularization / (1.0 - self.varx_forgetting)
                 if self.regularization > 0 and self.varx_forgetting < 1.0 else None)
        self._varx = RecursiveLeastSquares(m, self.p * (r + m), self.varx_forgetting,
                                           1.0 / self.varx_init, regularization=floor)

    @property
    def xi(self) -> np.ndarray | None:
        """Current VARX matrix ``[Xi_1, ..., Xi_p]`` (m x p (r + m)), normalized units."""
        return None if self._varx is None else self._varx.theta.copy()

    def _predict_output(self) -> np.ndarray:
        """The VARX's one-step prediction of the next output sample (normalized)."""
        return self._varx.predict(self._phi)

    def _fill_output(self) -> np.ndarray:
        return self._predict_output()

    def _admissible(self, u: np.ndarray, y: np.ndarray) -> bool | np.ndarray:
        """The outlier guard on the normalized one-step innovation.

        With ``outlier_threshold = c``, once warmed up a sample whose VARX
        innovation ``y - Xi phi`` exceeds ``c`` times its running RMS (per
        channel, memory 1 / (1 - varx_forgetting)) on any channel is
        rejected, and those channels are replaced by their prediction (the
        base class counts it in ``n_outliers``); accepted samples update the
        running RMS.
        """
        if self.outlier_threshold is None or self._k < self.p:
            return True
        innovation_sq = (y - self._predict_output()) ** 2
        ms = self._innovation_ms
        if ms is not None and self._k >= self.warmup:
            inside = innovation_sq <= self.outlier_threshold**2 * ms
            if not inside.all():
                self._rejected_sq = innovation_sq
                return inside
        self._track_innovation(innovation_sq)
        return True

    def _track_innovation(self, innovation_sq: np.ndarray) -> None:
        lam = self.varx_forgetting
        ms = self._innovation_ms
        self._innovation_ms = (innovation_sq if ms is None
                               else lam * ms + (1.0 - lam) * innovation_sq)

    def _accept_outlier_run(self, u: np.ndarray, y: np.ndarray) -> None:
        # a run of rejections: the innovations' level has changed; follow it
        self._track_innovation(self._rejected_sq)


class SystemRLSIdentifier(RecursiveVARXIdentifier):
    """Recursive VARX plus RLS for the system matrices on a state sequence.

    Given states ``x_k`` from the subclass, RLS for ``y_k = C x_k (+ D u_k)``
    (paper Eq. 47-48) and ``x_{k+1} = A x_k + B u_k + K e_k`` (Eq. 49-55, in
    innovation form, see :meth:`_learn_system`).

    Parameters
    ----------
    output_forgetting, system_forgetting : float, optional
        beta_3 (``[C D]``) and beta_4 (``[A B K]``); default ``forgetting``.
    output_init, system_init : float
        alpha_2, alpha_3: initial covariances ``I / alpha`` (paper: 0.9).
    feedthrough : bool
        Estimate D (default False: strictly proper, D = 0).
    **kwargs
        Those of :class:`RecursiveVARXIdentifier`.
    """

    PAPER_SETTINGS: ClassVar[Mapping[str, Any]] = MappingProxyType({
        **RecursiveVARXIdentifier.PAPER_SETTINGS, "output_init": 0.9, "system_init": 0.9})

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.9995, *,
                 output_forgetting: float | None = None,
                 system_forgetting: float | None = None, output_init: float = 0.9,
                 system_init: float = 0.9, feedthrough: bool = False, **kwargs: Any) -> None:
        forgetting = forgetting_factor("forgetting", forgetting)
        self.output_forgetting = forgetting_factor(
            "output_forgetting", forgetting if output_forgetting is None else output_forgetting)
        self.system_forgetting = forgetting_factor(
            "system_forgetting", forgetting if system_forgetting is None else system_forgetting)
        self.output_init = positive_float("output_init", output_init)
        self.system_init = positive_float("system_init", system_init)
        self.feedthrough = bool(feedthrough)
        super().__init__(n, p, forgetting, **kwargs)

    def reset(self) -> None:
        super().reset()
        self._output_rls = self._system_rls = None
        self._x = None

    def _allocate(self, r: int, m: int) -> None:
        super()._allocate(r, m)
        n = self.n
        self._output_rls = RecursiveLeastSquares(m, n + (r if self.feedthrough else 0),
                                                 self.output_forgetting, 1.0 / self.output_init)
        self._system_rls = RecursiveLeastSquares(n, n + r + m, self.system_forgetting,
                                                 1.0 / self.system_init)

    def _learn_system(self, x_k: np.ndarray, u: np.ndarray, y: np.ndarray,
                      x_next: np.ndarray) -> None:
        """RLS for ``y_k = C x_k (+ D u_k) + e_k`` and ``x_{k+1} = A x_k + B u_k + K e_k``.

        Paper Eq. 47-55 regress ``x_{k+1}`` on ``[x_k; u_k; y_k]`` for
        ``[At, Bt]`` and recover ``A = At + K C``. We regress on the
        innovation ``e_k = y_k - C_k x_k`` instead (the batch PBSID form): the
        same model, but where the data carry little innovation (low noise)
        ``[x; u; y]`` is nearly collinear (``y ~ C x``) and RLS with
        forgetting winds up along that direction, while ``[x; u; e]`` keeps
        A and B well determined.
        """
        reg = np.concatenate((x_k, u)) if self.feedthrough else x_k
        self._output_rls.update(reg, y)
        e = y - self._output_rls.theta @ reg
        self._system_rls.update(np.concatenate((x_k, u, e)), x_next)

    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        if self._x is None:
            return None
        n, r = self.n, self.n_inputs
        cd = self._output_rls.theta
        c = cd[:, :n]
        d = cd[:, n:] if self.feedthrough else np.zeros((self.n_outputs, r))
        sys_ = self._system_rls.theta
        return sys_[:, :n], sys_[:, n:n + r], c, d, sys_[:, n + r:]

    def _current_state(self) -> np.ndarray | None:
        return self._x


class PredictionStateIdentifier(SystemRLSIdentifier):
    """State from the VARX's stacked output predictions, then RLS system matrices.

    The state is ``x_k = W P(phi_k)`` where ``P`` stacks the output
    predictions ``[yhat_k; ...; yhat_{k+f-1}]`` (= ``LK phi_k``, computed by
    the subclass), and the selection ``W`` is

    * ``basis="svd"`` (default): the n leading left singular vectors of the
      predictions over the warm-up samples, computed once when warm-up ends
      and fixed afterwards (no SVD per step). A balanced, well-conditioned
      basis. The warm-up's states in that basis then go through the system
      stage at once, so ``C`` and ``[A B K]`` learn from the warm-up too
      (without it they would start after it: in a closed loop whose only
      large torques are the warm-up's excitation, ``B`` would see the loop's
      torques at the noise level alone).
    * ``basis="selection"``: ``W = [I_n 0]``, the first n predicted outputs.
      Cheapest, but on outputs that are nearly collinear over a few samples
      (an angle and its rate at dt = 0.1 s) the basis is badly conditioned.

    Parameters
    ----------
    f : int, optional
        Prediction horizon of the state, in samples (rows of LK); default
        from :func:`state_horizon`.
    basis : {"svd", "selection"}
    **kwargs
        Those of :class:`SystemRLSIdentifier`.
    """

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.9995, *,
                 f: int | None = None, basis: str = "svd", **kwargs: Any) -> None:
        if basis not in ("svd", "selection"):
            raise ValueError(f"basis must be 'svd' or 'selection', got {basis!r}")
        self.basis = basis
        self.f = None if f is None else positive_int("f", f)
        super().__init__(n, p, forgetting, **kwargs)
        if basis == "svd" and self.warmup - self.p < self.n:
            raise ValueError(f"the SVD basis needs warmup >= p + n = {self.p + self.n}")

    def reset(self) -> None:
        super().reset()
        self._w = None
        # the warm-up's learnt samples: (k, phi_(k+1), u_k, y_k)
        self._basis_data: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []

    def _allocate(self, r: int, m: int) -> None:
        super()._allocate(r, m)
        self._horizon = state_horizon(self.f, self.n, m, self.basis)
        if self.basis == "selection":
            self._w = np.eye(self.n, self._horizon * m)

    @abstractmethod
    def _predictions(self, phi: np.ndarray) -> np.ndarray:
        """Stacked output predictions ``LK phi`` over the horizon, (f m,)."""

    def _predictions_many(self, phis: np.ndarray) -> np.ndarray:
        """:meth:`_predictions` of each row of ``phis`` (N, p (r + m)), as rows (N, f m)."""
        return np.array([self._predictions(phi) for phi in phis])

    def _fix_basis(self) -> None:
        """W from the SVD of the warm-up predictions (once), then the warm-up's state
        sequence ``x_(k+1) = W P(phi_(k+1))`` through the system stage: sample ``k``
        teaches ``C`` and ``[A B K]`` whenever ``x_k`` is known (sample ``k - 1`` was
        learnt from too), as :meth:`_step` does from here on."""
        samples = self._basis_data
        preds = self._predictions_many(np.array([phi for _, phi, _, _ in samples]))
        left = np.linalg.svd(preds.T, full_matrices=False)[0]
        self._w = left[:, :self.n].T.copy()
        states = preds @ self._w.T
        for j in range(1, len(samples)):
            k, _, u, y = samples[j]
            if samples[j - 1][0] == k - 1:
                self._learn_system(states[j - 1], u, y, states[j])
        self._basis_data = []

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        if learn:
            self._varx.update(self._phi, y)
        self._push(u, y)
        if self._w is None:
            if learn:
                self._basis_data.append((self._k, self._phi.copy(), u, y))
            if self._k + 1 >= self.warmup and len(self._basis_data) >= self.n:
                self._fix_basis()        # this sample's system step included
                self._x = self._w @ self._predictions(self._phi)
            return
        x_next = self._w @ self._predictions(self._phi)
        if learn and self._x is not None:
            self._learn_system(self._x, u, y, x_next)
        self._x = x_next
