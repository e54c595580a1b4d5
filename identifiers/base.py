"""Streaming identifier API shared by every online method, and the stages
the recursive PBSID methods are built from.

:class:`OnlineIdentifier` owns everything that is not the algorithm: input
validation, sizes inferred from the first sample, the past window
``phi = [z_{k-1}; ...; z_{k-p}]``, NaN/inf handling, warm-up, ``fit`` and
``reset``. Two stages are shared by the recursive PBSID classes:

* :class:`RecursiveVARXIdentifier`: the recursive VARX predictor (paper
  Eq. 20-24), which every recursive PBSID method updates first;
* :class:`SystemRLSIdentifier`: RLS for ``[C D]`` and ``[A B K]`` on a state
  sequence (Eq. 47-55), for the methods that regress on states
  (:class:`~identifiers.improved.ImprovedRPBSID`,
  :class:`~identifiers.predictor.PredictorRPBSID`,
  :class:`~identifiers.classical.ClassicalRPBSID`), and
  :class:`PredictionStateIdentifier`, the state ``x = W LK phi`` of the last
  two.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from identifiers.data_monitor import SKIP_SHARE, WINDOW, DataMonitor
from identifiers.health import (
    HEALTH_EVERY,
    MAX_ROLLBACKS,
    IdentifierHealth,
    degenerate,
    state_problem,
    warn_health,
)
from identifiers.model import ModelSequence, StateSpaceModel
from identifiers.rls import RecursiveLeastSquares
from spacecraft_conventions import single_threaded_blas

__all__ = [
    "OUTLIER_RUN",
    "OnlineIdentifier",
    "PredictionStateIdentifier",
    "RecursiveVARXIdentifier",
    "SystemRLSIdentifier",
]


#: Longest run of consecutive samples the outlier guard rejects (0.5 s at
#: dt = 0.1 s). A longer run is not a faulty sensor but a plant (or signal
#: level) the guard's reference no longer describes: the samples are learned
#: from again, or the guard would shut the identifier off for good.
OUTLIER_RUN = 5

#: Attributes that a rollback keeps at their current values: the counters,
#: the health record itself and the sample clock.
_KEPT_ON_ROLLBACK = ("n_samples", "n_skipped", "n_outliers", "n_idle", "n_rollbacks",
                     "n_restarts", "n_rescales",
                     "_last_fault", "_fault_samples", "_good", "_k", "_healthy", "_warned",
                     "_monitor", "_range_skips", "_warned_faults")


def _positive_int(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if value < 1:
        raise ValueError(f"{name} must be >= 1, got {value}")
    return int(value)


def _scale(name: str, value) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be a 1-D array of positive finite scales")
    return arr


def _rms_scale(samples: np.ndarray) -> np.ndarray:
    """Per-column RMS of the finite entries, 1 where there is none or it is 0.

    Computed relative to each column's peak, so data of any magnitude up to
    the largest float give a finite scale (no overflow in the squares).
    """
    finite = np.where(np.isfinite(samples), samples, 0.0)
    count = np.isfinite(samples).sum(axis=0)
    peak = np.abs(finite).max(axis=0)
    peak = np.where(peak > 0, peak, 1.0)
    rms = peak * np.sqrt(((finite / peak) ** 2).sum(axis=0) / np.maximum(count, 1))
    return np.where((rms > 0) & np.isfinite(rms), rms, 1.0)


def _forgetting(name: str, value: float) -> float:
    value = float(value)
    if not 0.0 < value <= 1.0:
        raise ValueError(f"{name} must be in (0, 1], got {value}")
    return value


def _positive_float(name: str, value: float) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be positive, got {value}")
    return value


class OnlineIdentifier(ABC):
    """Base class of the streaming identifiers: ``update(u, y)`` one sample at a time.

    Parameters
    ----------
    n : int
        Model order.
    p : int
        Past window (VARX lags); ``p * m >= n`` is required.
    forgetting : float
        Forgetting factor in (0, 1].
    dt : float
        Sample time (s) stamped on the models.
    warmup : int, optional
        Samples before ``model`` is available; default ``4 p``.
    input_scale, output_scale : array_like, optional
        Per-channel scales (RMS levels) of u and y. Every estimator runs on
        ``u / input_scale`` and ``y / output_scale`` so that its constants
        (initial covariances, bounds) mean the same whatever the units;
        models are returned in physical units and the state in the internal
        coordinates that ``model`` uses. Default: the RMS of the first ``p``
        samples (a period in which nothing is learned anyway), 1 where that
        is zero.
    max_abs : float
        Largest normalized magnitude a sample may have (default 1e6: a
        million nominal levels, far beyond any physical signal); larger
        entries are treated as corrupt and the sample is skipped.

    Attributes
    ----------
    n_samples : int
        Samples received (including skipped ones).
    n_skipped : int
        Samples that were skipped: NaN/inf, beyond ``max_abs``, or rejected
        as outliers (see :meth:`update`).
    n_outliers : int
        Of those, the ones rejected by the outlier guard.
    n_idle : int
        Samples passed over because they carried no information at all: zero
        input and an output equal bit for bit to the previous one (a plant at
        rest, or a frozen sensor). They move no estimate and no clock.
    n_rollbacks, n_restarts : int
        Faults of the internal state repaired by a rollback, or by a restart
        of the estimator (see :attr:`health`).
    n_inputs, n_outputs : int or None
        r and m, inferred from the first sample.
    """

    #: Whether successive models share state coordinates.
    consistent_basis = True
    #: Attributes that describe the recent signals rather than what was learnt
    #: (past windows, filter states driven by the data): a rollback keeps their
    #: current values, so they stay aligned with the samples still to come.
    _SIGNAL_STATE: ClassVar[tuple[str, ...]] = ("_phi",)
    #: Attributes whose items are never changed in place (lists of sample
    #: tuples): the rollback copy shares their items instead of copying them.
    _SHARED_ITEMS: ClassVar[tuple[str, ...]] = ("_pending",)

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.98, *, dt: float = 0.1,
                 warmup: int | None = None, input_scale: ArrayLike | None = None,
                 output_scale: ArrayLike | None = None, max_abs: float = 1e6) -> None:
        self.n = _positive_int("n", n)
        self.p = _positive_int("p", p)
        self.forgetting = _forgetting("forgetting", forgetting)
        self.dt = float(dt)
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive finite number of seconds, got {dt}")
        self.max_abs = _positive_float("max_abs", max_abs)
        self.warmup = 4 * self.p if warmup is None else _positive_int("warmup", warmup)
        if self.warmup < self.p:
            raise ValueError(f"warmup must be >= p = {self.p}, got {self.warmup}")
        self._user_scales = (None if input_scale is None else _scale("input_scale", input_scale),
                             None if output_scale is None else _scale("output_scale",
                                                                       output_scale))
        self.reset()

    # ------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        """Forget everything, including the input and output sizes."""
        self.n_inputs: int | None = None
        self.n_outputs: int | None = None
        self.n_samples = 0
        self.n_skipped = 0
        self.n_outliers = 0
        self._k = 0            # samples processed by the estimator
        self._quiet = 0
        self._outlier_run = 0
        self._skip_run = 0
        self._last_y: np.ndarray | None = None
        self.n_idle = 0
        self._phi = None
        self._su = self._sy = None
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        self._monitor: DataMonitor | None = None
        self._range_skips = 0
        self._reset_health()

    def _reset_health(self) -> None:
        self.n_rollbacks = 0
        self.n_restarts = 0
        self.n_rescales = 0
        self._warned_faults: set[tuple[str, int | None]] = set()
        self._last_fault: str | None = None
        self._fault_samples: deque[int] = deque(maxlen=MAX_ROLLBACKS + 1)
        self._good: tuple[int, dict] | None = None     # (n_samples, copy of the state)
        self._healthy = True
        self._warned = False

    def restart(self) -> None:
        """Begin a new record of the same plant family (a new episode), keeping what was learnt.

        The next sample does not follow the last one in time: an episode
        reset, a data gap. An identifier that can carry its estimates over
        keeps them and restarts only what describes the old record's signals
        (past windows, filter states, the state estimate).
        :class:`~identifiers.rigid_flexible.RigidFlexibleIdentifier` does;
        this default forgets everything (:meth:`reset`), because the
        past-window methods also keep data windows and bases built from the
        old record.
        """
        self.reset()

    def _check_sizes(self, r: int, m: int) -> None:
        """Reject sizes the method cannot identify an order-n model from (the
        past-window methods need ``p m >= n``)."""
        if self.p * m < self.n:
            raise ValueError(f"p * m = {self.p * m} must be >= n = {self.n} "
                             f"(m = {m} outputs); increase p")

    def _init_sizes(self, r: int, m: int) -> None:
        self._check_sizes(r, m)
        su, sy = self._user_scales
        if su is not None and su.shape != (r,):
            raise ValueError(f"input_scale must have shape ({r},), got {su.shape}")
        if sy is not None and sy.shape != (m,):
            raise ValueError(f"output_scale must have shape ({m},), got {sy.shape}")
        self.n_inputs, self.n_outputs = r, m
        self._zr = r + m
        self._phi = np.zeros(self.p * self._zr)
        self._monitor = DataMonitor(r, m, self._memory(), self._output_names(m))
        self._allocate(r, m)

    def _memory(self) -> float:
        """The estimator's memory in samples, ``1 / (1 - forgetting)`` (inf without
        forgetting): an input constant for longer is reported ``unexcited``."""
        return np.inf if self.forgetting >= 1.0 else 1.0 / (1.0 - self.forgetting)

    def _output_names(self, m: int) -> tuple[str, ...]:
        """A label per output for the health messages (default ``y[i]``)."""
        return tuple(f"y[{i}]" for i in range(m))

    @abstractmethod
    def _allocate(self, r: int, m: int) -> None:
        """Create the estimator state once r and m are known."""

    @abstractmethod
    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        """Process one sample; must call :meth:`_push` once."""

    @abstractmethod
    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        """Current ``(A, B, C, D, K)`` or None."""

    @abstractmethod
    def _current_state(self) -> np.ndarray | None:
        """State estimate for the next sample time, x_{k+1|k}."""

    def _fill_output(self) -> np.ndarray:
        """Stand-in for a missing output sample (default zeros)."""
        return np.zeros(self.n_outputs)

    # ------------------------------------------------------------ streaming
    def _push(self, u: np.ndarray, y: np.ndarray) -> None:
        """Shift ``z_k = [u_k; y_k]`` into the past window (newest first)."""
        phi = self._phi
        zr = self._zr
        phi[zr:] = phi[:-zr]
        phi[:self.n_inputs] = u
        phi[self.n_inputs:zr] = y

    def _validate(self, u, y) -> tuple[np.ndarray, np.ndarray]:
        """``u`` and ``y`` as 1-D float arrays (the caller's own arrays when they are
        already that: a sample is only read, and :meth:`update` copies what it keeps)."""
        arrays = []
        for name, value in (("u", u), ("y", y)):
            arr = np.asarray(value)
            if arr.dtype.kind not in "fiu":
                raise TypeError(f"{name} must be a real numeric 1-D array, got dtype {arr.dtype}")
            if arr.ndim != 1 or arr.size == 0:
                raise ValueError(f"{name} must be a non-empty 1-D array of one sample, "
                                 f"got shape {arr.shape}")
            arrays.append(arr if arr.dtype == np.float64 else arr.astype(float))
        u, y = arrays
        if self.n_inputs is None:
            self._init_sizes(u.size, y.size)
        elif u.shape != (self.n_inputs,) or y.shape != (self.n_outputs,):
            raise ValueError(f"u and y must have shapes ({self.n_inputs},) and "
                             f"({self.n_outputs},) as in the first sample, got {u.shape} and "
                             f"{y.shape}")
        return u, y

    @single_threaded_blas
    def update(self, u: ArrayLike, y: ArrayLike) -> None:
        """Process one sample ``(u_k, y_k)``.

        BLAS runs single-threaded during the call (the library's small
        per-sample products are fastest and bit-reproducible that way; see
        :mod:`spacecraft_conventions.blas`), whatever the caller's setting.

        A sample that cannot be learned from is skipped and counted in
        ``n_skipped``: one with NaN or inf, or with a normalized magnitude
        beyond ``max_abs`` (a corrupt reading: a million nominal levels), or
        (if ``outlier_threshold`` is set) an outlier of the one-step
        prediction error. Its unusable entries are replaced (inputs by 0,
        outputs by their prediction) to keep the past window aligned in
        time; the sample itself is not learned from. A single stand-in is off
        by about the noise, so learning goes on; after two or more in a row
        it pauses until they have left the window. ``update`` never raises on
        such data (nor on any finite or non-finite data of the right shape).

        Raises
        ------
        ValueError
            Wrong shape, or a size different from the first sample's.
        TypeError
            Non-numeric data.
        """
        u, y = self._validate(u, y)
        self.n_samples += 1
        if self._su is None:
            su, sy = self._user_scales
            if su is not None and sy is not None:
                self._su, self._sy = su, sy
            else:
                self._pending.append((u.copy(), y.copy()))
                if len(self._pending) < self.p:
                    return
                pending_u = np.array([pu for pu, _ in self._pending])
                pending_y = np.array([py for _, py in self._pending])
                self._su = su if su is not None else _rms_scale(pending_u)
                self._sy = sy if sy is not None else _rms_scale(pending_y)
                for pu, py in self._pending:
                    self._process(pu, py)
                self._pending = []
                return
        self._process(u, y)

    def _process(self, u: np.ndarray, y: np.ndarray) -> None:
        # a broken internal state must not raise (or warn) from inside the arithmetic:
        # it is found by the health checks, which roll it back
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            self._process_sample(u, y)

    def _process_sample(self, u: np.ndarray, y: np.ndarray) -> None:
        u = u / self._su
        y = y / self._sy
        if self._last_y is not None and not u.any() and np.array_equal(y, self._last_y):
            # zero input and the same output bit for bit: a plant at rest or a frozen
            # sensor. No information; processing it would only let forgetting erase what
            # was learnt (and a warm-up end on nothing). Skipped without moving the clock.
            self.n_idle += 1
            return
        self._last_y = y
        received_u, received_y = u, y
        # every entry finite and within max_abs (a NaN fails the comparison too); the
        # per-entry masks are only needed for a sample that is not
        usable = bool(np.abs(u).max() <= self.max_abs and np.abs(y).max() <= self.max_abs)
        if not usable and (np.any(np.isfinite(u) & (np.abs(u) > self.max_abs))
                           or np.any(np.isfinite(y) & (np.abs(y) > self.max_abs))):
            self._range_skips += 1
        verdict: bool | np.ndarray = True
        if usable:
            verdict = self._admissible(u, y)
            if verdict is True or np.all(verdict):
                verdict = True
                self._outlier_run = 0
            else:
                self._outlier_run += 1
                if self._outlier_run <= OUTLIER_RUN:
                    self.n_outliers += 1
                    usable = False                   # an outlier: predict those outputs
                else:
                    verdict = True
                    self._accept_outlier_run(u, y)   # the guard's reference is stale
        if usable:
            learn = self._quiet == 0 and self._k >= self.p
            self._step(u, y, learn)
            if self._quiet:
                self._quiet -= 1
            self._skip_run = 0
        else:
            self.n_skipped += 1
            usable_u = np.isfinite(u) & (np.abs(u) <= self.max_abs)
            usable_y = np.isfinite(y) & (np.abs(y) <= self.max_abs) & verdict
            u = np.where(usable_u, u, 0.0)
            fill = self._fill_output()           # a broken estimator predicts NaN: 0 then
            y = np.where(usable_y, y, np.where(np.isfinite(fill), fill, 0.0))
            self._step(u, y, False)
            # one stand-in in the past window is the one-step prediction, off by about
            # the noise: learning goes on. From the second in a row, it pauses until the
            # stand-ins have left the window.
            self._skip_run += 1
            if self._skip_run > 1:
                self._quiet = self.p + 1
        if self._monitor.observe(received_u, received_y, skipped=self._skip_run > 0):
            self._assess_data()
            if self._monitor is None:          # re-scaled: the estimator starts again
                return
        self._k += 1
        state = self._state_vector()
        if self._k % HEALTH_EVERY == 0 or (state is not None and not np.isfinite(state).all()):
            self._check_health()

    # ------------------------------------------------------------ health
    def _accept_outlier_run(self, u: np.ndarray, y: np.ndarray) -> None:  # noqa: B027
        """Hook: a sample beyond the outlier guard is learned from, because the run of
        rejections exceeded :data:`OUTLIER_RUN` (default: nothing to update)."""

    def _assess_data(self) -> None:
        """After each monitor window: re-scale if the automatic scales froze on a level
        the data left, and warn once of each new data fault."""
        range_skips, self._range_skips = self._range_skips, 0
        auto = [s is None for s in self._user_scales]
        if any(auto) and range_skips >= SKIP_SHARE * WINDOW:
            self._rescale(range_skips)
            return
        for key, message in self._monitor.faults.items():
            if key not in self._warned_faults:
                self._warned_faults.add(key)
                warn_health(f"{type(self).__name__}: {message} (see .health)")

    def _rescale(self, range_skips: int) -> None:
        """Start again with automatic scales taken from the next ``p`` samples: the
        data left the level the first samples set by more than ``max_abs``."""
        kept = {k: getattr(self, k) for k in _KEPT_ON_ROLLBACK if k != "_monitor"}
        self.reset()
        vars(self).update(kept)
        self.n_rescales += 1
        self._good = None
        self._healthy = False
        self._last_fault = (f"rescaled: {range_skips} of the last {WINDOW} samples were beyond "
                            f"max_abs = {self.max_abs:g} times the automatic scales, which are "
                            f"taken again from the next p = {self.p} samples")
        warn_health(f"{type(self).__name__} {self._last_fault}")

    def _state_vector(self) -> np.ndarray | None:
        """The estimator's own state vector, checked for finiteness every sample
        (default: the ``_x`` attribute, if any)."""
        return vars(self).get("_x")

    def _health_problem(self) -> str | None:
        """What is wrong with the internal state now (:func:`~identifiers.health.state_problem`)."""
        mats = self._matrices() if self._k >= self.warmup else None
        state = self._current_state() if mats is not None else None
        return state_problem(self, mats, state)

    def _snapshot(self) -> dict:
        """A deep copy of the estimator state (items of :attr:`_SHARED_ITEMS` shared)."""
        state = {k: v for k, v in vars(self).items() if k not in _KEPT_ON_ROLLBACK}
        memo: dict[int, Any] = {}
        for key in self._SHARED_ITEMS:
            value = state.get(key)
            if value is not None:
                memo[id(value)] = copy.copy(value)
        return copy.deepcopy(state, memo)

    def _check_health(self) -> None:
        """Check the internal state; keep a copy if it is good, roll back if it is not.

        A fault is repaired by returning to the last good copy (the samples
        since are lost; learning pauses until the past window holds only
        samples after the rollback). More than :data:`~identifiers.health.MAX_ROLLBACKS`
        faults within ten check periods, or a fault with no good copy,
        restart the estimator: ``health.healthy`` is then False until a
        check passes.
        """
        problem = self._health_problem()
        if problem is None:
            self._good = (self.n_samples, self._snapshot())
            if not self._healthy and self.ready and self._matrices() is not None:
                self._healthy, self._warned = True, False
            return
        self._last_fault = problem
        self._fault_samples.append(self.n_samples)
        recent = sum(self.n_samples - s <= 10 * HEALTH_EVERY for s in self._fault_samples)
        if self._good is not None and recent <= MAX_ROLLBACKS:
            kept = {k: v for k, v in vars(self).items()
                    if k in _KEPT_ON_ROLLBACK or (k in self._SIGNAL_STATE and (
                        not isinstance(v, np.ndarray) or np.all(np.isfinite(v))))}
            restored = copy.deepcopy(self._good[1], {id(v): copy.copy(v) for k, v in
                                                     self._good[1].items()
                                                     if k in self._SHARED_ITEMS})
            vars(self).update(restored)
            vars(self).update(kept)
            self.n_rollbacks += 1
            self._quiet = max(self._quiet, self.p + 1)
            self._after_rollback()
        else:
            kept = {k: getattr(self, k) for k in _KEPT_ON_ROLLBACK}
            self.reset()
            vars(self).update(kept)
            self.n_restarts += 1
            self._good = None
            self._healthy = False

    def _after_rollback(self) -> None:  # noqa: B027  (optional hook)
        """Hook run after a rollback (default: nothing more)."""

    @property
    def health(self) -> IdentifierHealth:
        """The identifier's report on itself (:class:`~identifiers.health.IdentifierHealth`)."""
        good = None if self._good is None else self._good[0]
        faults = () if self._monitor is None else tuple(self._monitor.faults.values())
        if self._healthy and self.ready:
            nothing = degenerate(self._matrices())
            faults = faults if nothing is None else (nothing, *faults)
        return IdentifierHealth(
            healthy=self._healthy and not faults, samples=self.n_samples,
            skipped=self.n_skipped, outliers=self.n_outliers, idle=self.n_idle,
            rollbacks=self.n_rollbacks, restarts=self.n_restarts, rescales=self.n_rescales,
            faults=faults,
            last_fault=self._last_fault, last_good_sample=good,
            last_good_time_s=None if good is None else good * self.dt)

    def _admissible(self, u: np.ndarray, y: np.ndarray) -> bool | np.ndarray:
        """Whether a finite, in-range normalized sample may be learned from (hook for
        outlier guards; default: always). A boolean mask over the outputs rejects the
        sample and replaces only the outputs it marks False by their prediction."""
        return True

    def _physical(self, mats: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """Matrices of the normalized model in physical units (state unchanged)."""
        a, b, c, d, k = mats
        su, sy = self._su, self._sy
        return a, b / su, sy[:, None] * c, sy[:, None] * d / su, k / sy

    def fit(self, U: ArrayLike, Y: ArrayLike) -> ModelSequence:
        """Feed a whole record sample by sample; return the model after each.

        Parameters
        ----------
        U : (N, r) array_like
        Y : (N, m) array_like

        Returns
        -------
        ModelSequence
            Entry k is the model after sample k (None while warming up),
            with the state estimate ``x_{k+1|k}`` in ``states``; identical to
            calling :meth:`update` in a loop.
        """
        u = np.asarray(U, dtype=float)
        y = np.asarray(Y, dtype=float)
        if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
            raise ValueError(f"U and Y must have shapes (N, r) and (N, m), got {u.shape} and "
                             f"{y.shape}")
        with single_threaded_blas:       # one entry for the loop; updates nest cheaply
            return self._fit(u, y)

    def _fit(self, u: np.ndarray, y: np.ndarray) -> ModelSequence:
        N = u.shape[0]
        mats: list[np.ndarray] = []
        states = np.empty((N, 0))
        valid = np.zeros(N, dtype=bool)
        for k in range(N):
            self.update(u[k], y[k])
            if self.ready and self._exportable():
                # as quiet as update: a broken state is the health checks' to find
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    cur = self._matrices()
                    x = self._current_state()
                if cur is not None and x is not None and not degenerate(cur):
                    if not mats:       # the model order is known once there is a model
                        mats = [np.full((N, *mat.shape), np.nan) for mat in cur]
                        states = np.full((N, x.shape[0]), np.nan)
                    valid[k] = True
                    states[k] = x
                    for arr, mat in zip(mats, self._physical(cur), strict=True):
                        arr[k] = mat
        if not mats:
            n, r, m = self.n, u.shape[1], y.shape[1]
            mats = [np.full((N, *shape), np.nan)
                    for shape in ((n, n), (n, r), (m, n), (m, r), (n, m))]
            states = np.full((N, n), np.nan)
        return ModelSequence(*mats, valid, self.dt, self.consistent_basis, states=states)

    # ------------------------------------------------------------ results
    @property
    def ready(self) -> bool:
        """True once warmed up."""
        return self.n_samples >= self.warmup and self._su is not None

    def _exportable(self) -> bool:
        """False (with one :class:`~identifiers.health.IdentifierHealthWarning`) while
        the estimator is restarting after a fault; :attr:`model` and :meth:`fit` alike."""
        if not self._healthy:
            if not self._warned:
                self._warned = True
                warn_health(f"{type(self).__name__} restarted its estimator after a fault "
                            f"({self._last_fault}); no model until it is healthy again "
                            "(see .health)")
            return False
        return True

    @property
    def model(self) -> StateSpaceModel | None:
        """Current identified model, or None until warmed up (and, with an
        :class:`~identifiers.health.IdentifierHealthWarning`, while the
        estimator is restarting after a fault: see :attr:`health`)."""
        if not self._exportable():
            return None
        if not self.ready:
            return None
        mats = self._matrices()
        if mats is None or degenerate(mats):
            return None
        return StateSpaceModel(*self._physical(mats), dt=self.dt)

    @property
    def state(self) -> np.ndarray | None:
        """State estimate for the next sample, x_{k+1|k}, in the model's coordinates."""
        if not self.ready:
            return None
        x = self._current_state()
        return None if x is None else x.copy()

    @property
    def rigid_states(self) -> tuple[slice, slice] | None:
        """Slices of the model state that are the attitude and the body rate, if
        the identifier's state has that physical layout (default None: a
        subspace method's state is in coordinates of its own)."""
        return None

    def filtered_state(self, y: ArrayLike) -> np.ndarray | None:
        """State estimate at the current sample given its measurement, ``x_{k|k}``.

        :attr:`state` is the prediction ``x_{k|k-1}`` made before ``y_k`` was
        seen; a controller that acts on ``y_k`` before passing it to
        :meth:`update` uses this instead. Identifiers with a Kalman filter
        correct the prediction with ``y_k`` (non-finite entries ignored);
        the default returns the prediction. The identifier is not changed.
        """
        return self.state

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n={self.n}, p={self.p}, forgetting={self.forgetting}, "
                f"samples={self.n_samples}, skipped={self.n_skipped})")




