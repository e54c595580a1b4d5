"""The sample guard of every streaming identifier: what may be learned from.

:class:`SampleScreening` is the part of
:class:`identifiers.core.online.OnlineIdentifier` that checks each sample
before the estimator sees it: shapes and types (``raise``), samples that
carry no information (a plant at rest, a frozen sensor), NaN/inf and
magnitudes beyond ``max_abs`` (skipped, replaced by a stand-in that keeps
the past window aligned in time), the outlier guard (a hook each method
fills from its own prediction error) and the automatic re-scaling when the
data leave the level their first samples set. An identifier composes it
with :class:`identifiers.core.rollback.HealthGuard` (the estimator's own
state) through :class:`identifiers.core.online.OnlineIdentifier`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from identifiers.core.checks import all_finite
from identifiers.core.data_monitor import SKIP_SHARE, WINDOW
from identifiers.core.health import HEALTH_EVERY, warn_health
from identifiers.core.rollback import KEPT_ON_ROLLBACK

__all__ = ["OUTLIER_RUN", "SampleScreening"]


#: Longest run of consecutive samples the outlier guard rejects (0.5 s at
#: dt = 0.1 s). A longer run is not a faulty sensor but a plant (or signal
#: level) the guard's reference no longer describes: the samples are learned
#: from again, or the guard would shut the identifier off for good.
OUTLIER_RUN = 5


@njit(cache=True, nogil=True)
def _idle_and_usable(u: np.ndarray, y: np.ndarray, last_y: np.ndarray, has_last: bool,
                     max_abs: float) -> tuple[bool, bool]:
    """Compiled: whether a normalized sample is idle (``has_last``, ``u`` all zero and
    ``y`` equal to ``last_y`` entry by entry: ``not u.any() and np.array_equal(y,
    last_y)``) and whether every entry is finite and within ``max_abs``
    (``np.abs(u).max() <= max_abs and np.abs(y).max() <= max_abs``: a NaN fails)."""
    idle = has_last
    if idle:
        for v in u:
            if v != 0.0:
                idle = False
                break
    if idle:
        for i in range(y.shape[0]):
            if not y[i] == last_y[i]:
                idle = False
                break
    usable = True
    for v in u:
        if not abs(v) <= max_abs:
            usable = False
            break
    if usable:
        for v in y:
            if not abs(v) <= max_abs:
                usable = False
                break
    return idle, usable


class SampleScreening:
    """Mixin: validation, idle and corrupt samples, the outlier guard and re-scaling.

    It needs the host's ``_init_sizes``, ``_step``, ``_fill_output``,
    ``_state_vector``, ``_check_health`` and ``reset`` (see
    :class:`identifiers.core.online.OnlineIdentifier`), and fills the
    counters ``n_skipped``, ``n_outliers`` and ``n_idle``.
    """

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

    def _process(self, u: np.ndarray, y: np.ndarray) -> None:
        # a broken internal state must not raise (or warn) from inside the arithmetic:
        # it is found by the health checks, which roll it back
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            self._process_sample(u, y)

    def _process_sample(self, u: np.ndarray, y: np.ndarray) -> None:
        u = u / self._su
        y = y / self._sy
        last = self._last_y
        idle, usable = _idle_and_usable(u, y, y if last is None else last, last is not None,
                                        self.max_abs)
        if idle:
            # zero input and the same output bit for bit: a plant at rest or a frozen
            # sensor. No information; processing it would only let forgetting erase what
            # was learnt (and a warm-up end on nothing). Skipped without moving the clock.
            self.n_idle += 1
            return
        self._last_y = y
        received_u, received_y = u, y
        # usable: every entry finite and within max_abs; the per-entry masks are only
        # needed for a sample that is not
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
        if self._k % HEALTH_EVERY == 0 or (state is not None and not all_finite(state)):
            self._check_health()

    # ------------------------------------------------------------ health
    def _accept_outlier_run(self, u: np.ndarray, y: np.ndarray) -> None:
        """Hook: a sample beyond the outlier guard is learned from, because the run of
        rejections exceeded :data:`OUTLIER_RUN` (default: nothing to update)."""

    def _admissible(self, u: np.ndarray, y: np.ndarray) -> bool | np.ndarray:
        """Whether a finite, in-range normalized sample may be learned from (hook for
        outlier guards; default: always). A boolean mask over the outputs rejects the
        sample and replaces only the outputs it marks False by their prediction."""
        return True

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
        kept = {k: v for k, v in vars(self).items() if k in KEPT_ON_ROLLBACK and k != "_monitor"}
        self.reset()
        vars(self).update(kept)
        self.n_rescales += 1
        self._good = None
        self._healthy = False
        self._last_fault = (f"rescaled: {range_skips} of the last {WINDOW} samples were beyond "
                            f"max_abs = {self.max_abs:g} times the automatic scales, which are "
                            f"taken again from the next p = {self.p} samples")
        warn_health(f"{type(self).__name__} {self._last_fault}")
