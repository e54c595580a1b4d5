"""The modal structure of :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier`:
its modes found, rebuilt on and tracked, and the regressions physics allows.

:class:`ModalRegression` finds the flexible modes in the kept record at the
end of the warm-up and again with a back-off
(:func:`identifiers.modal.modal_discovery.discover_resonators`),
rebuilds the estimator on them (filter bank, one RLS per sensor group over
the regressors that group may see, the modal tracker) and replays the
record (:class:`identifiers.modal.record_replay.RecordReplay`), and
refines the modes between searches by one variable-projection step of the
:class:`identifiers.modal.modal_tracker.ModalTracker`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from identifiers.core.change_detection import RESOLUTION, ChangeEvent, RegressionGLR
from identifiers.core.modal_basis import Resonator
from identifiers.core.residual_statistics import (
    correlation_time,
    lag_product_step,
    mean_square_step,
)
from identifiers.core.rls import RecursiveLeastSquares
from identifiers.modal.modal_discovery import discover_resonators, merge_resonators
from identifiers.modal.modal_tracker import ModalTracker, TrackerGroup
from identifiers.modal.record_replay import RecordReplay
from spacecraft_conventions import MEASURES

__all__ = ["FILTER_TAIL", "FLEXIBLE_FLOOR", "INITIAL_COVARIANCE", "REBUILD_TOLERANCE",
           "ModalRegression"]

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
#: Samples at the end of a replay over which the Kalman filter runs (the gains
#: learn from the whole replay): its state settles within a few hundred.
FILTER_TAIL = 300


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


class ModalRegression(RecordReplay):
    """Mixin of :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier`:
    the modes (search, rebuild, tracking), the sensor groups' regressions and
    their reaction to a detected change."""

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
        self._fits, self._stated_drifts, self._drift_scales = [], [], None
        for rows_g, cols in self._regression_groups():
            rls = RecursiveLeastSquares(rows_g.size, cols.size, 1.0, INITIAL_COVARIANCE,
                                        regularization=floor[cols], hold=hold[cols],
                                        drift=drift[cols])
            # the prior is the floor: a coupling the data have not excited yet has the
            # variance it settles at when they stop exciting it
            rls.set_covariance(np.diag(np.minimum(INITIAL_COVARIANCE, 1.0 / floor[cols])))
            self._fits.append((rows_g, cols, rls))
            self._stated_drifts.append(drift[cols])
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
        flags = np.array([learn and real for _, _, learn, real in samples], dtype=bool)
        sensitivities = None if dphis is None else (dphis, dfrees)
        self._replay_learning(phis[:tail], y_fs[:tail], flags[:tail],
                              None if dphis is None else (dphis[:tail], dfrees[:tail]))
        self._replay_tail(samples, tail, start_k, phis, y_fs, flags, sensitivities)

    def _track_levels(self, err: np.ndarray, y_f: np.ndarray) -> None:
        """One sample's step of the running mean squares of the gains' a-priori errors
        and of the high-passed signals, and of the errors' lag-1 products (the first
        sample, or pair, sets them)."""
        if self._last_err is not None:
            if self._errlag is None:
                self._errlag = err * self._last_err
            else:
                lag_product_step(self._errlag, err, self._last_err, 0.995, 0.005)
        self._last_err = err.copy()
        if self._resvar is None:
            self._resvar, self._sigvar = err**2, y_f**2
        else:
            mean_square_step(self._resvar, err, 0.995, 0.005)
            mean_square_step(self._sigvar, y_f, 0.995, 0.005)

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

    def _scale_drifts(self) -> None:
        """Each group's drifts at its data's error level: the stated drifts (at the
        sensor-noise variance ``drift_reference``) times ``max(1, drift_reference / v)``,
        ``v`` the running mean square of the group's a-priori errors over the
        high-pass's noise gain (noise and misfit: what the regression cannot explain),
        at least :data:`RESOLUTION` of the high-passed signal on each output and
        ``RESOLUTION**2`` (60 dB of the nominal levels). A rebuild starts as stated."""
        if self.drift_reference is None or self._resvar is None:
            return
        level = np.maximum(self._resvar, RESOLUTION**2 * self._sigvar)
        scales = []
        for (rows, _, rls), stated in zip(self._fits, self._stated_drifts, strict=True):
            v = max(float(np.mean(level[rows])) / self._noise_gain, RESOLUTION**2)
            scales.append(max(1.0, self.drift_reference / v))
            rls.set_drift(stated * scales[-1])
        self._drift_scales = scales

    @property
    def drift_scales(self) -> dict[str, float]:
        """Factor by which each sensor group's regression now walks faster than stated
        (1 where its data are no cleaner than ``drift_reference``; empty before the
        warm-up's end)."""
        if not self._fits:
            return {}
        scales = self._drift_scales or [1.0] * len(self._fits)
        return dict(zip(self.layout.names, scales, strict=True))

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
        # the whole kept record is replayed: its last 150 s alone lost the rigid gain's
        # information from the excitation before them, so that in a quiet closed loop the
        # 200 s rebuild's gain was worse than the nominal guess (docs/results/rl.md)
        if self._try_modes(found, len(self._history)):
            self.n_rediscoveries += 1
        else:
            self.n_searches_rejected += 1

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
        # the gains' a-priori errors stand for the window's residual: how correlated
        # they are says how many independent samples the window holds
        delta = tracker.refine(1.0 if self._errlag is None
                               else correlation_time(self._errlag, self._resvar))
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
