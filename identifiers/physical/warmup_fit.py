"""What the identifiers that fit to their warm-up and then hold the fit share.

:class:`WarmupFit` records the samples until the warm-up is over, calls the
host's ``_fit_record`` (retried once the record is half a warm-up longer when it
fails: each attempt is a nonlinear fit of seconds), then runs a Kalman filter
on the held model (:class:`identifiers.core.state_filter.ModelFilter`),
its measurement noise the fit's residual per output and its process noise an
unmodelled torque.

A host with ``refit_on_change`` set also watches the filter's innovations
with a CUSUM test (:class:`identifiers.core.change_detection.InnovationCUSUM`,
alarm level :data:`CHANGE_THRESHOLD`, allowance :data:`CHANGE_DRIFT`; the test
runs on across accumulating refits): when it fires, the held model keeps flying
while a new record of ``warmup`` samples is taken, and the host's
``_fit_record`` then fits that record (it may start from the held fit). A host
that ``judges_changes`` (``_held_misfit``) has the alarm confirmed first: the
refit replaces the held model only where it explains the record clearly better
(:func:`identifiers.core.change_detection.misfit_confirms_change`) than
the held model refined on the whole accumulated record does; otherwise that
refinement flies and the record stays (where the refit fails, the held model).
Each alarm is reported in :attr:`WarmupFit.events`, its ``confirmed`` flag set by
the outcome. So the fit is renewed where the data say the plant moved, not on a
clock.

A host with ``accumulate`` set lets the information grow: it keeps the last
``max_record`` samples and fits them again, the held model refined first, each
time as many samples have come since the last fit as that fit used (30 s, 60 s,
120 s, ...), then every ``max_record`` samples. A refit that knows the rigid-body
gain less well than the held fit is kept out, so information is not lost.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from typing import Any

import numpy as np

from identifiers.core.background import BackgroundFits
from identifiers.core.change_detection import (
    ChangeEvent,
    InnovationCUSUM,
    misfit_confirms_change,
)
from identifiers.core.kalman import KalmanPredictor
from identifiers.core.state_filter import ModelFilter

__all__ = ["CHANGE_DRIFT", "CHANGE_THRESHOLD", "WarmupFit"]

#: The change test's alarm level and allowance (:class:`InnovationCUSUM`'s
#: ``threshold`` and ``drift``), more sensitive than that test's defaults (40, 0.5)
#: because each alarm is confirmed before it replaces anything: with them, open
#: loop, the drive-scheduled fit finds both dockings of the docking scenario (the
#: defaults, which restarted after each accumulating refit, missed the second); on
#: noise-free records of a plant that does not change it raises alarms on 8 of 10
#: and confirms none (gain 0.00-0.02 % off at the end; docs/results/identification.md).
CHANGE_THRESHOLD = 20.0
CHANGE_DRIFT = 0.25


class WarmupFit(BackgroundFits, ModelFilter):
    """Mixin: the record, the fit's hold and the filter on it.

    The host provides ``process_torque`` (N m per axis), ``refit_on_change``
    (bool), ``_fit_record() -> bool`` (fit the record, set ``held_fit`` and ``_mats``,
    start the filter with :meth:`_start_filter`; False when it failed, with
    ``held_fit`` and ``_mats`` as they were) and may override :meth:`_record_item`
    (what each sample adds to the record), :meth:`_follow` (run before the
    filter's update once the model is held) and :meth:`_held_misfit` (the held
    model's misfit of a refit's record, which confirms a change). During a refit's record
    :attr:`refit_start` holds the filter's state at the record's first sample
    (a start for the refit); it is None otherwise. :attr:`accumulating_refit`
    is True while ``_fit_record`` runs for an accumulating refit (the held model's
    record grown, no change detected), so the host may refit more cheaply. Every fit
    runs through :class:`identifiers.core.background.BackgroundFits` (the host's
    ``fit_timing``: at once by default, or off the caller's thread with a latency).
    """

    refit_on_change: bool = False
    #: Whether the host judges an alarm (:meth:`_held_misfit`) before a refit replaces
    #: the held model.
    judges_changes: bool = False
    accumulate: bool = False
    max_record: int = 1200

    _SHARED_ITEMS = ("_pending", "_record", "_history", "_priors")

    def reset(self) -> None:
        super().reset()
        self._reset_fits()
        self.held_fit: Any = None
        self._record: list[tuple] = []
        self._retry_at = 0
        self._kf: KalmanPredictor | None = None
        self._mats: tuple[np.ndarray, ...] | None = None
        self._q = self._r = None
        self._seen: np.ndarray | None = None
        self._events: list[ChangeEvent] = []
        self._detector: InnovationCUSUM | None = None
        self.refit_start: np.ndarray | None = None
        self.accumulating_refit = False
        self.n_refits = 0
        self.n_refits_kept_out = 0
        self.n_refits_skipped = 0
        self.n_alarms_unconfirmed = 0
        # the accumulating refits: the last max_record samples and the filter's prior
        # state at each (NaN before the first fit), the sample count at which the
        # held fit's record started, its length and the samples since
        self._history: deque = deque(maxlen=self.max_record)
        self._priors: deque = deque(maxlen=self.max_record)
        self._count = 0
        self._fit_origin = 0
        self._fit_length = 0
        self._since_fit = 0

    @property
    def events(self) -> list[ChangeEvent]:
        """The change test's alarms (samples counted from the first update; empty
        without ``refit_on_change``), each ``confirmed`` True where its refit
        replaced the held model, False where the data after it did not confirm a
        change, None while its record is being taken (or where the host cannot
        judge, or the refit failed)."""
        return list(self._events)

    @property
    def refitting(self) -> bool:
        """True while the record for a refit after a detected change is being taken."""
        return self.refit_start is not None

    def restart(self) -> None:
        """A new record of the same plant: keep the fit, restart the state's filter
        (``x = 0`` with a vague covariance) and the change test, drop a refit's
        unfinished record; before the fit, keep recording."""
        self._cancel_fit()                 # a fit of the old record is not wanted
        if self._kf is not None:
            self._kf = KalmanPredictor(self.n, initial_covariance=1.0)
            # a refit's record, and the change test's calibration, belong to the old record
            self._record, self.refit_start = [], None
            self._history.clear()
            self._priors.clear()
            self._since_fit = 0
            self._watch()

    def _allocate(self, r: int, m: int) -> None:
        """Nothing before the fit: the record grows sample by sample."""

    def _record_item(self, u: np.ndarray, y: np.ndarray) -> tuple:
        return (u.copy(), y.copy())

    def _follow(self) -> None:
        """Hook before each filter update of the held model (default: nothing)."""

    def _filter_input(self, u: np.ndarray) -> np.ndarray:
        """The input the state's filter propagates for the normalized torques ``u``
        ((3,) or (T, 3)); default ``u`` (a host adds what else its fit says acted)."""
        return u

    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        seen = self._seen if self._seen is not None else np.ones(y.size, dtype=bool)
        y = np.where(seen, y, np.nan)
        self._count += 1
        # this sample's record item, made once where it is kept beyond this step
        item = self._record_item(u, y) if self.accumulate else None
        if self.accumulate:
            self._history.append(item)
        if self.held_fit is None:
            if self.accumulate:
                self._priors.append(np.full(self.n, np.nan))
            self._record.append(item or self._record_item(u, y))
            if len(self._record) >= max(self.warmup, self._retry_at) and not self.fit_pending:
                self._run_fit("_first_fit")
            return
        self._follow()
        a, b, c, _, _ = self._mats
        # the filter's prior of this sample: the refit's start if the test fires on it
        prior = self._kf.x.copy() if self._detector is not None or self.accumulate else None
        self._kf.update(a, b, c, self._q, self._r, self._filter_input(u), y)
        if self.accumulate:
            self._priors.append(prior)
        self._since_fit += 1
        if self.refit_start is not None:
            self._record.append(item or self._record_item(u, y))
            if len(self._record) >= self.warmup and not self.fit_pending:
                self._run_fit("_refit")
            return
        if self.accumulate and self._since_fit >= min(self._fit_length, self.max_record):
            if not self.fit_pending:
                self._run_fit("_refit_accumulated")
            return
        if self._detector is not None and learn and np.isfinite(y).all():
            event = self._detector.update(self._kf.innovation, self._kf.innovation_covariance)
            if event is not None:
                # the test counts only the samples it was fed: stamp the event with
                # this identifier's sample count
                sample = self.n_samples - 1
                self._events.append(ChangeEvent(sample=sample,
                                                onset=sample - (event.sample - event.onset),
                                                time=sample * self.dt,
                                                statistic=event.statistic))
                # the record for the refit starts with this sample: the filter's
                # prior of it is the refit's start
                self.refit_start = prior
                self._record = [item or self._record_item(u, y)]

    def _first_fit(self) -> None:
        """Fit the warm-up's record; where it fails, record on and try again once the
        record is half a warm-up longer."""
        length = len(self._record)
        if self._fit_record():
            self._fitted(self._count - length, length)
            self._watch()
        else:
            self.held_fit = None
            self._fit_abandoned("_first_fit")

    def _fit_abandoned(self, action: str) -> None:
        """The held state after a fit that did not come (failed or abandoned)."""
        if action == "_first_fit":
            self._retry_at = len(self._record) + max(self.warmup // 2, 1)
        else:
            self._record, self.refit_start, self._since_fit = [], None, 0
            self._watch(keep=action == "_refit_accumulated")

    def _refit(self) -> None:
        """Fit the record taken since the detected change and judge the alarm.

        Without a judge (:meth:`_held_misfit` None) the refit replaces the held
        model. With one, the alarm is confirmed where the refit explains its record
        clearly better (:func:`misfit_confirms_change`) than the model that holds no
        change does: the held model fitted again to its accumulated record with the
        alarm's record in it (``accumulate``; otherwise the held model as it is). A
        confirmed change restarts the accumulating record with the refit's (the
        samples before the change are another plant's); an unconfirmed one keeps that
        joint refit, an accumulating refit, where it knows the rigid-body gain at least
        as well as the held model. A failed refit keeps the held model and judges
        nothing."""
        length, record, start = len(self._record), self._record, self.refit_start
        held = dict(self.__dict__)
        if not self._fit_record():
            self.__dict__.update(held)
        else:
            after = dict(self.__dict__)
            joint = misfit = None
            if self.judges_changes:
                joint = self._joint_refit(held)
                self._record, self.refit_start = record, start
                misfit = self._held_misfit()
            if misfit is None or self._confirms(misfit, length, after["held_fit"]):
                self.__dict__.update(after)
                self.n_refits += 1
                if misfit is not None:
                    self._events[-1] = replace(self._events[-1], confirmed=True)
                if self.accumulate:
                    self._history.clear()
                    self._history.extend(record)
                    self._priors.clear()
                    self._priors.extend([np.full(self.n, np.nan)] * length)
                self._fitted(self._count - length, length)
            else:
                self.__dict__.update(held if joint is None else joint)
                self.n_alarms_unconfirmed += 1
                self._events[-1] = replace(self._events[-1], confirmed=False)
                if joint is not None:
                    self.n_refits += 1
                    self._fitted(self._count - len(self._history), len(self._history))
        self._record = []
        self.refit_start = None
        self._watch()

    def _joint_refit(self, held: dict) -> dict | None:
        """From the held state ``held``: the held model refined on the accumulated
        record (the alarm's record its last part), as an accumulating refit; the
        resulting state, or None where it fails or knows the gain less well (the
        identifier is left in the held state then)."""
        self.__dict__.update(held)
        if not self.accumulate:
            return None
        if self._fit_accumulated(self._stage_accumulated()):
            return dict(self.__dict__)
        self.__dict__.update(held)
        return None

    def _stage_accumulated(self) -> float:
        """Make the accumulated record the one to fit, from the held model's state at
        its first sample; return the held fit's relative gain standard deviation."""
        start = self._priors[0]
        if self._count - len(self._history) == self._fit_origin:
            start = self._fit_initial_state()     # the held fit's record starts there too
        self.refit_start = start if start is not None and np.isfinite(start).all() \
            else None
        self._record = list(self._history)
        return self._gain_relative_std()

    def _fit_accumulated(self, held_std: float) -> bool:
        """Fit the staged record as an accumulating refit; True where the fit worked
        and knows the rigid-body gain at least as well as ``held_std`` says the held
        fit did (the caller restores the held state otherwise)."""
        self.accumulating_refit = True
        try:
            fitted = self._fit_record()
        finally:
            self.accumulating_refit = False
        return fitted and self._gain_relative_std() <= held_std

    def _held_misfit(self) -> float | None:
        """The held model's misfit of the refit's record (``_record`` from
        ``refit_start``), in the units of the fit's ``cost``, for a host that
        ``judges_changes``; None where it cannot say, and the refit then replaces the
        held model unconfirmed."""
        return None

    def _confirms(self, misfit: float, length: int, fit: Any) -> bool:
        """Whether ``fit`` (the refit) explains its record clearly better than the
        no-change model's ``misfit`` of it (``fit``'s ``cost`` and ``noise_floor``
        over ``length`` samples of every output)."""
        return misfit_confirms_change(misfit, float(fit.cost),
                                      max(float(getattr(fit, "noise_floor", 0.0)), 0.0),
                                      length * self.n_outputs)

    def _refit_accumulated(self) -> None:
        """Fit the last ``max_record`` samples again, the held model refined first from
        its state at the record's first sample; keep the held model if the fit fails
        or knows the rigid-body gain less well (a record that no longer holds the
        warm-up's excitation can), and skip the fit where the host predicts that
        (:meth:`_refit_worthwhile`; ``n_refits_skipped``)."""
        length = len(self._history)
        origin = self._count - length
        held_std = self._stage_accumulated()
        if not self._refit_worthwhile(held_std):
            # what a refit the guard keeps out leaves, without fitting
            self._record = []
            self._since_fit = 0
            self.n_refits_skipped += 1
            self.refit_start = None
            self._watch(keep=True)
            return
        # what the fit replaces (the held fit, its matrices, its filter: the host's as
        # well), restored if the refit is kept out
        held = dict(self.__dict__)
        if self._fit_accumulated(held_std):
            self.n_refits += 1
            self._fitted(origin, length)
        else:
            self.__dict__.update(held)
            self._record = []
            self._since_fit = 0
            self.n_refits_kept_out += 1
        self.refit_start = None
        self._watch(keep=True)

    def _refit_worthwhile(self, held_std: float) -> bool:
        """Whether to run the accumulating refit of ``_record`` (from ``refit_start``)
        at all; the host may predict that it would be kept out (default True)."""
        return True

    def _gain_relative_std(self) -> float:
        """The held fit's relative standard deviation of the rigid-body gain (inf if the
        host reports none)."""
        estimate = getattr(self, "rigid_gain", None)
        return float("inf") if estimate is None else float(estimate.relative_std())

    def _fitted(self, origin: int, length: int) -> None:
        """A fit of ``length`` samples from sample ``origin`` (own count) is held."""
        self._fit_origin, self._fit_length, self._since_fit = origin, length, 0

    def _fit_initial_state(self) -> np.ndarray | None:
        """The held fit's state at its record's first sample (physical units), or None;
        the host's fit object carries it as ``initial_state``."""
        state = getattr(self.held_fit, "initial_state", None)
        return None if state is None else np.asarray(state, dtype=float)

    def _watch(self, keep: bool = False) -> None:
        """A fresh change test on the (new) held model's innovations, from the next
        sample on; with ``keep`` (after an accumulating refit, which a change in the
        plant does not explain) the running test goes on."""
        if not self.refit_on_change:
            self._detector = None
        elif not keep or self._detector is None:
            self._detector = InnovationCUSUM(threshold=CHANGE_THRESHOLD, drift=CHANGE_DRIFT,
                                             dt=self.dt)

    def _start_filter(self, x0: np.ndarray, u: np.ndarray, y: np.ndarray,
                      fitted: np.ndarray) -> None:
        """Empty the record and run the filter over it from the fitted initial state
        ``x0``: ``u``, ``y`` and the fit's outputs ``fitted`` normalized, (T, .)."""
        self._r = np.maximum(np.nanmean((y - fitted) ** 2, axis=0), 1e-12)
        self._record = []
        self._kf = KalmanPredictor(self.n, initial_covariance=1e-6)
        self._kf.x = x0.copy()
        a, b, c, _, _ = self._mats
        for uk, yk in zip(self._filter_input(u), y, strict=True):
            self._kf.update(a, b, c, self._q, self._r, uk, yk)

    @property
    def ready(self) -> bool:
        """True once the model is fitted."""
        return self.held_fit is not None and super().ready
