"""Fits off the control path: a fit runs on a worker thread, its model usable after a latency.

A flight computer that samples at 10 Hz cannot stop its loop for a fit of
seconds. :class:`BackgroundFits` is the part of an identifier that fits
(:class:`identifiers.physical.warmup_fit.WarmupFit`'s hosts) which, when a
fit falls due at sample ``T``, forks the identifier (a copy that shares the
record's samples), runs the fit on the fork in a worker thread and goes on
with the model it holds. The fit's result becomes usable at the sample its
latency (:class:`FitTiming`) names: the fork's state, fitted at ``T``, then
takes over, and the samples received since ``T`` are replayed through it
on the worker (its filter catches up on the new model), as a flight computer
would apply a model computed in the background. Until then the held model
flies; taking the caught-up fork over costs the caller a dictionary swap.

The latency is charged in samples, not in wall-clock time, so results are
reproducible to the bit: with a fixed ``latency_s`` the model arrives at the
same sample on every machine (where the thread has not finished by then the
loop waits for it, which costs wall time, never CPU time of the caller).
``measured`` charges instead the fit's own CPU time rounded up to samples (what
this machine would need: machine-dependent). A fit that raises, or whose CPU
time exceeds ``budget_s``, or that has not returned ``timeout_s`` of wall time
after its due sample, is abandoned: the held model keeps flying, the outcome is
in :attr:`BackgroundFits.fit_log` and an
:class:`identifiers.core.health.IdentifierHealthWarning` names it. The worker's
side (the thread, the replay, cancellation) is :mod:`identifiers.core.fit_jobs`.
"""

from __future__ import annotations

import copy
import math
import time
import weakref
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.fit_jobs import FitJob
from identifiers.core.health import warn_health

__all__ = ["FIT_OUTCOMES", "BackgroundFits", "FitTiming"]

#: How a fit ended (``fit_log[i]["outcome"]``): its model was taken, it raised, its CPU
#: time exceeded the budget, or it had not returned ``timeout_s`` after its due sample.
FIT_OUTCOMES = ("adopted", "failed", "over budget", "timed out")