def state_horizon(f: int | None, n: int, m: int, basis: str) -> int:
    """Prediction horizon (samples) of a state built from stacked output predictions.

    Default ``2 ceil(n / m)`` for a basis fitted to the predictions (twice
    the minimum, which measured best on the ETS-VIII model) and
    ``ceil(n / m)`` for the plain selection ``W = [I_n 0]``.

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
        :class:`~identifiers.rls.RecursiveLeastSquares`). A VARX with
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
        reproduce its tables; ``overrides`` change single settings (e.g. ``dt``)."""
        return cls(n, **{**cls.PAPER_SETTINGS, **overrides})

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.9995, *, dt: float = 0.1,
                 warmup: int | None = 500, regularization: float = 1e-4,
                 varx_forgetting: float | None = None, varx_init: float = 0.9,
                 outlier_threshold: float | None = 30.0,
                 input_scale: ArrayLike | None = None,
                 output_scale: ArrayLike | None = None, max_abs: float = 1e6) -> None:
        forgetting = _forgetting("forgetting", forgetting)
        if not (np.isfinite(regularization) and regularization >= 0):
            raise ValueError(f"regularization must be >= 0, got {regularization}")
        self.regularization = float(regularization)
        self.varx_forgetting = _forgetting(
            "varx_forgetting", forgetting if varx_forgetting is None else varx_forgetting)
        self.varx_init = _positive_float("varx_init", varx_init)
        self.outlier_threshold = (None if outlier_threshold is None
                                  else _positive_float("outlier_threshold", outlier_threshold))
        if warmup is None:
            warmup = max(4 * _positive_int("p", p), p + 2 * _positive_int("n", n))
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

    def _fill_output(self) -> np.ndarray:
        return self._varx.predict(self._phi)

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
        innovation_sq = (y - self._varx.predict(self._phi)) ** 2
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
        forgetting = _forgetting("forgetting", forgetting)
        self.output_forgetting = _forgetting(
            "output_forgetting", forgetting if output_forgetting is None else output_forgetting)
        self.system_forgetting = _forgetting(
            "system_forgetting", forgetting if system_forgetting is None else system_forgetting)
        self.output_init = _positive_float("output_init", output_init)
        self.system_init = _positive_float("system_init", system_init)
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
      basis.
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
        self.f = None if f is None else _positive_int("f", f)
        super().__init__(n, p, forgetting, **kwargs)
        if basis == "svd" and self.warmup - self.p < self.n:
            raise ValueError(f"the SVD basis needs warmup >= p + n = {self.p + self.n}")

    def reset(self) -> None:
        super().reset()
        self._w = None
        self._basis_data: list[np.ndarray] = []

    def _allocate(self, r: int, m: int) -> None:
        super()._allocate(r, m)
        self._horizon = state_horizon(self.f, self.n, m, self.basis)
        if self.basis == "selection":
            self._w = np.eye(self.n, self._horizon * m)

    @abstractmethod
    def _predictions(self, phi: np.ndarray) -> np.ndarray:
        """Stacked output predictions ``LK phi`` over the horizon, (f m,)."""

    def _fix_basis(self) -> None:
        """W from the SVD of the warm-up predictions (once)."""
        preds = np.array([self._predictions(phi) for phi in self._basis_data]).T
        left = np.linalg.svd(preds, full_matrices=False)[0]
        self._w = left[:, :self.n].T.copy()
        self._basis_data = []

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        if learn:
            self._varx.update(self._phi, y)
        self._push(u, y)
        if self._w is None:
            if learn:
                self._basis_data.append(self._phi.copy())
            if self._k + 1 >= self.warmup and len(self._basis_data) >= self.n:
                self._fix_basis()
            else:
                return
        x_next = self._w @ self._predictions(self._phi)
        if learn and self._x is not None:
            self._learn_system(self._x, u, y, x_next)
        self._x = x_next
