"""A structure-aware RPBSID: the rigid body known, a recursive PBSID on the rest.

A black-box recursive PBSID must place the rigid body's three double
integrators (a Jordan block at ``z = 1``) from noisy data, and the paper's
test responses tolerate almost no error there (docs/results/paper.md).
Physics fixes that block up to the inverse inertia ``G = J^-1``, so
:class:`StructuredRPBSID` keeps it exact
(:class:`identifiers.structured.rigid_block.RigidBlock`):

1. **One regression** (the paper's VARX, Eq. 20-24, extended):
   ``y_f,k = Theta_r rho_k + sum_i Xi_i z_{k-i} + e_k`` on high-passed signals, ``rho``
   the rigid regressors (``G`` is the rate rows' block of ``Theta_r``, its covariance the
   gain's calibrated band); no attitude or rate *level* in the past window. A change test
   on the rate rows discounts the rigid block at an alarm (a docking).
2. **The flexible part**: a recursive PBSID on ``w = y_f - Theta_r rho``, by default a
   classical RPBSID on the tip deflections
   (:class:`identifiers.structured.flexible_part.FlexiblePart`), or the paper's improved
   RPBSID (Eq. 25-55) on every row (``flexible="improved"``, the paper preset); its stable
   resonances above the high-pass's corner, damped at most 0.3, are exported
   (:func:`identifiers.structured.resonant.resonant_part`).
3. **The model**: ``A = diag(A_r, A_f)``, ``B = [B_r(G); B_f]``, ``C = [C_r, C_f]``; a
   Kalman filter on it and the raw signals gives the state and ``K``.

Design and measurements: ``docs/design/identification.md``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import block_diag

from identifiers.core.change_detection import ChangeEvent, RegressionGLR, resolved_variance
from identifiers.core.checks import positive_float
from identifiers.core.kalman import KalmanPredictor
from identifiers.core.modal_basis import HighPass
from identifiers.core.rigid_gain import RigidGainEstimate
from identifiers.core.rls import RecursiveLeastSquares
from identifiers.core.state_filter import ModelFilter
from identifiers.structured.flexible_part import FLEXIBLE_METHODS, FlexiblePart
from identifiers.structured.resonant import resonant_part
from identifiers.structured.rigid_block import (
    N_RIGID_REGRESSORS,
    RIGID_ORDER,
    RigidBlock,
    highpass_offset,
)
from identifiers.subspace.improved import ImprovedRPBSID
from spacecraft_conventions import NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["RIGID_PRIOR", "StructuredRPBSID"]

#: Initial covariance of the initial-condition coefficients (unit-peak regressors,
#: units of the noise variance): vague, so no prior pulls them.
RIGID_PRIOR = 1e6

#: Samples between refreshes of the combined model the Kalman filter runs on.
_REFRESH = 10


class StructuredRPBSID(ImprovedRPBSID):
    """A recursive PBSID on the flexible part, with an exact rigid block.

    Parameters
    ----------
    layout : OutputLayout
        The measured sensor groups, in the order of ``y`` (default: the
        environments' standard attitude, rate and four tip deflections).
        Attitude and rate are required.
    n : int
        Model order: 6 rigid states plus the flexible part's order ``n - 6``
        (default 22). :attr:`n` is the flexible part's order (the subspace
        method's), :attr:`order` the model's.
    p : int
        Past window of the VARX, samples (default 15, the paper's).
    forgetting : float
        Forgetting of every stage (default 0.9995; the paper's 0.98 is far too short).
    flexible : {"classical", "improved"}, optional
        The flexible part's method. ``"classical"`` (the default where the
        layout has tip deflections): a classical RPBSID of its own on them,
        the rows of ``C_f`` for attitude and rate by RLS on its state.
        ``"improved"`` (the default without deflections): the paper's improved
        RPBSID on every row of ``w``, inside this regression; its sign step
        cannot follow the modes (docs/design/identification.md).
    highpass : float
        Pole ``rho`` of the high-pass that removes the initial conditions'
        constants and ramps (default 0.97, the modal identifier's).
    process_torque : float
        Unmodelled torque (N m per axis, standard deviation) the Kalman filter
        assumes (default 10: it follows the sensors where the model disagrees).
    detect_changes : bool
        Watch the rate rows' errors with a likelihood-ratio test
        (:class:`identifiers.core.change_detection.RegressionGLR`) and,
        at an alarm (a docking), multiply the rigid block's covariance by
        ``discount`` and restart its initial-condition terms.
    min_mode_hz : float, optional
        Lowest frequency (Hz) of a flexible mode the exported model keeps
        (default: the high-pass's corner ``(1 - highpass) / (2 pi dt)``, below
        which the data carry no information).
    change_threshold, discount : float
        Alarm level (a multiple of the test's degrees of freedom) and the
        covariance factor at an alarm (defaults 10 and 10; the modal
        identifier's 6 raised false alarms here: docs/design/identification.md).
    warmup : int, optional
        Samples before a model is given (default 500: 50 s at 0.1 s; None:
        ``max(4 p, p + 2 (n - 6))``, the paper's).
    dt : float
        Sample time, s.
    input_scale, output_scale : array_like, optional
        Normalization; default 1 N m and the nominal levels of ``layout``.
    **kwargs
        The improved RPBSID's (``mu``, ``nu``, ``predict``, ``regularization``,
        ``outlier_threshold``, ...), see
        :class:`identifiers.subspace.improved.ImprovedRPBSID`.

    Attributes
    ----------
    order : int
        States of the exported model (``6 + n``).
    events : list of ChangeEvent
        Changes detected so far.

    Examples
    --------
    The gain of a noise-free rigid body (three ZOH double integrators) from 100 s
    of multisine torques:

    >>> import numpy as np
    >>> from identifiers import StructuredRPBSID, identification_inputs, relative_gain_error
    >>> from spacecraft_conventions import OutputLayout
    >>> layout = OutputLayout.of(("attitude", "rate"), n_sensors=0)
    >>> g = np.diag([1 / 30_000, 1 / 20_000, 1 / 22_000])    # J^-1, rad/s^2 per N m
    >>> u = identification_inputs(1000, np.random.default_rng(0))
    >>> psi, omega, y = np.zeros(3), np.zeros(3), []
    >>> for u_k in u:
    ...     y.append(np.concatenate((psi, omega)))
    ...     psi, omega = psi + 0.1 * omega + 0.005 * g @ u_k, omega + 0.1 * g @ u_k
    >>> ident = StructuredRPBSID(layout, n=8)
    >>> _ = ident.fit(u, np.array(y))
    >>> bool(relative_gain_error(ident.rigid_gain.gain, g) < 1e-3)
    True
    >>> ident.model.A.shape          # 6 rigid states and the flexible part's 2
    (8, 8)
    """

    _SIGNAL_STATE: ClassVar[tuple[str, ...]] = (
        *ImprovedRPBSID._SIGNAL_STATE, "_rigid", "_hp_y", "_hp_u", "_kf", "_dwin", "_w_last")

    def __init__(self, layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22, p: int = 15,
                 forgetting: float = 0.9995, flexible: str | None = None,
                 highpass: float = 0.97,
                 process_torque: float = 10.0, min_mode_hz: float | None = None,
                 detect_changes: bool = True,
                 change_threshold: float = 10.0, discount: float = 10.0,
                 warmup: int | None = 500, dt: float = 0.1,
                 input_scale: ArrayLike | None = None, output_scale: ArrayLike | None = None,
                 **kwargs: Any) -> None:
        if not isinstance(layout, OutputLayout):
            raise TypeError(f"layout must be an OutputLayout, got {type(layout).__name__}")
        self.layout = layout.sensors()
        missing = [g for g in ("attitude", "rate") if g not in self.layout]
        if missing:
            raise ValueError(f"the structure-aware RPBSID needs the sensor groups {missing}; "
                             f"the layout holds {self.layout.names}")
        if not isinstance(n, (int, np.integer)) or n <= RIGID_ORDER:
            raise ValueError(f"n must be an integer > {RIGID_ORDER} (6 rigid states plus the "
                             f"flexible part), got {n!r}")
        if flexible is None:
            flexible = "classical" if "deflection" in self.layout else "improved"
        if flexible not in FLEXIBLE_METHODS:
            raise ValueError(f"flexible must be one of {FLEXIBLE_METHODS}, got {flexible!r}")
        if flexible == "classical" and "deflection" not in self.layout:
            raise ValueError("flexible='classical' identifies the tip deflections; the layout "
                             f"holds {self.layout.names}")
        self.flexible = flexible
        if not 0 <= highpass < 1:
            raise ValueError(f"highpass must be in [0, 1), got {highpass}")
        self.highpass = float(highpass)
        self.process_torque = positive_float("process_torque", process_torque)
        self.min_mode_hz = ((1.0 - self.highpass) / (2.0 * np.pi * dt) if min_mode_hz is None
                            else positive_float("min_mode_hz", min_mode_hz))
        self.detect_changes = bool(detect_changes)
        self.change_threshold = positive_float("change_threshold", change_threshold)
        self.discount = positive_float("discount", discount)
        self.order = int(n)
        scales = (np.full(3, NOMINAL_TORQUE) if input_scale is None else input_scale,
                  self.layout.scales() if output_scale is None else output_scale)
        super().__init__(int(n) - RIGID_ORDER, p, forgetting, warmup=warmup, dt=dt,
                         input_scale=scales[0], output_scale=scales[1], **kwargs)

    @classmethod
    def paper(cls, layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22,
              **overrides: Any) -> StructuredRPBSID:
        """The flexible part by the paper's improved RPBSID with its constants (p = 15,
        every forgetting 0.98, the sign step alone), the rigid block unchanged.

        Returns
        -------
        StructuredRPBSID
            A new identifier with those settings.
        """
        return cls(layout, n=n, **{"flexible": "improved", **cls.PAPER_SETTINGS, **overrides})

    # ------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        super().reset()
        self._rigid: RigidBlock | None = None
        self._hp_y = self._hp_u = None
        self._kf: KalmanPredictor | None = None
        self._combined: tuple[np.ndarray, ...] | None = None
        self._errvar = self._sigvar = None      # running mean squares: errors, signals
        self._detector = RegressionGLR(threshold=self.change_threshold, dt=self.dt)
        self.events: list[ChangeEvent] = self._detector.events

    def _check_sizes(self, r: int, m: int) -> None:
        ModelFilter._check_sizes(self, r, m)      # 3 torques, the layout's outputs
        super()._check_sizes(r, m)

    #: Health messages name the channels by the layout (``rate[1]``, not ``y[4]``).
    _output_names = ModelFilter._output_names

    def _allocate(self, r: int, m: int) -> None:
        super()._allocate(r, m)
        # the VARX carries the rigid regressors in front of the past window
        floor = (self.regularization / (1.0 - self.varx_forgetting)
                 if self.regularization > 0 and self.varx_forgetting < 1.0 else None)
        # the past window: every torque, the outputs that see no rigid body, the rates'
        # first differences; an attitude or rate *level* there lets the predictor absorb
        # the gain's error (docs/design/identification.md)
        rigid_rows = np.concatenate((self.layout.indices("attitude"),
                                     self.layout.indices("rate")))
        kept = np.ones(r + m, dtype=bool)
        kept[r + rigid_rows] = False
        self._window = np.flatnonzero(np.tile(kept, self.p))
        self._rigid_rows = rigid_rows
        self._rate_rows = self.layout.indices("rate")
        self._dwin = np.zeros(self.p * self._rate_rows.size)
        self._w_last = np.zeros(self._rate_rows.size)
        self._markov_full = np.zeros((m, self.p * (r + m)))
        size = N_RIGID_REGRESSORS + self._window.size + self._dwin.size
        # the floor bounds the rigid coefficients' covariance without pulling them to 0
        # (Tikhonov toward 0 is right for couplings, wrong for a gain known to be non-zero)
        hold = np.arange(size) < N_RIGID_REGRESSORS
        self._varx = RecursiveLeastSquares(m, size, self.varx_forgetting, 1.0 / self.varx_init,
                                           regularization=floor, hold=hold)
        # a vague prior on the initial-condition terms only (a prior pulling them to 0
        # leaks into the gain; measured choices: docs/design/identification.md)
        initial_conditions = np.arange(size) >= N_RIGID_REGRESSORS - 2
        self._varx.set_covariance(self._varx.P + np.diag(
            np.where(initial_conditions, RIGID_PRIOR, 0.0)))
        s = self._user_scales[1]
        self._rigid = RigidBlock(self.layout, self.dt, self.highpass, s)
        self._flex = None if self.flexible == "improved" else FlexiblePart(
            self.flexible, self.n, self.p, self.forgetting, self.layout.indices("deflection"),
            rigid_rows, m, self.warmup, self.dt)
        self._new_signals(m)

    def _new_signals(self, m: int) -> None:
        self._hp_y = HighPass(m, self.highpass)
        self._hp_u = HighPass(3, self.highpass)
        self._kf = KalmanPredictor(self.order, initial_covariance=1.0)

    # ------------------------------------------------------------ streaming
    @property
    def xi(self) -> np.ndarray | None:
        """The VARX's Markov parameters on the flexible past window (normalized)."""
        return None if self._varx is None else self._markov().copy()

    def _markov(self) -> np.ndarray:
        full = self._markov_full
        full[:, self._window] = self._varx.theta[:, N_RIGID_REGRESSORS:
                                                 N_RIGID_REGRESSORS + self._window.size]
        return full

    def _predict_output(self) -> np.ndarray:
        """One-step prediction of the raw normalized output: the regression's
        prediction of the high-passed output minus what the high-pass adds."""
        full = np.concatenate((self._rigid.peek(), self._phi[self._window], self._dwin))
        return self._varx.predict(full) - highpass_offset(self._hp_y)

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        rho = self._rigid.regressor()
        y_f = self._hp_y(y)
        u_f = self._hp_u(u)
        full = np.concatenate((rho, self._phi[self._window], self._dwin))
        if learn:
            err = self._varx.update(full, y_f)          # the a-priori error; None if refused
            if err is not None:
                self._watch(rho, err, y_f)
        # the rigid response removed where physics puts one (attitude and rate)
        w = y_f.copy()
        rows = self._rigid_rows
        w[rows] -= self._varx.theta[rows, :N_RIGID_REGRESSORS] @ rho
        if self._flex is None:
            self._state_step(u_f, w, learn)
        else:
            self._flex.update(u_f, w, learn)
            self._push(u_f, w)                  # this regression's own past window
        d, nr, w_rate = self._dwin, self._rate_rows.size, w[self._rate_rows]
        d[nr:], d[:nr], self._w_last = d[:-nr], w_rate - self._w_last, w_rate
        self._rigid.step(u)
        if self._k >= self.warmup:
            if self._combined is None or self._k % _REFRESH == 0:
                self._combined = self._assemble()
            if self._combined is not None:
                a, b, c, _, _ = self._combined
                self._kf.update(a, b, c, self._process_noise(b), self._noise(), u, y)

    def _watch(self, rho: np.ndarray, err: np.ndarray, y_f: np.ndarray) -> None:
        """Running mean squares of the a-priori errors and the signals, and the change
        test on the rate rows (an alarm discounts the rigid block)."""
        if self._errvar is None:
            self._errvar, self._sigvar = err * err, y_f * y_f
            return
        self._errvar = 0.995 * self._errvar + 0.005 * err * err
        self._sigvar = 0.995 * self._sigvar + 0.005 * y_f * y_f
        if not self.detect_changes:
            return
        rate = self._rate_rows
        variance = resolved_variance(self._errvar[rate], self._sigvar[rate])
        if self._detector.update(rho[3:6], err[rate], variance, sample=self._k) is not None:
            factor = np.ones(self._varx.P.shape[0])
            factor[:N_RIGID_REGRESSORS] = np.sqrt(self.discount)
            self._varx.set_covariance(self._varx.P * np.outer(factor, factor))
            self._rigid.restart_initial_conditions()
            self._kf.inflate(np.diag(np.abs(np.diag(self._kf.P))))

    # ------------------------------------------------------------ the model
    def _noise(self) -> np.ndarray:
        """Measurement noise variances (normalized): the regression's a-priori errors."""
        return np.maximum(np.ones(self.n_outputs) if self._errvar is None else self._errvar, 1e-12)

    def _process_noise(self, b: np.ndarray) -> np.ndarray:
        """Unmodelled torque of ``process_torque`` N m per axis through ``B``."""
        return (self.process_torque / float(np.mean(self._su))) ** 2 * (b @ b.T)

    def _assemble(self) -> tuple[np.ndarray, ...] | None:
        """The combined model ``(A, B, C, D, K)`` (normalized), without ``K``'s update."""
        flex = ImprovedRPBSID._matrices(self) if self._flex is None else self._flex.matrices()
        if flex is None:
            return None
        a_f, b_f, c_f = resonant_part(*flex[:3], self.dt, self.min_mode_hz)
        g = self._rigid.gain(self._varx.theta[:, :N_RIGID_REGRESSORS])
        a_r, b_r, c_r = self._rigid.matrices(g, self.n_outputs)
        mats = (block_diag(a_r, a_f), np.vstack((b_r, b_f)), np.hstack((c_r, c_f)),
                np.zeros((self.n_outputs, self.n_inputs)))
        if not all(np.all(np.isfinite(mat)) for mat in mats):
            return None
        return (*mats, np.zeros((self.order, self.n_outputs)))

    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        if self._k < self.warmup or self._combined is None:
            return None
        a, b, c, d, _ = self._combined
        gain = self._kf.gain
        k = np.zeros((self.order, self.n_outputs)) if gain is None else gain
        return a, b, c, d, k

    def _current_state(self) -> np.ndarray | None:
        if self._kf is None or self._combined is None:
            return None
        return self._kf.x

    @property
    def rigid_states(self) -> tuple[slice, slice] | None:
        """The attitude and rate states (the first six, normalized units)."""
        return slice(0, 3), slice(3, 6)

    def filtered_state(self, y: ArrayLike) -> np.ndarray | None:
        if self._combined is None or self._sy is None:
            return self.state
        y_n = np.asarray(y, dtype=float) / self._sy
        return self._kf.filtered(self._combined[2], self._noise(), y_n)

    @property
    def rigid_gain(self) -> RigidGainEstimate | None:
        """The rigid-body gain ``G = J^-1`` (rad/s^2 per N m) with its calibrated
        covariance, from the rate rows of the regression; None before warm-up."""
        if self._varx is None or self._errvar is None or self._k < self.warmup:
            return None
        return self._rigid.estimate(self._varx.theta, self._varx.P, self._errvar, self._sy,
                                    self._su)

    def restart(self) -> None:
        """Begin a new record (a new episode): the estimates are kept, the signals'
        filters (integrals, high-passes, past windows, Kalman filter) start anew."""
        if self._varx is None:
            return
        self._rigid.restart()
        if self._flex is not None:
            self._flex.restart()
        self._new_signals(self.n_outputs)
        for signal in (self._phi, self._future, self._tau, self._dwin, self._w_last):
            signal[:] = 0.0

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(order={self.order}, p={self.p}, forgetting="
                f"{self.forgetting}, samples={self.n_samples}, skipped={self.n_skipped})")