@dataclass(frozen=True)
class FitTiming:
    """When a fit's model becomes usable.

    Attributes
    ----------
    latency_s : float or None
        Simulated seconds from the sample at which the fit falls due to the
        first sample that uses its model (rounded up to samples). None: the
        fit runs at once on the caller's thread (synchronous: an offline
        identification; the simulation waits for it).
    measured : bool
        Charge each fit its own CPU time (rounded up to samples) instead of
        ``latency_s``: what this machine needs, so results depend on the
        machine (default False).
    budget_s : float or None
        CPU seconds a fit may take; a fit over it is abandoned (default None:
        no budget).
    timeout_s : float
        Wall-clock seconds the caller waits for a fit at its due sample before
        abandoning it (default 600: only a fit that hangs meets it).

    Raises
    ------
    ValueError
        For a negative or non-finite latency, budget or timeout.
    """

    latency_s: float | None = None
    measured: bool = False
    budget_s: float | None = None
    timeout_s: float = 600.0

    def __post_init__(self) -> None:
        for name in ("latency_s", "budget_s"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise ValueError(f"FitTiming.{name} must be a finite number of seconds >= 0 "
                                 f"or None, got {value!r}")
        if not (math.isfinite(self.timeout_s) and self.timeout_s > 0):
            raise ValueError(f"FitTiming.timeout_s must be a finite number of seconds > 0, "
                             f"got {self.timeout_s!r}")

    def latency_samples(self, dt: float) -> int:
        """The fixed latency in samples of ``dt`` s, rounded up (0 for a fit at once;
        a measured charge is known only once its fit has run).

        Returns
        -------
        int
            Samples from when the fit falls due to when its model may be used.
        """
        return 0 if self.latency_s is None else math.ceil(round(self.latency_s / dt, 9))

    @property
    def background(self) -> bool:
        """Whether fits run on a worker thread (a latency or a measured charge)."""
        return self.latency_s is not None or self.measured


_AT_ONCE = FitTiming()

class BackgroundFits:
    """Mixin: run the host's fits off the caller's thread with a charged latency.

    The host calls :meth:`_run_fit` with the name of the method that fits (it
    runs on a fork of the host) where a fit falls due, checks
    :attr:`fit_pending` before calling it again, and implements
    :meth:`_fit_abandoned` (what the held state does when a fit is abandoned),
    and names in :attr:`_CONTEXT` what it is told before each ``update`` (a drive
    angle). The host's ``reset`` calls :meth:`_reset_fits`.

    Attributes
    ----------
    fit_timing : FitTiming
    fit_log : list of dict
        One entry per fit: ``action``, ``sample`` (the sample count at which it
        fell due), ``due`` and ``adopted`` (the sample counts from which its
        model was to be and was used; None if never), ``latency_s`` (the
        charge, s), ``cpu_s`` (its CPU time) and ``outcome``
        (:data:`FIT_OUTCOMES`).
    """

    #: What a fork shares with its host instead of copying: containers whose items are
    #: never changed in place (the record's sample tuples).
    _SHARED_ITEMS: tuple[str, ...] = ()
    #: Attributes the host is told before each sample's ``update`` (a drive angle): kept
    #: with each sample received while a fit runs, and set again when it is replayed.
    _CONTEXT: tuple[str, ...] = ()

    @property
    def fit_timing(self) -> FitTiming:
        """When a fit's model becomes usable (:class:`FitTiming`; default: at once)."""
        return self.__dict__.get("_fit_timing", _AT_ONCE)

    @fit_timing.setter
    def fit_timing(self, timing: FitTiming) -> None:
        if not isinstance(timing, FitTiming):
            raise TypeError(f"fit_timing must be a FitTiming, got {type(timing).__name__}")
        self.__dict__["_fit_timing"] = timing

    def _reset_fits(self) -> None:
        self._cancel_fit()
        self._clock = 0
        self.fit_log: list[dict[str, Any]] = []

    def _cancel_fit(self) -> None:
        """Drop the fit running in the background, if any (a fit of an old record)."""
        job = self.__dict__.get("_job")
        if job is not None:
            job.cancel()
            job.release()
        self._job: FitJob | None = None

    @property
    def fit_pending(self) -> bool:
        """True while a fit runs in the background (its model not yet usable)."""
        return self.__dict__.get("_job") is not None

    # ------------------------------------------------------------ hooks
    def _sample_context(self) -> tuple:
        """The values of :attr:`_CONTEXT` now."""
        return tuple(getattr(self, name) for name in self._CONTEXT)

    def _restore_context(self, context: tuple) -> None:
        """Set the values :meth:`_sample_context` returned."""
        for name, value in zip(self._CONTEXT, context, strict=True):
            setattr(self, name, value)

    def _fit_abandoned(self, action: str) -> None:
        """The fit ``action`` was abandoned: put the held state where it would have been
        had the fit failed (default: nothing)."""

    # ------------------------------------------------------------ fitting
    def _fork(self) -> Any:
        """A copy of this identifier sharing the items of :attr:`_SHARED_ITEMS`."""
        memo: dict[int, Any] = {}
        for name in self._SHARED_ITEMS:
            for item in self.__dict__.get(name) or ():
                memo[id(item)] = item
        return copy.deepcopy(self, memo)       # launched only while no fit runs

    def _run_fit(self, action: str) -> None:
        """Fit now (synchronous timing) or launch ``action`` on a fork in the background."""
        timing = self.fit_timing
        sample = self.n_samples
        if not timing.background:
            start = time.thread_time()
            getattr(self, action)()
            self.fit_log.append({"action": action.strip("_"), "sample": sample, "due": sample,
                                 "adopted": sample, "latency_s": 0.0,
                                 "cpu_s": time.thread_time() - start, "outcome": "adopted"})
            return
        due = None if timing.measured else \
            max(sample, self._clock) + timing.latency_samples(self.dt)
        job = FitJob(action, sample, due)
        fork = self._fork()
        self._job = job
        # a fit whose identifier is gone is not wanted either (detached once the fit is
        # taken over or dropped, so no finished fit stays referenced)
        job.finalizer = weakref.finalize(self, job.cancel)
        job.start(fork, self.dt, f"{type(self).__name__} fit")

    def _due(self, job: FitJob) -> bool:
        """Whether the fit's model is usable from the coming sample (measured: once the fit
        has finished and its own CPU time, in samples, has passed since it fell due)."""
        return job.due is not None and self.n_samples >= job.due

    def _adopt(self) -> None:
        """The pending fit's state takes over and catches up on the samples since (or, for
        an abandoned fit, the held state goes on)."""
        job, self._job = self._job, None
        job.release()
        timing = self.fit_timing
        entry = {"action": job.action.strip("_"), "sample": job.sample, "due": job.due,
                 "adopted": None, "latency_s": (job.due - job.sample) * self.dt,
                 "cpu_s": float("nan"), "outcome": "adopted"}
        try:
            fork, cpu, error = job.future.result(timeout=timing.timeout_s)
        except FutureTimeout:
            job.cancel()                  # it stops at its next cancellation point
            fork, cpu, error = None, float("nan"), None
            entry["outcome"] = "timed out"
        else:
            entry["cpu_s"] = cpu
            if error is not None:
                entry["outcome"] = "failed"
            elif timing.budget_s is not None and cpu > timing.budget_s:
                entry["outcome"] = "over budget"
        log = self.fit_log
        if entry["outcome"] != "adopted":
            log.append(entry)
            self._fit_abandoned(job.action)
            what = f"{type(error).__name__}: {error}" if error is not None else (
                f"{entry['cpu_s']:.2f} s of CPU against a budget of {timing.budget_s} s"
                if entry["outcome"] == "over budget"
                else f"no result {timing.timeout_s:g} s after its due sample")
            warn_health(f"{type(self).__name__}: the fit due at sample {job.sample} was "
                        f"abandoned ({entry['outcome']}: {what}); the held model flies on")
            return
        # the fork, fitted when the fit fell due and caught up since on the worker
        # what the caller told this identifier about the coming sample (a drive angle),
        # which the fork, caught up to the sample before, does not know yet
        now, context = self.n_samples, self._sample_context()
        self.__dict__.clear()
        self.__dict__.update(fork.__dict__)
        self.fit_timing, self.fit_log = timing, log
        entry["adopted"] = now
        log.append(entry)
        # a measured charge can be taken later than its due sample: the samples past it
        # are replayed here (none with a fixed latency, which is taken at its due sample)
        for u, y, sample_context in job.remaining():
            self._restore_context(sample_context)
            self.update(u, y)
        self._restore_context(context)

    def update(self, u: ArrayLike, y: ArrayLike) -> None:
        job = self.__dict__.get("_job")
        if job is not None and self._due(job):
            self._adopt()
        super().update(u, y)          # type: ignore[misc]
        job = self.__dict__.get("_job")
        if job is not None and job.sample < self.n_samples:
            # a sample the pending fit's fork has not seen: the worker replays it
            job.receive(np.array(u, dtype=float), np.array(y, dtype=float),
                        self._sample_context())
