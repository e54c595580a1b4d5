"""Online identification that knows the rigid body: a rigid-flexible spacecraft model.

A recursive subspace identifier estimates everything, even what physics
already fixes, and on this plant it scatters the three double integrators
(a Jordan block at ``z = 1``) over ``1 +- 0.002``, which ruins every
long-horizon prediction. :class:`RigidFlexibleIdentifier` uses what is
known and is composed of separate parts, each in its own module:

1. **Kinematics and modal structure** (:mod:`identifiers.core.modal_basis`).
   Attitude integrates rate, and rate integrates torque through the inverse
   inertia ``G = J(t)^-1``; the flexible modes are resonators. Given their
   frequencies every output is *linear* in the unknown gains. A
   displacement sensor (attitude, deflection) sees a mode through its
   coordinate, a velocity sensor (rate) through its rate, and deflections
   see no rigid-body term (:data:`spacecraft_conventions.MEASURES`), so each
   sensor group has its own regression over the regressors physics allows
   it, on high-passed signals that remove the constants and ramps of
   unknown initial conditions.
2. **The gains** (:mod:`identifiers.core.rls`): per sensor group a Kalman filter
   over parameters that drift as random walks (``drift``): the rigid gains
   drift fast (a docking changes them at once, and they are well excited),
   the modal couplings slowly. Unlike per-parameter forgetting (which
   biased the rigid gain by 4-15 % on a constant plant, see
   docs/design/identification.md) this is the exact conditional mean for
   that parameter model, and its covariance, scaled by the measured residual
   variance, is the calibrated uncertainty of the rigid-body gain
   (:class:`identifiers.core.rigid_gain.RigidGainEstimate`, :attr:`rigid_gain`).
3. **The modes** are *found* by a batch search (:mod:`identifiers.modal.modal_discovery`)
   at the end of the warm-up and again, with a back-off, on the longer
   record kept since (modes 2 % apart need hundreds of seconds to
   separate), and *tracked* in between every ``refresh`` samples by variable
   projection on a forgetting window (:class:`identifiers.modal.modal_tracker.ModalTracker`):
   frequencies and damping move a little every second, the filter bank with
   them (its states corrected to first order), without a rebuild.
4. **Changes** (:mod:`identifiers.core.change_detection`): a generalized
   likelihood-ratio test on the rate regression's errors flags an abrupt
   change of the inertia; the rigid gains' covariance is inflated, the
   initial-condition regressors restart and the modal tracker's window
   restarts (only data after the change inform the modes).
5. **The state** (:mod:`identifiers.core.kalman`): a time-varying Kalman filter
   on the current model, with the sensor noise estimated from its
   innovations; its predictor gain is the model's ``K``.

The class is composed of three parts, each in its own module:
:class:`identifiers.modal.modal_regression.ModalRegression` (items
1-4: the modes found, rebuilt on and tracked, the sensor groups'
regressions and the reaction to a change),
:class:`identifiers.core.state_filter.StateFilter` (item 5) and
:class:`identifiers.modal.minimal_model.MinimalModelExport` (the
minimal innovation-form model exported every ``refresh`` samples, order
``n``, state ``[psi (3); omega (3); one complex mode per resonator rank as
2 real states]``, and the estimates it reports); this module holds the
parameters, the lifecycle and the per-sample step.

The design, the choices and their measured effect:
``docs/design/identification.md``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.change_detection import RESOLUTION, resolved_variance
from identifiers.core.checks import positive_float, positive_int
from identifiers.core.kalman import KalmanPredictor
from identifiers.core.modal_basis import (
    HighPass,
    ModalFilterBank,
    Resonator,
    highpass_noise_gain,
)
from identifiers.core.online import OnlineIdentifier
from identifiers.core.rls import RecursiveLeastSquares
from identifiers.core.state_filter import StateFilter
from identifiers.modal.minimal_model import MinimalModelExport
from identifiers.modal.modal_regression import ModalRegression
from identifiers.modal.modal_tracker import ModalTracker
from spacecraft_conventions import NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["RESOLUTION", "RigidFlexibleIdentifier"]


class RigidFlexibleIdentifier(ModalRegression, StateFilter, MinimalModelExport,
                              OnlineIdentifier):
    """Online identifier with known rigid-body kinematics and estimated flexible modes.

    Parameters
    ----------
    layout : OutputLayout
        The measured sensor groups, in the order of ``y`` (default: the
        environments' standard attitude, rate and four tip deflections).
        Attitude and rate are required.
    n : int
        Model order: 6 rigid states plus two per flexible mode (default 22:
        eight modes). The order is fixed; capacity for which the data show no
        mode is exported as inert states (zero rows and columns).
    dt : float
        Sample time, s.
    rigid_drift, coupling_drift, initial_drift : float
        Random-walk variance per sample of the rigid-body gains, the modal
        couplings and the initial-condition terms, in units of the output
        noise variance (unit-RMS regressors): how fast each may change (see
        :class:`identifiers.core.rls.RecursiveLeastSquares`, ``drift``). The rigid
        gains change at once at a docking and through the paddles' geometry;
        the couplings turn with the paddles. Default couplings' drift 1e-4
        (1e-7 until 2026-11-29, which held them fixed while the paddles turned:
        on paddle rotation the 10 s deflection VAF fell as the data got cleaner;
        ``docs/results/identification.md``). See also ``drift_reference``.
    drift_reference : float or None
        Opt-in: the sensor-noise variance (units of the nominal levels
        squared; 1e-4 is 40 dB of them) at which the drifts are stated. A
        drift in units of the noise allows less change per sample the cleaner
        the data, while the plant changes as fast whatever its sensors; with a
        reference, every ``refresh`` samples each sensor group's drifts are
        multiplied by ``max(1, drift_reference / v)``, ``v`` the mean square
        of its regression's a-priori errors over the high-pass's noise gain
        (noise and misfit: what the regression cannot explain), at least
        ``RESOLUTION**2`` (so at most 100x at 1e-4; :attr:`drift_scales`).
        Noisier data keep the stated drifts. It makes the rigid gain's 2-sigma
        region cover the truth at 60 dB and noise-free (74-98 % of samples
        against 3-56 %) at the price of a noisier gain on a constant plant
        (``docs/results/identification.md``). Default None: drifts in units
        of the noise at every level.
    warmup : int
        Samples collected before the modes are found and a model is given
        (default 500: 50 s at dt = 0.1 s).
    prior : sequence of Resonator, optional
        Flexible modes of a nominal structural model (frequencies, damping);
        near-coincident ones are merged. They are used from the end of the
        warm-up until the first search of the data (``rediscover``) finds
        others; with ``rediscover=None`` they are kept. Default: found from
        the warm-up data by a batch PBSID.
    highpass : float
        Pole ``rho`` of the high-pass that removes constants and ramps.
    detect_changes : bool
        Run the change detector and react to its alarms.
    change_threshold : float
        Alarm level of the change test, a multiple of its degrees of freedom
        (see :class:`identifiers.core.change_detection.RegressionGLR`).
    discount : float
        Factor by which the covariance of the gains grows at a detected
        change (old information discounted that much).
    process_torque : float
        Standard deviation (N m) of the unmodelled torque the Kalman filter
        assumes per axis: a stand-in for everything the model gets wrong, so
        large (default 10) that the filter follows the sensors wherever the
        model and they disagree. Measured on docking at 40 dB, 0.05 -> 10
        raised the one-step rate VAF from 98.2 to 99.8 % (persistence: 99.9)
        and the 10 s deflection VAF from 81 to 91 %.
    refresh : int
        Samples between exports of the minimal model and between refinements
        of the modes (the Kalman filter runs every sample).
    track_modes : bool
        Track the modal frequencies and damping every ``refresh`` samples
        (:class:`identifiers.modal.modal_tracker.ModalTracker`).
    tracking_memory : float
        Forgetting of the tracker's window (default 0.998: 50 s).
    rediscover : int or None
        Samples from the end of the warm-up to the next search for the modes
        in the longer record kept since; every later search waits twice as
        long (back-off: 50, 100, 200 s, ...), the record being longer each
        time. Close modes that 50 s cannot separate are resolved as data
        accumulate; when the number of modes found or their ranks differ, or
        a frequency by more than 2 % from the tracked one, the estimator is
        rebuilt on them and the kept record is replayed; the rebuild is undone
        if its model predicts the last 50 s 10 s ahead clearly worse than the
        model in use (``n_searches_rejected``). None keeps the warm-up's modes.
    history : int
        Most recent samples kept for the searches (default 3000: 300 s).
    outlier_threshold : float, optional
        Reject samples whose normalized innovation exceeds this on any
        channel (default 100).
    input_scale, output_scale : array_like, optional
        Normalization; default the nominal levels of ``layout`` and 1 N m.
    max_abs : float
        See :class:`identifiers.core.online.OnlineIdentifier`.

    Attributes
    ----------
    resonators : tuple of Resonator
        The flexible modes in use (after warm-up).
    events : list of ChangeEvent
        Changes detected so far.
    n_rediscoveries : int
        Times a search found other modes and the estimator was rebuilt on them.
    n_searches_rejected : int
        Times a search found other modes whose model predicted the last 50 s
        10 s ahead clearly worse than the model in use (the rebuild on them was
        undone; :meth:`identifiers.modal.record_replay.RecordReplay._try_modes`).
    """

    # the filter bank and high-passes run on the signals (kept current by a rollback);
    # the recorded samples are tuples of arrays that are never changed in place
    _SIGNAL_STATE = ("_phi", "_bank", "_hp_x", "_hp_y", "_hp_dq", "_hp_dfree")
    _SHARED_ITEMS = ("_pending", "_buffer", "_history")

    def __init__(self, layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22,
                 dt: float = 0.1, rigid_drift: float = 3e-5, coupling_drift: float = 1e-4,
                 initial_drift: float = 1e-5, warmup: int = 500,
                 prior: Sequence[Resonator] | None = None, highpass: float = 0.97,
                 detect_changes: bool = True, change_threshold: float = 6.0,
                 drift_reference: float | None = None, discount: float = 10.0,
                 process_torque: float = 10.0, refresh: int = 10,
                 track_modes: bool = True, tracking_memory: float = 0.998,
                 rediscover: int | None = 500, history: int = 3000,
                 outlier_threshold: float | None = 100.0,
                 input_scale: ArrayLike | None = None, output_scale: ArrayLike | None = None,
                 max_abs: float = 1e6) -> None:
        if not isinstance(layout, OutputLayout):
            raise TypeError(f"layout must be an OutputLayout, got {type(layout).__name__}")
        self.layout = layout.sensors()
        missing = [g for g in ("attitude", "rate") if g not in self.layout]
        if missing:
            raise ValueError(f"the rigid-flexible identifier needs the sensor groups {missing}; "
                             f"the layout holds {self.layout.names}")
        self._att_rows = self.layout.slice("attitude")
        self._rate_rows = self.layout.slice("rate")
        n = positive_int("n", n)
        if n < 6 or n % 2:
            raise ValueError(f"n must be an even order >= 6 (6 rigid states), got {n}")
        self.prior = None if prior is None else tuple(prior)
        if self.prior is not None and not all(isinstance(r, Resonator) for r in self.prior):
            raise TypeError("prior must be a sequence of Resonator")
        if not 0 <= highpass < 1:
            raise ValueError(f"highpass must be in [0, 1), got {highpass}")
        self.highpass = float(highpass)
        self.detect_changes = bool(detect_changes)
        self.change_threshold = positive_float("change_threshold", change_threshold)
        self.discount = positive_float("discount", discount)
        self.process_torque = positive_float("process_torque", process_torque)
        self.refresh = positive_int("refresh", refresh)
        for name, value in (("rigid_drift", rigid_drift), ("coupling_drift", coupling_drift),
                            ("initial_drift", initial_drift)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be >= 0, got {value}")
        self.rigid_drift = float(rigid_drift)
        self.coupling_drift = float(coupling_drift)
        self.initial_drift = float(initial_drift)
        self.drift_reference = (None if drift_reference is None
                                else positive_float("drift_reference", drift_reference))
        self.track_modes = bool(track_modes)
        if not 0 < tracking_memory < 1:
            raise ValueError(f"tracking_memory must be in (0, 1), got {tracking_memory}")
        self.tracking_memory = float(tracking_memory)
        self.rediscover = None if rediscover is None else positive_int("rediscover", rediscover)
        self.history = positive_int("history", history)
        self.outlier_threshold = (None if outlier_threshold is None
                                  else positive_float("outlier_threshold", outlier_threshold))
        scales = (np.full(3, NOMINAL_TORQUE) if input_scale is None else input_scale,
                  self.layout.scales() if output_scale is None else output_scale)
        warmup = positive_int("warmup", warmup)
        super().__init__(n, 2, 1.0, dt=dt, warmup=max(warmup, 100),
                         input_scale=scales[0], output_scale=scales[1], max_abs=max_abs)
        self._noise_gain = highpass_noise_gain(self.highpass)

    # ------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        super().reset()
        self.resonators: tuple[Resonator, ...] = ()
        self._bank: ModalFilterBank | None = None
        self._buffer: list[tuple[np.ndarray, np.ndarray, bool, bool]] = []
        self._fits: list[tuple[np.ndarray, np.ndarray, RecursiveLeastSquares]] = []
        self._drift_scales: list[float] | None = None
        self._kf = self._detector = None
        self._r: np.ndarray | None = None
        self._history: deque[tuple[np.ndarray, np.ndarray, bool, bool]] = deque(
            maxlen=self.history)
        self._next_discovery = 0
        self._search_interval = self.rediscover or 0
        self._tracker: ModalTracker | None = None
        self.n_rediscoveries = 0
        self.n_searches_rejected = 0
        self._mats = None
        self._torque_noise: tuple = (None, None, None)
        self._phases: dict[tuple[int, int], np.ndarray] = {}
        self._resvar: np.ndarray | None = None
        self._sigvar: np.ndarray | None = None
        self._errlag: np.ndarray | None = None          # the errors' lag-1 products
        self._last_err: np.ndarray | None = None
        self._noise_var: np.ndarray | None = None
        self._last_innovation: np.ndarray | None = None
        self._real = True
        self._seen: np.ndarray | None = None

    def restart(self) -> None:
        """Begin a new record of the same plant family (a new episode), keeping what was learnt.

        Kept: the modes, every gain estimate with its covariance, the
        regressor scales, the sensor-noise estimate, the change test's
        calibration and the exported model, so the model is available from
        the first sample of the new record. Restarted: the filter bank and
        the high-passes (the old record's torques do not act on the new
        one), the Kalman filter (state unknown: ``x = 0``, ``P = P_0``), the
        record kept for the mode searches (a search over the junction would
        see a jump) and the next search's time. The rigid-body gains'
        covariance is discounted as at a detected change (the plant may have
        changed between records, e.g. randomized episodes).

        Before the warm-up has ended there is nothing to keep but the
        warm-up samples; they are kept, so the warm-up can span short
        records.
        """
        if self._bank is None:
            return
        self._new_signal_state()
        self._discount_rigid()
        self._detector.restart()
        self._history.clear()
        self._last_innovation = self._last_err = None
        self._next_discovery = self._k + (self.rediscover or 0)
        self._quiet = self.p

    def _new_signal_state(self) -> None:
        """Fresh filter bank (on the current resonators), high-passes and Kalman
        filter: everything that describes the signals of one record."""
        self._bank = ModalFilterBank(self.resonators, self.dt, self._ratio,
                                     sensitivities=self.track_modes)
        self._hp_x = HighPass(self._bank.size, self.highpass)
        self._hp_y = HighPass(self.n_outputs, self.highpass)
        n_res = len(self.resonators)
        self._hp_dq = HighPass(12 * n_res, self.highpass)
        self._hp_dfree = HighPass(4 * n_res, self.highpass)
        self._kf = KalmanPredictor(self.n, initial_covariance=1.0)

    def _memory(self) -> float:
        # the modal tracker forgets; the rigid gains do not (without rigid_drift)
        return 1.0 / (1.0 - self.tracking_memory) if self.track_modes else np.inf

    def _allocate(self, r: int, m: int) -> None:
        s = self.layout.scales() if self._user_scales[1] is None else self._user_scales[1]
        self._ratio = float(np.mean(s[self._rate_rows]) / np.mean(s[self._att_rows]))

    # ------------------------------------------------------------ streaming
    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        if self._bank is None:
            self._buffer.append((u, y, learn, self._real))
            if len(self._buffer) >= self.warmup:
                self._start()
            return
        self._sample(u, y, learn, self._real, seen=self._seen)

    def _sample(self, u: np.ndarray, y: np.ndarray, learn: bool, real: bool,
                replay_k: int | None = None, filtering: bool = True,
                signals: tuple | None = None, seen: np.ndarray | None = None) -> None:
        """One sample: Kalman filter on the current model (if ``filtering``), the
        gains' regressions, the change test (live samples only), the modal tracker,
        the filter bank, and an export and a modal refinement every ``refresh``
        samples (if ``filtering``). A replay passes the sample's ``signals``: the
        scaled high-passed regressor, the high-passed outputs and the scaled
        sensitivities (or None), computed when the bank was rebuilt (the bank and the
        high-passes have then already run past it)."""
        k = self._k if replay_k is None else replay_k
        bank = self._bank
        if signals is None:
            phi, sensitivity = self._signals()
            y_f = self._hp_y(y)
        else:
            phi, y_f, sensitivity = signals
        if filtering and self._mats is not None:
            self._filter_step(u, y, real, seen)
        if learn and real:
            err = self._learn(phi, y_f)
            if (err is not None and self.detect_changes and replay_k is None
                    and self._resvar is not None):
                rate = self._rate_rows                 # a change of inertia shows here
                # on noise-free data the a-priori error is all slow model error
                variance = resolved_variance(self._resvar[rate], self._sigvar[rate])
                event = self._detector.update(phi[bank.slices["rate"]], err[rate], variance,
                                              sample=k)
                if event is not None:
                    self._react(event)
            if err is not None:
                self._track_levels(err, y_f)
                if self._last_innovation is None:       # before the filter runs
                    self._r = np.maximum(self._resvar / self._noise_gain, 1e-12)
            if self._tracker is not None and sensitivity is not None:
                self._tracker.update(phi, sensitivity[0], sensitivity[1], y_f)
        if signals is None:
            bank.step(u)
        if replay_k is None and (k + 1) % self.refresh == 0:
            self._scale_drifts()
            self._refine_modes()
        if filtering and ((k + 1) % self.refresh == 0 or self._mats is None):
            self._export()
        if replay_k is None:
            self._history.append((u, y, learn, real))
            self._maybe_rediscover()

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n={self.n}, "
                f"modes={[round(r.frequency_hz, 4) for r in self.resonators]}, "
                f"samples={self.n_samples}, skipped={self.n_skipped}, events={len(self.events)})")
