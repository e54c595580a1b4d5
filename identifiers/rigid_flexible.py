"""Online identification that knows the rigid body: a rigid-flexible spacecraft model.

A recursive subspace identifier estimates everything, even what physics
already fixes, and on this plant it scatters the three double integrators
(a Jordan block at ``z = 1``) over ``1 +- 0.002``, which ruins every
long-horizon prediction. :class:`RigidFlexibleIdentifier` uses what is
known:

1. **Kinematics.** Attitude integrates rate, and rate integrates torque
   through the inverse inertia: exact ZOH double integrators per axis with
   an unknown gain ``G = J(t)^-1``.
2. **Modal structure.** The flexible modes are resonators whose frequencies
   are found from data (:mod:`identifiers.modal_discovery`) or given as a
   prior. Given the frequencies, every output is *linear* in the unknown
   gains (:mod:`identifiers.modal_basis`). A displacement sensor (attitude,
   deflection) sees a mode through its coordinate and a velocity sensor
   (rate) through its rate, and deflections see no rigid-body term
   (:data:`spacecraft_conventions.MEASURES`), so each sensor group has its
   own recursive least squares over the regressors physics allows it
   (:class:`~identifiers.rls.RecursiveLeastSquares`, on high-passed signals
   that remove the constants and ramps of unknown initial conditions). The
   rigid gains forget faster than the modal couplings (vector forgetting).
3. **Modes are resolved by long records.** Modes 2 % apart need hundreds of
   seconds to separate. The warm-up's modes are a start; every 50 s the
   search is run again on the record kept so far (up to 300 s), and when
   the modes found have moved, the estimator is rebuilt on them and the
   record replayed.
4. **Changes are abrupt.** A docking shows in the rate regression's
   errors. A generalized likelihood-ratio test
   (:mod:`identifiers.change_detection`) flags it; the covariance of the
   rigid gains is inflated and the initial-condition regressors restart.
   Events are exposed in :attr:`~RigidFlexibleIdentifier.events`.

Model exported at every sample (innovation form, order ``n``): the state is
``[psi (3); omega (3); one complex mode per resonator rank as 2 real
states]``; each resonator's couplings are factored into input and output
vectors by a complex SVD (exact for a non-classically damped mode, whose
residue is complex rank one), with input vectors of unit norm and their
phase aligned from one export to the next so the state keeps its meaning
(until the modes are rebuilt). The state estimate is a time-varying Kalman
filter (:class:`~identifiers.kalman.KalmanPredictor`) on the current
model, with the sensor noise estimated from its innovations; its predictor
gain is the model's ``K``.

The design, the choices and their measured effect are in
``docs/design/identification.md``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identifiers.base import OnlineIdentifier, _positive_float, _positive_int
from identifiers.change_detection import ChangeEvent, RegressionGLR
from identifiers.kalman import KalmanPredictor
from identifiers.modal_basis import HighPass, ModalFilterBank, Resonator
from identifiers.modal_discovery import discover_resonators, merge_resonators
from identifiers.rls import RecursiveLeastSquares
from spacecraft_conventions import MEASURES, NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["ATTITUDE_STATES", "FILTER_TAIL", "FLEXIBLE_FLOOR", "RATE_STATES", "RESOLUTION",
           "RigidFlexibleIdentifier"]

#: States of the exported model that are the attitude (its first three) and
#: the body rate (the next three); the flexible modes follow.
ATTITUDE_STATES = slice(0, 3)
RATE_STATES = slice(3, 6)

#: Tikhonov floor of the flexible couplings (unit-RMS regressors): the
#: information a coupling keeps when the data stop exciting it.
FLEXIBLE_FLOOR = 1e-2
#: Samples at the end of a replay over which the Kalman filter runs (the gains
#: learn from the whole replay): its state settles within a few hundred.
FILTER_TAIL = 300
#: Smallest relative error (of the high-passed signal's RMS) the change test
#: treats as evidence: 1e-3, a 60 dB signal-to-error ratio.
RESOLUTION = 1e-3


def _spend_rank(resonators: list[Resonator], budget: int) -> list[Resonator]:
    """Give unused modal capacity to the strongest resonators (up to rank 2 each).

    A discovered resonator may stand for two modes closer than the warm-up
    record resolves (the antenna pair at 0.0894 and 0.0900 Hz): a second
    rank lets the export represent both. Resonators are listed by frequency;
    the strongest are assumed to be the lowest-frequency ones here.
    """
    spare = budget - sum(r.rank for r in resonators)
    out = []
    for r in resonators:
        extra = min(spare, 2 - r.rank) if r.rank < 2 else 0
        spare -= max(extra, 0)
        out.append(Resonator(r.frequency_hz, r.damping, r.rank + max(extra, 0)))
    return out


def _same_modes(a: Sequence[Resonator], b: Sequence[Resonator],
                tolerance: float = 0.005) -> bool:
    """Same number of resonators, same ranks, frequencies within ``tolerance`` (relative)."""
    if len(a) != len(b):
        return False
    return all(x.rank == y.rank and abs(x.frequency_hz / y.frequency_hz - 1.0) <= tolerance
               for x, y in zip(a, b, strict=True))


def _highpass_noise_gain(rho: float) -> float:
    """Sum of the squared impulse response of ``((1 - z^-1) / (1 - rho z^-1))^2``."""
    hp = HighPass(1, rho)
    impulse = np.zeros(4000)
    impulse[0] = 1.0
    return float(sum(hp(np.array([x]))[0] ** 2 for x in impulse))


class RigidFlexibleIdentifier(OnlineIdentifier):
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
    forgetting : float
        Forgetting of the gain estimates (memory ``1 / (1 - forgetting)``
        samples; default 0.998: 50 s).
    rigid_forgetting : float
        Forgetting of the rigid-body gains ``G`` (default 0.99: a 10 s
        memory): they change at once at a docking, and three well-excited
        gains per axis need little data. See
        :class:`~identifiers.rls.RecursiveLeastSquares` (vector forgetting).
    rigid_floor : float
        Information floor of the rigid gains (unit-RMS regressors): it bounds
        their covariance when the data stop exciting them (in regulation)
        without pulling them toward 0.
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
        (see :class:`~identifiers.change_detection.RegressionGLR`).
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
        Samples between exports of the minimal model (the Kalman filter
        runs every sample).
    rediscover : int or None
        Samples between searches for the modes in the longer record kept
        since warm-up or the last detected change (default 500: 50 s). Close
        modes that 50 s cannot separate are resolved as data accumulate; when
        the modes found differ (frequency by more than 0.5 %, or their
        number), the estimator is rebuilt on them and the kept record is
        replayed (a cost of about a millisecond per kept sample, paid once).
        None keeps the warm-up's modes.
    history : int
        Most recent samples kept for the searches (default 3000: 300 s).
    gate : float or None
        Excitation-gated forgetting of the gains (see
        :class:`~identifiers.rls.RecursiveLeastSquares`): a sample forgets
        only in proportion to how informative it is, relative to ``gate``
        times the typical sample that set the estimate (default 0.25). In a
        closed loop that holds the spacecraft still the estimates then keep
        what they learnt instead of drifting with the sensor noise. None:
        plain forgetting.
    outlier_threshold : float, optional
        Reject samples whose normalized innovation exceeds this on any
        channel (default 100).
    input_scale, output_scale : array_like, optional
        Normalization; default the nominal levels of ``layout`` and 1 N m.
    max_abs : float
        See :class:`~identifiers.base.OnlineIdentifier`.

    Attributes
    ----------
    resonators : tuple of Resonator
        The flexible modes in use (after warm-up).
    events : list of ChangeEvent
        Changes detected so far.
    n_rediscoveries : int
        Times the modes were found to have moved and the estimator rebuilt.
    """

    # the filter bank and high-passes run on the signals (kept current by a rollback);
    # the recorded samples are tuples of arrays that are never changed in place
    _SIGNAL_STATE = ("_phi", "_bank", "_hp_x", "_hp_y")
    _SHARED_ITEMS = ("_pending", "_buffer", "_history")

    def __init__(self, layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22,
                 dt: float = 0.1, forgetting: float = 0.998, rigid_forgetting: float = 0.995,
                 rigid_floor: float = 1e-4, warmup: int = 500,
                 prior: Sequence[Resonator] | None = None, highpass: float = 0.97,
                 detect_changes: bool = True, change_threshold: float = 6.0,
                 discount: float = 10.0, process_torque: float = 10.0, refresh: int = 10,
                 rediscover: int | None = 500, history: int = 3000,
                 gate: float | None = 0.25,
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
        n = _positive_int("n", n)
        if n < 6 or n % 2:
            raise ValueError(f"n must be an even order >= 6 (6 rigid states), got {n}")
        self.prior = None if prior is None else tuple(prior)
        if self.prior is not None and not all(isinstance(r, Resonator) for r in self.prior):
            raise TypeError("prior must be a sequence of Resonator")
        if not 0 <= highpass < 1:
            raise ValueError(f"highpass must be in [0, 1), got {highpass}")
        self.highpass = float(highpass)
        self.detect_changes = bool(detect_changes)
        self.change_threshold = _positive_float("change_threshold", change_threshold)
        self.discount = _positive_float("discount", discount)
        self.process_torque = _positive_float("process_torque", process_torque)
        self.refresh = _positive_int("refresh", refresh)
        if not 0 < rigid_forgetting <= 1:
            raise ValueError(f"rigid_forgetting must be in (0, 1], got {rigid_forgetting}")
        self.rigid_forgetting = float(rigid_forgetting)
        if not (np.isfinite(rigid_floor) and rigid_floor >= 0):
            raise ValueError(f"rigid_floor must be >= 0, got {rigid_floor}")
        self.rigid_floor = float(rigid_floor)
        self.rediscover = None if rediscover is None else _positive_int("rediscover", rediscover)
        self.history = _positive_int("history", history)
        if gate is not None and not (np.isfinite(gate) and gate > 0):
            raise ValueError(f"gate must be a positive fraction or None, got {gate}")
        self.gate = None if gate is None else float(gate)
        self.outlier_threshold = (None if outlier_threshold is None
                                  else _positive_float("outlier_threshold", outlier_threshold))
        scales = (np.full(3, NOMINAL_TORQUE) if input_scale is None else input_scale,
                  self.layout.scales() if output_scale is None else output_scale)
        warmup = _positive_int("warmup", warmup)
        super().__init__(n, 2, forgetting, dt=dt, warmup=max(warmup, 100),
                         input_scale=scales[0], output_scale=scales[1], max_abs=max_abs)
        self._noise_gain = _highpass_noise_gain(self.highpass)

    # ------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        super().reset()
        self.resonators: tuple[Resonator, ...] = ()
        self._bank: ModalFilterBank | None = None
        self._buffer: list[tuple[np.ndarray, np.ndarray, bool, bool]] = []
        self._fits: list[tuple[np.ndarray, np.ndarray, RecursiveLeastSquares]] = []
        self._kf = self._detector = None
        self._r: np.ndarray | None = None
        self._history: deque[tuple[np.ndarray, np.ndarray, bool, bool]] = deque(
            maxlen=self.history)
        self._next_discovery = 0
        self.n_rediscoveries = 0
        self._mats = None
        self._torque_noise: tuple = (None, None)
        self._phases: dict[tuple[int, int], np.ndarray] = {}
        self._resvar: np.ndarray | None = None
        self._sigvar: np.ndarray | None = None
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
        self._last_innovation = None
        self._next_discovery = self._k + (self.rediscover or 0)
        self._quiet = self.p

    def _new_signal_state(self) -> None:
        """Fresh filter bank (on the current resonators), high-passes and Kalman
        filter: everything that describes the signals of one record."""
        self._bank = ModalFilterBank(self.resonators, self.dt, self._ratio)
        self._hp_x = HighPass(self._bank.size, self.highpass)
        self._hp_y = HighPass(self.n_outputs, self.highpass)
        self._kf = KalmanPredictor(self.n, initial_covariance=1.0)

    def _check_sizes(self, r: int, m: int) -> None:
        if r != 3:
            raise ValueError(f"u must hold the 3 body torques, got {r} inputs")
        if m != self.layout.size:
            raise ValueError(f"y must have {self.layout.size} entries as the layout "
                             f"{self.layout.names} says, got {m}")

    def _allocate(self, r: int, m: int) -> None:
        s = self.layout.scales() if self._user_scales[1] is None else self._user_scales[1]
        rate, att = self.layout.slice("rate"), self.layout.slice("attitude")
        self._ratio = float(np.mean(s[rate]) / np.mean(s[att]))

    def _process(self, u: np.ndarray, y: np.ndarray) -> None:
        # the base class replaces unusable samples by a stand-in and calls _step with
        # learn=False; remember whether this sample's y was real for the Kalman filter
        self._seen = np.isfinite(y)
        self._real = bool(self._seen.all())
        super()._process(u, y)

    def _admissible(self, u: np.ndarray, y: np.ndarray) -> bool | np.ndarray:
        kf = self._kf
        if self.outlier_threshold is None or kf is None or self._mats is None:
            return True
        c = self._mats[2]
        spread = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", c, kf.P, c) + self._r, 1e-30))
        inside = np.abs(y - c @ kf.x) <= self.outlier_threshold * spread
        if not inside.all():
            # the base class counts it in n_outliers; the filter still uses the other outputs
            self._real = False
            self._seen = self._seen & inside
            return inside
        return True

    def _accept_outlier_run(self, u: np.ndarray, y: np.ndarray) -> None:
        self._real = True           # learned from after all: the filter uses it too
        self._seen = np.ones(self.n_outputs, dtype=bool)

    def _state_vector(self) -> np.ndarray | None:
        return None if self._kf is None else self._kf.x

    def _after_rollback(self) -> None:
        # the restored filter state is up to a check period old: let it re-converge
        if self._kf is not None:
            self._kf.inflate(np.diag(np.abs(np.diag(self._kf.P))) + 1e-3 * np.eye(self.n))

    def _fill_output(self) -> np.ndarray:
        if self._kf is None or self._mats is None:
            return np.zeros(self.n_outputs)
        return self._mats[2] @ self._kf.x

    # ------------------------------------------------------------ streaming
    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        if self._bank is None:
            self._buffer.append((u, y, learn, self._real))
            if len(self._buffer) >= self.warmup:
                self._start()
            return
        self._sample(u, y, learn, self._real, seen=self._seen)

    def _start(self) -> None:
        """End of warm-up: find the modes, build the estimator, replay the buffer."""
        buffer, self._buffer = self._buffer, []
        self._history.extend(buffer)
        budget = (self.n - 6) // 2
        if self.prior is not None:
            start = merge_resonators([r.frequency_hz for r in self.prior],
                                     [r.damping for r in self.prior], budget=budget)
        else:
            start = self._find_resonators()
        self._rebuild(start, len(buffer))

    def _find_resonators(self) -> list[Resonator]:
        """The flexible modes the kept history shows."""
        budget = (self.n - 6) // 2
        if not budget:
            return []
        u = np.array([h[0] for h in self._history])
        y = np.array([h[1] for h in self._history])
        real = np.array([h[3] for h in self._history])      # samples whose y was real
        cols = np.concatenate([self.layout.indices(g) for g in ("rate", "deflection")
                               if g in self.layout])
        y = y[:, cols]
        # a skipped sample's stand-in is the filter's prediction (kept: off by about the
        # noise; dropping the sample would join the record across a jump), or zeros before
        # there was a model: those are interpolated from their neighbours
        filled = ~real & ~np.any(y, axis=1)
        if filled.any():
            if filled.all() or (~filled).sum() < 2:
                return list(self.resonators)
            k, seen = np.arange(len(real)), np.flatnonzero(~filled)
            y = np.column_stack([np.interp(k, seen, col[seen]) for col in y.T])
        try:
            found = discover_resonators(u, y, budget, self.dt)
        except (ValueError, np.linalg.LinAlgError):     # too short or degenerate a record
            return list(self.resonators)
        return _spend_rank(found, budget)

    def _rebuild(self, resonators: list[Resonator], replay: int) -> None:
        """Build the estimator on ``resonators`` and replay the last ``replay`` samples."""
        self.resonators = tuple(resonators)
        self._new_signal_state()
        size = self._bank.size
        m = self.n_outputs
        samples = list(self._history)[-replay:]
        # the high-passed regressors of the replayed samples, computed once: they set
        # the regressor scales (unit-RMS columns) and are then replayed as they are,
        # leaving the bank and its high-pass where the replay ends
        rows = []
        for uk, *_ in samples:
            rows.append(self._hp_x(self._bank.regressor()))
            self._bank.step(uk)
        scale = np.sqrt(np.mean(np.array(rows) ** 2, axis=0))
        scale[self._bank.slices["free"]] = 1.0
        scale[self._bank.slices["step"]] = 1.0
        scale[self._bank.slices["ramp"]] = self.dt
        self._scale = np.where(scale > 0, scale, 1.0)
        # Tikhonov floors: the flexible couplings are many and weakly excited (noise
        # would be fitted there); the rigid gains and the initial-condition terms
        # are few, well excited, and a floor would bias them through their
        # collinearity during transients
        floor = np.full(size, 1e-4)
        floor[self._bank.slices["flexible"]] = FLEXIBLE_FLOOR
        lam = np.full(size, self.forgetting)
        hold = np.zeros(size, dtype=bool)
        for block in ("attitude", "rate"):          # the rigid gains
            rigid = self._bank.slices[block]
            floor[rigid] = self.rigid_floor
            # they forget faster than the rest: a docking changes them at once, and
            # three well-excited gains per axis need little memory
            lam[rigid] = self.rigid_forgetting
            # they are never 0: their floor bounds P but does not pull them
            hold[rigid] = True
        self._fits = [(rows, cols, RecursiveLeastSquares(rows.size, cols.size, lam[cols],
                                                         1e4, regularization=floor[cols],
                                                         hold=hold[cols], gate=self.gate))
                      for rows, cols in self._regression_groups()]
        if self._detector is None:
            self._detector = RegressionGLR(threshold=self.change_threshold, dt=self.dt)
        else:
            self._detector.restart()
        if self._r is None:
            self._r = np.full(m, 1e-4)
        self._mats = None
        self._phases = {}
        # replay: the gains learn from every sample; the Kalman filter (and the
        # exports it needs) only over the last FILTER_TAIL, enough for its state
        # to settle on the new model
        start_k = self._k - len(samples) + 1
        tail = len(samples) - min(len(samples), FILTER_TAIL)
        for j, (uk, yk, learn, real) in enumerate(samples):
            self._sample(uk, yk, learn, real, replay_k=start_k + j, filtering=j >= tail,
                         regressor=rows[j])
        self._next_discovery = self._k + 1 + (self.rediscover or 0)

    def _maybe_rediscover(self) -> None:
        """Look for the modes again in the longer history; rebuild if they moved."""
        if (not self.rediscover or self._k + 1 < self._next_discovery
                or len(self._history) < self.warmup):
            return
        self._next_discovery = self._k + 1 + self.rediscover
        found = self._find_resonators()
        if _same_modes(found, self.resonators):
            return
        self.n_rediscoveries += 1
        # replay three memories of the couplings: older samples would carry no weight
        self._rebuild(found, min(len(self._history), round(3.0 / (1.0 - self.forgetting))))

    def _sample(self, u: np.ndarray, y: np.ndarray, learn: bool, real: bool,
                replay_k: int | None = None, filtering: bool = True,
                regressor: np.ndarray | None = None, seen: np.ndarray | None = None) -> None:
        """One sample: Kalman filter on the current model (if ``filtering``), the
        gains' RLS, the change test (live samples only), the filter bank, and an
        export every ``refresh`` samples (if ``filtering``). A replay passes the
        sample's high-passed ``regressor``, computed when the bank was rebuilt
        (the bank has then already run past it)."""
        k = self._k if replay_k is None else replay_k
        bank = self._bank
        if regressor is None:
            phi = self._hp_x(bank.regressor()) / self._scale
        else:
            phi = regressor / self._scale
        y_f = self._hp_y(y)
        if filtering and self._mats is not None:
            a, b, c, _, _ = self._mats
            # the outputs that were measured (all of them, or those a skipped sample kept)
            y_kf = y if real else (None if seen is None else np.where(seen, y, np.nan))
            self._kf.update(a, b, c, self._process_noise(), self._r, u, y_kf)
            innovation = self._kf.innovation
            if real and innovation is not None and np.all(np.isfinite(innovation)):
                self._measurement_noise(innovation)
        if learn and real:
            err = self._learn(phi, y_f)
            if (err is not None and self.detect_changes and replay_k is None
                    and self._resvar is not None):
                rate = self.layout.slice("rate")      # a change of inertia shows here
                # errors below RESOLUTION of the signal are not evidence of a change
                # (on noise-free data the a-priori error is all slow model error)
                variance = np.maximum(self._resvar[rate], RESOLUTION**2 * self._sigvar[rate])
                event = self._detector.update(phi[bank.slices["rate"]], err[rate], variance,
                                              sample=k)
                if event is not None:
                    self._react(event)
            if err is not None:
                e2, s2 = err**2, y_f**2
                if self._resvar is None:
                    self._resvar, self._sigvar = e2, s2
                else:
                    self._resvar = 0.995 * self._resvar + 0.005 * e2
                    self._sigvar = 0.995 * self._sigvar + 0.005 * s2
                if self._last_innovation is None:       # before the filter runs
                    self._r = np.maximum(self._resvar / self._noise_gain, 1e-12)
        if regressor is None:
            bank.step(u)
        if filtering and ((k + 1) % self.refresh == 0 or self._mats is None):
            self._export()
        if replay_k is None:
            self._history.append((u, y, learn, real))
            self._maybe_rediscover()

    def _regression_groups(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Rows of ``y`` and the regressor columns physics allows them, per sensor group.

        A displacement sensor (attitude, deflection) sees a mode through its
        coordinate ``q``, a velocity sensor (rate) through ``q'``; attitude
        integrates the torques twice and rate once through ``G``; deflections
        see no rigid-body term. With proportional damping this is exact, and
        it halves the flexible couplings each output is fitted with.
        """
        bank = self._bank
        idx = np.arange(bank.size)
        flexible = idx[bank.slices["flexible"]].reshape(len(self.resonators), 3, 2)
        initial = np.concatenate([idx[bank.slices[b]] for b in ("free", "step", "ramp")])
        groups = []
        for name, rows in self.layout:
            velocity = MEASURES[name] == "velocity"
            rigid = idx[bank.slices[name]] if name in ("attitude", "rate") else idx[:0]
            cols = np.concatenate((rigid, flexible[:, :, int(velocity)].ravel(), initial))
            groups.append((np.arange(rows.start, rows.stop), cols))
        return groups

    def _learn(self, phi: np.ndarray, y_f: np.ndarray) -> np.ndarray | None:
        """One step of every group's RLS; the a-priori errors, or None if one refused."""
        err = np.empty(self.n_outputs)
        for rows, cols, rls in self._fits:
            e = rls.update(phi[cols], y_f[rows])
            if e is None:
                return None
            err[rows] = e
        return err

    def _theta(self) -> np.ndarray:
        """All groups' estimates as one ``(m, size)`` matrix (zero where excluded)."""
        theta = np.zeros((self.n_outputs, self._bank.size))
        for rows, cols, rls in self._fits:
            theta[np.ix_(rows, cols)] = rls.theta
        return theta

    def _measurement_noise(self, innovation: np.ndarray) -> None:
        """Sensor noise variance from the filter's innovations: white noise shows in
        their first difference (``E[(e_k - e_{k-1})^2] / 2 = R`` for white ``e``),
        slow model error barely does, so the filter keeps trusting the sensors
        where the model is wrong instead of mistaking model error for noise."""
        last = self._last_innovation
        self._last_innovation = innovation
        if last is None:
            return
        d2 = 0.5 * (innovation - last) ** 2
        self._noise_var = d2 if self._noise_var is None else 0.998 * self._noise_var + 0.002 * d2
        self._r = np.maximum(self._noise_var, 1e-12)

    def _process_noise(self) -> np.ndarray:
        """Unmodelled torque through B, plus an attitude random walk at half the noise."""
        if self._torque_noise[0] is not self._mats:      # B changes only at an export
            b = self._mats[1]
            self._torque_noise = (self._mats,
                                  (self.process_torque / self._su.mean()) ** 2 * (b @ b.T))
        q = self._torque_noise[1].copy()
        att = self.layout.slice("attitude")
        q[:3, :3] += np.diag(0.25 * self._r[att])
        return q

    def _react(self, event: ChangeEvent) -> None:
        """A detected change: discount what was learnt of the rigid body before it.

        The covariance of the rigid-body gains and the initial-condition
        terms is multiplied by ``discount`` (as if their old data had been
        forgotten that much faster), the initial-condition regressors restart
        (a docking makes the rates jump: momentum is conserved), and the
        Kalman filter's state uncertainty is doubled. The flexible couplings
        keep their memory: the modes move little at a docking and need long
        records.
        """
        self._discount_rigid()
        self._bank.restart()
        self._kf.inflate(np.diag(np.abs(np.diag(self._kf.P))))

    def _discount_rigid(self) -> None:
        """Multiply the covariance of the rigid gains and initial-condition terms by
        ``discount``."""
        bank = self._bank
        idx = np.arange(bank.size)
        touched = np.concatenate([idx[bank.slices[b]]
                                  for b in ("attitude", "rate", "free", "step", "ramp")])
        for _, cols, rls in self._fits:
            factor = np.where(np.isin(cols, touched), np.sqrt(self.discount), 1.0)
            rls.set_covariance(rls.P * np.outer(factor, factor))

    # ------------------------------------------------------------ the model
    def _export(self) -> None:
        """Minimal innovation-form model from the current gains (normalized units)."""
        theta = self._theta() / self._scale
        bank = self._bank
        att, rate = self.layout.slice("attitude"), self.layout.slice("rate")
        m = self.n_outputs
        order = self.n           # fixed: capacity not used by a resonator stays inert (zero)
        a = np.zeros((order, order))
        b = np.zeros((order, 3))
        c = np.zeros((m, order))
        g = theta[rate, bank.slices["rate"]]                  # normalized inverse inertia
        dt, ratio = self.dt, self._ratio
        psi, omega = ATTITUDE_STATES, RATE_STATES
        a[psi, psi] = np.eye(3)
        a[psi, omega] = dt * ratio * np.eye(3)
        a[omega, omega] = np.eye(3)
        b[psi] = 0.5 * dt * dt * ratio * g
        b[omega] = dt * g
        c[att, psi] = np.eye(3)
        c[rate, omega] = np.eye(3)
        modes_a, modes_b = bank.mode_matrices
        flexible = theta[:, bank.slices["flexible"]].reshape(m, len(self.resonators), 3, 2)
        j = 6
        for i, res in enumerate(self.resonators):
            vals, vecs = np.linalg.eig(modes_a[i])
            top = int(np.argmax(vals.imag))
            mu = vals[top]
            to_complex = vecs[:, top] * np.linalg.solve(vecs, modes_b[i])[top]
            chat = 2.0 * flexible[:, i] @ to_complex                   # (m, 3) complex
            left, sv, right = np.linalg.svd(chat, full_matrices=False)
            for rank in range(res.rank):
                c_vec, b_vec = left[:, rank] * sv[rank], right[rank].copy()
                ref = self._phases.get((i, rank))
                phase = b_vec[np.argmax(np.abs(b_vec))] if ref is None else np.vdot(ref, b_vec)
                phase = phase / abs(phase) if abs(phase) > 0 else 1.0
                b_vec, c_vec = b_vec / phase, c_vec * phase
                self._phases[(i, rank)] = b_vec
                a[j:j + 2, j:j + 2] = [[mu.real, -mu.imag], [mu.imag, mu.real]]
                b[j], b[j + 1] = b_vec.real, b_vec.imag
                c[:, j], c[:, j + 1] = c_vec.real, -c_vec.imag
                j += 2
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(c))):
            return
        self._mats = (a, b, c, np.zeros((m, 3)), None)

    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        if self._mats is None:
            return None
        a, b, c, d, _ = self._mats
        gain = self._kf.gain if self._kf.gain is not None else np.zeros((a.shape[0], c.shape[0]))
        return a, b, c, d, gain

    def _current_state(self) -> np.ndarray | None:
        return None if self._mats is None else self._kf.x

    def input_uncertainty(self) -> np.ndarray | None:
        """Covariance (3, 3) of the rigid gains' torque directions, from the rate
        regression's RLS (larger = less known), for shaping an excitation;
        None before warm-up."""
        if not self._fits:
            return None
        bank = self._bank
        rate_cols = np.arange(bank.size)[bank.slices["rate"]]
        for rows, cols, rls in self._fits:
            if rows[0] == self.layout.slice("rate").start:
                where = np.flatnonzero(np.isin(cols, rate_cols))
                scale = self._scale[rate_cols]
                return rls.P[np.ix_(where, where)] / np.outer(scale, scale)
        return None

    def filtered_state(self, y: ArrayLike) -> np.ndarray | None:
        """``x_{k|k}``: the Kalman filter's prediction corrected by ``y_k`` (physical units)."""
        if not self.ready or self._mats is None:
            return None
        y = np.asarray(y, dtype=float).reshape(-1)
        if y.shape != (self.n_outputs,):
            raise ValueError(f"y must have {self.n_outputs} entries, got shape {y.shape}")
        with np.errstate(invalid="ignore", over="ignore"):
            y_n = y / self._sy
        y_n = np.where(np.abs(y_n) <= self.max_abs, y_n, np.nan)
        return self._kf.filtered(self._mats[2], self._r, y_n)

    @property
    def rigid_states(self) -> tuple[slice, slice]:
        """Slices of the model state that are the attitude and the body rate."""
        return ATTITUDE_STATES, RATE_STATES

    @property
    def events(self) -> list[ChangeEvent]:
        """Changes detected so far (empty before warm-up)."""
        return [] if self._detector is None else list(self._detector.events)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n={self.n}, forgetting={self.forgetting}, "
                f"modes={[round(r.frequency_hz, 4) for r in self.resonators]}, "
                f"samples={self.n_samples}, skipped={self.n_skipped}, events={len(self.events)})")
