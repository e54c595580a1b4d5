"""Online identification that knows the rigid body: a rigid-flexible spacecraft model.

A recursive subspace identifier estimates everything, even what physics
already fixes, and on this plant it scatters the three double integrators
(a Jordan block at ``z = 1``) over ``1 +- 0.002``, which ruins every
long-horizon prediction. :class:`RigidFlexibleIdentifier` uses what is
known and is composed of separate parts, each in its own module:

1. **Kinematics and modal structure** (:mod:`identifiers.modal_basis`).
   Attitude integrates rate, and rate integrates torque through the inverse
   inertia ``G = J(t)^-1``; the flexible modes are resonators. Given their
   frequencies every output is *linear* in the unknown gains. A
   displacement sensor (attitude, deflection) sees a mode through its
   coordinate, a velocity sensor (rate) through its rate, and deflections
   see no rigid-body term (:data:`spacecraft_conventions.MEASURES`), so each
   sensor group has its own regression over the regressors physics allows
   it, on high-passed signals that remove the constants and ramps of
   unknown initial conditions.
2. **The gains** (:mod:`identifiers.rls`): per sensor group a Kalman filter
   over parameters that drift as random walks (``drift``): the rigid gains
   drift fast (a docking changes them at once, and they are well excited),
   the modal couplings slowly. Unlike per-parameter forgetting (which
   biased the rigid gain by 4-15 % on a constant plant, see
   docs/design/identification.md) this is the exact conditional mean for
   that parameter model, and its covariance, scaled by the measured residual
   variance, is the calibrated uncertainty of the rigid-body gain
   (:class:`~identifiers.rigid_gain.RigidGainEstimate`, :attr:`rigid_gain`).
3. **The modes** are *found* by a batch search (:mod:`identifiers.modal_discovery`)
   at the end of the warm-up and again, with a back-off, on the longer
   record kept since (modes 2 % apart need hundreds of seconds to
   separate), and *tracked* in between every ``refresh`` samples by variable
   projection on a forgetting window (:class:`~identifiers.modal_tracker.ModalTracker`):
   frequencies and damping move a little every second, the filter bank with
   them (its states corrected to first order), without a rebuild.
4. **Changes** (:mod:`identifiers.change_detection`): a generalized
   likelihood-ratio test on the rate regression's errors flags an abrupt
   change of the inertia; the rigid gains' covariance is inflated, the
   initial-condition regressors restart and the modal tracker's window
   restarts (only data after the change inform the modes).
5. **The state** (:mod:`identifiers.kalman`): a time-varying Kalman filter
   on the current model, with the sensor noise estimated from its
   innovations; its predictor gain is the model's ``K``.

Model exported every ``refresh`` samples (innovation form, order ``n``):
the state is ``[psi (3); omega (3); one complex mode per resonator rank as 2
real states]``; each resonator's couplings are factored into input and
output vectors by a complex SVD, with input vectors of unit norm and their
phase aligned from one export to the next so the state keeps its meaning.

The design, the choices and their measured effect are in
``docs/design/identification.md``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from identifiers.base import OnlineIdentifier, _positive_float, _positive_int
from identifiers.change_detection import ChangeEvent, RegressionGLR
from identifiers.kalman import KalmanPredictor
from identifiers.modal_basis import HighPass, ModalFilterBank, Resonator
from identifiers.modal_discovery import discover_resonators, merge_resonators
from identifiers.modal_tracker import ModalTracker, TrackerGroup
from identifiers.rigid_gain import RigidGainEstimate
from identifiers.rls import RecursiveLeastSquares
from spacecraft_conventions import MEASURES, NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["ATTITUDE_STATES", "FILTER_TAIL", "FLEXIBLE_FLOOR", "INITIAL_COVARIANCE", "RATE_STATES",
           "REBUILD_TOLERANCE", "REPLAY", "RESOLUTION", "RigidFlexibleIdentifier"]

#: States of the exported model that are the attitude (its first three) and
#: the body rate (the next three); the flexible modes follow.
ATTITUDE_STATES = slice(0, 3)
RATE_STATES = slice(3, 6)
#: The diagonal of the attitude block of the state covariance.
_ATTITUDE_DIAGONAL = np.diag_indices(3)

#: Initial covariance of every gain (unit-RMS regressors, units of the output
#: noise variance): a vague prior.
INITIAL_COVARIANCE = 1e4
#: Information floor of the flexible couplings (unit-RMS regressors): the
#: variance of a coupling the data do not excite settles at its inverse.
FLEXIBLE_FLOOR = 1e-2
#: A search's modes replace the tracked ones only if their number or ranks
#: differ, or a frequency by more than this (relative): smaller moves are the
#: tracker's.
REBUILD_TOLERANCE = 0.02
#: Samples replayed after a rebuild (the last 150 s of the kept record).
REPLAY = 1500
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


@njit(cache=True, nogil=True)
def _mean_square_step(level: np.ndarray, x: np.ndarray, keep: float, weight: float) -> None:
    """``level <- keep * level + weight * x**2`` in place: one step of an exponentially
    weighted mean square (the arithmetic of the NumPy expression)."""
    for i in range(x.shape[0]):
        level[i] = keep * level[i] + weight * (x[i] * x[i])


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
    rigid_drift, coupling_drift, initial_drift : float
        Random-walk variance per sample of the rigid-body gains, the modal
        couplings and the initial-condition terms, in units of the output
        noise variance (unit-RMS regressors): how fast each may change (see
        :class:`~identifiers.rls.RecursiveLeastSquares`, ``drift``). The rigid
        gains change at once at a docking and through the paddles' geometry;
        the couplings change slowly with the mode shapes.
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
        Samples between exports of the minimal model and between refinements
        of the modes (the Kalman filter runs every sample).
    track_modes : bool
        Track the modal frequencies and damping every ``refresh`` samples
        (:class:`~identifiers.modal_tracker.ModalTracker`).
    tracking_memory : float
        Forgetting of the tracker's window (default 0.998: 50 s).
    rediscover : int or None
        Samples from the end of the warm-up to the next search for the modes
        in the longer record kept since; every later search waits twice as
        long (back-off: 50, 100, 200 s, ...), the record being longer each
        time. Close modes that 50 s cannot separate are resolved as data
        accumulate; when the number of modes found or their ranks differ, or
        a frequency by more than 2 % from the tracked one, the estimator is
        rebuilt on them and the kept record is replayed. None keeps the
        warm-up's modes.
    history : int
        Most recent samples kept for the searches (default 3000: 300 s).
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
        Times a search found other modes and the estimator was rebuilt.
    """

    # the filter bank and high-passes run on the signals (kept current by a rollback);
    # the recorded samples are tuples of arrays that are never changed in place
    _SIGNAL_STATE = ("_phi", "_bank", "_hp_x", "_hp_y", "_hp_dq", "_hp_dfree")
    _SHARED_ITEMS = ("_pending", "_buffer", "_history")

    def __init__(self, layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22,
                 dt: float = 0.1, rigid_drift: float = 3e-5, coupling_drift: float = 1e-7,
                 initial_drift: float = 1e-5, warmup: int = 500,
                 prior: Sequence[Resonator] | None = None, highpass: float = 0.97,
                 detect_changes: bool = True, change_threshold: float = 6.0,
                 discount: float = 10.0, process_torque: float = 10.0, refresh: int = 10,
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
        for name, value in (("rigid_drift", rigid_drift), ("coupling_drift", coupling_drift),
                            ("initial_drift", initial_drift)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be >= 0, got {value}")
        self.rigid_drift = float(rigid_drift)
        self.coupling_drift = float(coupling_drift)
        self.initial_drift = float(initial_drift)
        self.track_modes = bool(track_modes)
        if not 0 < tracking_memory < 1:
            raise ValueError(f"tracking_memory must be in (0, 1), got {tracking_memory}")
        self.tracking_memory = float(tracking_memory)
        self.rediscover = None if rediscover is None else _positive_int("rediscover", rediscover)
        self.history = _positive_int("history", history)
        self.outlier_threshold = (None if outlier_threshold is None
                                  else _positive_float("outlier_threshold", outlier_threshold))
        scales = (np.full(3, NOMINAL_TORQUE) if input_scale is None else input_scale,
                  self.layout.scales() if output_scale is None else output_scale)
        warmup = _positive_int("warmup", warmup)
        super().__init__(n, 2, 1.0, dt=dt, warmup=max(warmup, 100),
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
        self._search_interval = self.rediscover or 0
        self._tracker: ModalTracker | None = None
        self.n_rediscoveries = 0
        self._mats = None
        self._torque_noise: tuple = (None, None, None)
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
        self._bank = ModalFilterBank(self.resonators, self.dt, self._ratio,
                                     sensitivities=self.track_modes)
        self._hp_x = HighPass(self._bank.size, self.highpass)
        self._hp_y = HighPass(self.n_outputs, self.highpass)
        n_res = len(self.resonators)
        self._hp_dq = HighPass(12 * n_res, self.highpass)
        self._hp_dfree = HighPass(4 * n_res, self.highpass)
        self._kf = KalmanPredictor(self.n, initial_covariance=1.0)

    def _check_sizes(self, r: int, m: int) -> None:
        if r != 3:
            raise ValueError(f"u must hold the 3 body torques, got {r} inputs")
        if m != self.layout.size:
            raise ValueError(f"y must have {self.layout.size} entries as the layout "
                             f"{self.layout.names} says, got {m}")

    def _memory(self) -> float:
        # the modal tracker forgets; the rigid gains do not (without rigid_drift)
        return 1.0 / (1.0 - self.tracking_memory) if self.track_modes else np.inf

    def _output_names(self, m: int) -> tuple[str, ...]:
        return tuple(f"{name}[{j}]" for name, sl in self.layout
                     for j in range(sl.stop - sl.start))

    def _allocate(self, r: int, m: int) -> None:
        s = self.layout.scales() if self._user_scales[1] is None else self._user_scales[1]
        self._ratio = float(np.mean(s[self._rate_rows]) / np.mean(s[self._att_rows]))

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
        inside = kf.within(self._mats[2], self._r, y, self.outlier_threshold)
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
        self._search_interval = self.rediscover or 0
        self._next_discovery = self._k + 1 + self._search_interval

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
        # every channel at unit RMS: a tip sensor's own appendage modes (weak in the
        # torque-to-rate response) weigh as much as the hub's
        rms = np.sqrt(np.mean(y**2, axis=0))
        y = y / np.where(rms > 0, rms, 1.0)
        try:
            found = discover_resonators(u, y, budget, self.dt)
        except (ValueError, np.linalg.LinAlgError):     # too short or degenerate a record
            return list(self.resonators)
        return _spend_rank(found, budget)

    def _rebuild(self, resonators: list[Resonator], replay: int) -> None:
        """Build the estimator on ``resonators`` and replay the last ``replay`` samples."""
        self.resonators = tuple(resonators)
        self._new_signal_state()
        bank = self._bank
        size = bank.size
        m = self.n_outputs
        n_res = len(self.resonators)
        samples = list(self._history)[-replay:]
        # the high-passed regressors (and their derivatives by the modal parameters) of
        # the replayed samples, computed at once: they set the regressor scales (unit-RMS
        # columns) and are then replayed as they are, leaving the bank and its
        # high-passes where the replay ends
        raw, raw_dq, raw_dfree = bank.run(np.array([s[0] for s in samples]))
        rows = self._hp_x.run(raw)
        scale = np.sqrt(np.mean(rows ** 2, axis=0))
        scale[bank.slices["free"]] = 1.0
        scale[bank.slices["step"]] = 1.0
        scale[bank.slices["ramp"]] = self.dt
        self._scale = np.where(scale > 0, scale, 1.0)
        # random-walk drift per sample, and an information floor: the flexible couplings
        # are many and weakly excited (noise would be fitted there); the rigid gains
        # are never 0, so their floor bounds the covariance without pulling them
        drift = np.full(size, self.initial_drift)
        floor = np.full(size, 1.0 / INITIAL_COVARIANCE)
        hold = np.zeros(size, dtype=bool)
        drift[bank.slices["flexible"]] = self.coupling_drift
        floor[bank.slices["flexible"]] = FLEXIBLE_FLOOR
        for block in ("attitude", "rate"):                   # the rigid gains
            drift[bank.slices[block]] = self.rigid_drift
            hold[bank.slices[block]] = True
        self._fits = []
        for rows_g, cols in self._regression_groups():
            rls = RecursiveLeastSquares(rows_g.size, cols.size, 1.0, INITIAL_COVARIANCE,
                                        regularization=floor[cols], hold=hold[cols],
                                        drift=drift[cols])
            # the prior is the floor: a coupling the data have not excited yet has the
            # variance it settles at when they stop exciting it
            rls.set_covariance(np.diag(np.minimum(INITIAL_COVARIANCE, 1.0 / floor[cols])))
            self._fits.append((rows_g, cols, rls))
        self._tracker = (ModalTracker(self._tracker_groups(), n_res, self.tracking_memory)
                         if self.track_modes and n_res else None)
        if self._detector is None:
            self._detector = RegressionGLR(threshold=self.change_threshold, dt=self.dt)
        else:
            self._detector.restart()
        if self._r is None:
            self._r = np.full(m, 1e-4)
        self._mats = None
        self._phases = {}
        # replay: the gains and the modal tracker learn from every sample; the Kalman
        # filter (and the exports it needs) only over the last FILTER_TAIL, enough for
        # its state to settle on the new model
        start_k = self._k - len(samples) + 1
        tail = len(samples) - min(len(samples), FILTER_TAIL)
        phis = rows / self._scale
        y_fs = self._hp_y.run(np.array([s[1] for s in samples]))
        dphis = dfrees = None
        if self.track_modes and n_res:
            flex, free = self._modal_scales
            dphis = self._hp_dq.run(raw_dq).reshape(-1, n_res, 2, 3, 2) / flex
            dfrees = self._hp_dfree.run(raw_dfree).reshape(-1, n_res, 2, 2) / free
        for j, (uk, yk, learn, real) in enumerate(samples):
            sensitivity = None if dphis is None else (dphis[j], dfrees[j])
            self._sample(uk, yk, learn, real, replay_k=start_k + j, filtering=j >= tail,
                         signals=(phis[j], y_fs[j], sensitivity))

    def _signals(self) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """The current sample's high-passed regressor and, with tracking, its flexible
        and free-response columns' derivatives by the modal parameters, all scaled as
        the regressor (:attr:`_modal_scales`); advances the high-passes."""
        if not self.track_modes or not self.resonators:
            return self._bank.highpassed(self._hp_x)[0] / self._scale, None
        n_res = len(self.resonators)
        phi, dq, dfree = self._bank.highpassed(self._hp_x, self._hp_dq, self._hp_dfree)
        flex, free = self._modal_scales
        return phi / self._scale, (dq.reshape(n_res, 2, 3, 2) / flex,
                                   dfree.reshape(n_res, 2, 2) / free)

    def _tracker_groups(self) -> list[TrackerGroup]:
        """The sensor groups as the modal tracker sees them."""
        bank = self._bank
        n_res = len(self.resonators)
        idx = np.arange(bank.size)
        flexible = idx[bank.slices["flexible"]].reshape(n_res, 3, 2)
        free = idx[bank.slices["free"]].reshape(n_res, 2)
        groups = []
        for (rows, cols, _), (name, _r) in zip(self._fits, self.layout, strict=True):
            component = int(MEASURES[name] == "velocity")
            where = {c: j for j, c in enumerate(cols)}
            flex_pos = np.array([[where[flexible[i, a, component]] for a in range(3)]
                                 for i in range(n_res)], dtype=int).reshape(n_res, 3)
            free_pos = np.array([[where[free[i, c]] for c in range(2)] for i in range(n_res)],
                                dtype=int).reshape(n_res, 2)
            groups.append(TrackerGroup(rows, cols, flex_pos, free_pos, component))
        return groups

    def _maybe_rediscover(self) -> None:
        """Look for the modes again in the longer history; rebuild if they differ."""
        if (not self.rediscover or self._k + 1 < self._next_discovery
                or len(self._history) < self.warmup):
            return
        self._search_interval *= 2
        self._next_discovery = self._k + 1 + self._search_interval
        found = self._find_resonators()
        if _same_modes(found, self.resonators, REBUILD_TOLERANCE):
            return
        self.n_rediscoveries += 1
        self._rebuild(found, min(len(self._history), REPLAY))

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
            a, b, c, _, _ = self._mats
            # the outputs that were measured (all of them, or those a skipped sample kept)
            y_kf = y if real else (None if seen is None else np.where(seen, y, np.nan))
            self._kf.update(a, b, c, self._process_noise(), self._r, u, y_kf)
            innovation = self._kf.innovation
            if real and innovation is not None and np.isfinite(innovation).all():
                self._measurement_noise(innovation)
        if learn and real:
            err = self._learn(phi, y_f)
            if (err is not None and self.detect_changes and replay_k is None
                    and self._resvar is not None):
                rate = self._rate_rows                 # a change of inertia shows here
                # errors below RESOLUTION of the signal are not evidence of a change
                # (on noise-free data the a-priori error is all slow model error)
                variance = np.maximum(self._resvar[rate], RESOLUTION**2 * self._sigvar[rate])
                event = self._detector.update(phi[bank.slices["rate"]], err[rate], variance,
                                              sample=k)
                if event is not None:
                    self._react(event)
            if err is not None:
                if self._resvar is None:
                    self._resvar, self._sigvar = err**2, y_f**2
                else:           # running mean squares of the errors and the signals
                    _mean_square_step(self._resvar, err, 0.995, 0.005)
                    _mean_square_step(self._sigvar, y_f, 0.995, 0.005)
                if self._last_innovation is None:       # before the filter runs
                    self._r = np.maximum(self._resvar / self._noise_gain, 1e-12)
            if self._tracker is not None and sensitivity is not None:
                self._tracker.update(phi, sensitivity[0], sensitivity[1], y_f)
        if signals is None:
            bank.step(u)
        if replay_k is None and (k + 1) % self.refresh == 0:
            self._refine_modes()
        if filtering and ((k + 1) % self.refresh == 0 or self._mats is None):
            self._export()
        if replay_k is None:
            self._history.append((u, y, learn, real))
            self._maybe_rediscover()

    @property
    def _modal_scales(self) -> tuple[np.ndarray, np.ndarray]:
        """Column scales of the flexible (M, 1, 3, 2) and free-response (M, 1, 2)
        regressors, shaped to divide their derivatives."""
        cached = self.__dict__.get("_modal_scale_cache")
        if cached is not None and cached[0] is self._scale:
            return cached[1]
        bank = self._bank
        n_res = len(self.resonators)
        idx = np.arange(bank.size)
        flex = self._scale[idx[bank.slices["flexible"]]].reshape(n_res, 1, 3, 2)
        free = self._scale[idx[bank.slices["free"]]].reshape(n_res, 1, 2)
        self.__dict__["_modal_scale_cache"] = (self._scale, (flex, free))
        return flex, free

    def _refine_modes(self) -> None:
        """One variable-projection step on the tracker's window; move the resonators,
        the filter bank (states corrected to first order), the high-passes of its
        regressors and the tracker's linearization point by the step."""
        tracker = self._tracker
        if tracker is None:
            return
        delta = tracker.refine()
        if delta is None:
            return
        bank = self._bank
        n_res = len(self.resonators)
        idx = np.arange(bank.size)
        flex = idx[bank.slices["flexible"]].reshape(n_res, 3, 2)
        free = idx[bank.slices["free"]].reshape(n_res, 2)
        # the high-pass is linear: its state for (regressor + delta * derivative) is its
        # state for the regressor plus delta times its state for the derivative
        for hp_d, columns, shape, spec in ((self._hp_dq, flex, (n_res, 2, 3, 2), "mp,mpai->mai"),
                                           (self._hp_dfree, free, (n_res, 2, 2), "mp,mpc->mc")):
            for j in range(2):
                self._hp_x._last[j, columns] += np.einsum(spec, delta,
                                                          hp_d._last[j].reshape(shape))
                self._hp_x._out[j, columns] += np.einsum(spec, delta,
                                                         hp_d._out[j].reshape(shape))
        bank.recenter(delta[:, 0], delta[:, 1])
        self.resonators = bank.resonators
        tracker.recenter(delta)

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
        cached = self.__dict__.get("_theta_index_cache")
        if cached is None or cached[0] is not self._fits:
            cached = (self._fits, [np.ix_(rows, cols) for rows, cols, _ in self._fits])
            self.__dict__["_theta_index_cache"] = cached
        theta = np.zeros((self.n_outputs, self._bank.size))
        for (_, _, rls), index in zip(self._fits, cached[1], strict=True):
            theta[index] = rls.theta
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
        """Unmodelled torque through B, plus an attitude random walk at half the noise.

        The matrix is rewritten in place at every call (only its attitude diagonal
        changes between exports): it is for the filter step at hand only."""
        if self._torque_noise[0] is not self._mats:      # B changes only at an export
            b = self._mats[1]
            q = (self.process_torque / self._su.mean()) ** 2 * (b @ b.T)
            self._torque_noise = (self._mats, q, q[_ATTITUDE_DIAGONAL])
        _, q, torque_diagonal = self._torque_noise
        q[_ATTITUDE_DIAGONAL] = torque_diagonal + 0.25 * self._r[self._att_rows]
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
        if self._tracker is not None:
            self._tracker.reset()

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
        bank = self._bank
        m = self.n_outputs
        theta = self._theta() / self._scale
        # the rigid body's blocks: kinematics (fixed) and the estimated inverse inertia
        a, c = (x.copy() for x in self._rigid_blocks())
        b = np.zeros((self.n, 3))
        g = theta[self._rate_rows, bank.slices["rate"]]       # normalized inverse inertia
        dt, ratio = self.dt, self._ratio
        b[ATTITUDE_STATES] = 0.5 * dt * dt * ratio * g
        b[RATE_STATES] = dt * g
        n_res = len(self.resonators)
        if n_res:
            # every resonator at once: its complex mode, and the SVD of its couplings
            # factored through that mode
            mus, to_complex = self._complex_modes()
            flexible = theta[:, bank.slices["flexible"]].reshape(m, n_res, 3, 2)
            chats = 2.0 * np.einsum("imas,is->ima", flexible.transpose(1, 0, 2, 3),
                                    to_complex)                                 # (M, m, 3)
            lefts, svs, rights = np.linalg.svd(chats, full_matrices=False)
            # one exported mode per (resonator, rank): its singular triple, as complex
            # output and input vectors
            res, rank = self._export_modes()
            c_vecs = lefts[res, :, rank] * svs[res, rank][:, None]             # (R, m)
            b_vecs = rights[res, rank]                                          # (R, 3)
            b_vecs, c_vecs = self._align_phases(res, rank, b_vecs, c_vecs)
            # mode r is the real 2x2 block of mu at states 6 + 2 r and 6 + 2 r + 1
            re = np.arange(6, 6 + 2 * res.size, 2)
            mu = mus[res]
            a[re, re] = a[re + 1, re + 1] = mu.real
            a[re, re + 1] = -mu.imag
            a[re + 1, re] = mu.imag
            b[re], b[re + 1] = b_vecs.real, b_vecs.imag
            c[:, re], c[:, re + 1] = c_vecs.real.T, -c_vecs.imag.T
        if not (np.isfinite(a).all() and np.isfinite(b).all() and np.isfinite(c).all()):
            return
        self._mats = (a, b, c, np.zeros((m, 3)), None)

    def _complex_modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Every resonator's complex mode ``mu`` (M,) and the map (M, 2) from its real
        states ``[q, q']`` to the mode's coordinate, scaled by the input's share of it.

        They change only when the resonators move (a refinement, a rebuild): kept
        until then."""
        bank = self._bank
        cached = self.__dict__.get("_complex_mode_cache")
        if cached is not None and cached[0] is bank and cached[1] is bank.resonators:
            return cached[2]
        modes_a, modes_b = bank.mode_matrices
        every = np.arange(len(bank.resonators))
        vals, vecs = np.linalg.eig(modes_a)                                   # (M, 2)
        top = np.argmax(vals.imag, axis=1)
        mus = vals[every, top]
        shares = np.linalg.solve(vecs, modes_b[:, :, None])[:, :, 0]           # (M, 2)
        to_complex = vecs[every, :, top] * shares[every, top][:, None]          # (M, 2)
        self.__dict__["_complex_mode_cache"] = (bank, bank.resonators, (mus, to_complex))
        return mus, to_complex

    def _align_phases(self, res: np.ndarray, rank: np.ndarray, b_vecs: np.ndarray,
                      c_vecs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fix the free phase of every exported mode's singular pair.

        The input vector ``b`` of each mode is rotated to agree in phase with
        its last export (its largest entry made real at the first), and the
        output vector ``c`` by the opposite phase, so the product is unchanged
        and the state keeps its meaning from one export to the next.

        Returns
        -------
        b_vecs, c_vecs : ndarray
            The rotated vectors; the new references are recorded.
        """
        phases = np.ones(res.size, dtype=complex)
        for j, key in enumerate(zip(res.tolist(), rank.tolist(), strict=True)):
            b_vec = b_vecs[j]
            ref = self._phases.get(key)
            phase = b_vec[np.argmax(np.abs(b_vec))] if ref is None else np.vdot(ref, b_vec)
            if abs(phase) > 0:
                phases[j] = phase / abs(phase)
        b_vecs = b_vecs / phases[:, None]
        c_vecs = c_vecs * phases[:, None]
        self._phases.update(zip(zip(res.tolist(), rank.tolist(), strict=True), b_vecs,
                                strict=True))
        return b_vecs, c_vecs

    def _rigid_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """The fixed part of the exported ``A`` and ``C`` (kinematics, sensor selection):
        attitude integrates rate, both are measured; the modal blocks are left 0."""
        key = (self.n, self.n_outputs, self.dt, self._ratio)
        cached = self.__dict__.get("_rigid_block_cache")
        if cached is not None and cached[0] == key:
            return cached[1]
        psi, omega = ATTITUDE_STATES, RATE_STATES
        a = np.zeros((self.n, self.n))
        c = np.zeros((self.n_outputs, self.n))
        a[psi, psi] = np.eye(3)
        a[psi, omega] = self.dt * self._ratio * np.eye(3)
        a[omega, omega] = np.eye(3)
        c[self._att_rows, psi] = np.eye(3)
        c[self._rate_rows, omega] = np.eye(3)
        self.__dict__["_rigid_block_cache"] = (key, (a, c))
        return a, c

    def _export_modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Resonator and rank of every exported mode, in state order."""
        ranks = [r.rank for r in self.resonators]
        cached = self.__dict__.get("_export_mode_cache")
        if cached is not None and cached[0] == ranks:
            return cached[1]
        res = np.repeat(np.arange(len(ranks)), ranks)
        rank = np.concatenate([np.arange(r) for r in ranks]) if ranks else res
        self.__dict__["_export_mode_cache"] = (ranks, (res, rank))
        return res, rank

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
    def rigid_gain(self) -> RigidGainEstimate | None:
        """The rigid-body gain ``G = J^-1`` (rad/s^2 per N m) with its calibrated
        covariance (:class:`~identifiers.rigid_gain.RigidGainEstimate`), from the rate
        regression; None before warm-up."""
        if not self._fits or self._resvar is None:
            return None
        bank = self._bank
        rate = self.layout.slice("rate")
        rate_cols = np.arange(bank.size)[bank.slices["rate"]]
        for rows, cols, rls in self._fits:
            if rows[0] != rate.start:
                continue
            where = np.searchsorted(cols, rate_cols) if np.all(np.diff(cols) > 0) else \
                np.array([int(np.flatnonzero(cols == c)[0]) for c in rate_cols])
            theta = rls.theta[:, where]
            p = rls.P[np.ix_(where, where)]
            return RigidGainEstimate.from_regression(
                theta, p, self._resvar[rate], self._sy[rate],
                self._scale[rate_cols] * self._su)
        return None

    @property
    def mode_estimates(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The tracked resonators: frequencies (Hz), damping ratios and the covariance
        of ``[log f_1, zeta_1, ..., log f_M, zeta_M]`` from the last refinement (None
        before one or without tracking)."""
        freq = np.array([r.frequency_hz for r in self.resonators])
        zeta = np.array([r.damping for r in self.resonators])
        cov = None if self._tracker is None else self._tracker.covariance
        return freq, zeta, cov

    @property
    def events(self) -> list[ChangeEvent]:
        """Changes detected so far (empty before warm-up)."""
        return [] if self._detector is None else list(self._detector.events)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n={self.n}, "
                f"modes={[round(r.frequency_hz, 4) for r in self.resonators]}, "
                f"samples={self.n_samples}, skipped={self.n_skipped}, events={len(self.events)})")
