"""The estimator's own health: snapshots, rollback and restart.

:class:`HealthGuard` is the part of
:class:`identifiers.core.online.OnlineIdentifier` that watches the
internal state (every :data:`identifiers.core.health.HEALTH_EVERY` samples
and whenever the state vector is not finite), keeps a copy of the last good
state, rolls back to it after a fault and restarts the estimator when the
faults repeat; its report is :attr:`HealthGuard.health`
(:class:`identifiers.core.health.IdentifierHealth`).
"""

from __future__ import annotations

import copy
import pickle
from collections import deque
from typing import Any

import numpy as np

from identifiers.core.health import (
    HEALTH_EVERY,
    MAX_ROLLBACKS,
    IdentifierHealth,
    degenerate,
    state_problem,
    warn_health,
)

__all__ = ["KEPT_ON_ROLLBACK", "HealthGuard"]

#: Attributes that a rollback keeps at their current values: the counters,
#: the health record itself and the sample clock.
KEPT_ON_ROLLBACK = ("n_samples", "n_skipped", "n_outliers", "n_idle", "n_rollbacks",
                     "n_restarts", "n_rescales",
                     "_last_fault", "_fault_samples", "_good", "_k", "_healthy", "_warned",
                     "_monitor", "_range_skips", "_warned_faults",
                     # a fit running in the background goes on across a rollback
                     "_job", "_clock", "fit_log", "_fit_timing")


class HealthGuard:
    """Mixin: the internal state's health checks, rollback and restart.

    The host provides ``_matrices``, ``_current_state``, ``reset``, ``ready``,
    ``n_samples``, ``p``, ``dt`` and the class attributes ``_SIGNAL_STATE``
    and ``_SHARED_ITEMS`` (see :class:`identifiers.core.online.OnlineIdentifier`).
    """

    def _reset_health(self) -> None:
        self.n_rollbacks = 0
        self.n_restarts = 0
        self.n_rescales = 0
        self._warned_faults: set[tuple[str, int | None]] = set()
        self._last_fault: str | None = None
        self._fault_samples: deque[int] = deque(maxlen=MAX_ROLLBACKS + 1)
        # (n_samples, the state's copy from _snapshot)
        self._good: tuple[int, tuple[bytes, dict[str, Any]]] | None = None
        self._healthy = True
        self._warned = False

    def _state_vector(self) -> np.ndarray | None:
        """The estimator's own state vector, checked for finiteness every sample
        (default: the ``_x`` attribute, if any)."""
        return vars(self).get("_x")

    def _health_problem(self) -> str | None:
        """What is wrong with the internal state now
        (:func:`identifiers.core.health.state_problem`)."""
        mats = self._matrices() if self._k >= self.warmup else None
        state = self._current_state() if mats is not None else None
        return state_problem(self, mats, state)

    def _snapshot(self) -> tuple[bytes, dict[str, Any]]:
        """A copy of the estimator state: every attribute but :data:`KEPT_ON_ROLLBACK`,
        pickled, and the containers of :attr:`_SHARED_ITEMS` copied shallowly (their
        items are never changed in place, so the copy shares them).

        Pickling the state costs about a quarter of a deep copy of it (0.5 against
        2 ms for the default identifier), and the snapshot is taken every
        :data:`identifiers.core.health.HEALTH_EVERY` samples while it is read only at
        a rollback. The shared containers must be top-level attributes referenced
        nowhere else in the state (a reference elsewhere would be restored as a
        copy of its own)."""
        state = {k: v for k, v in vars(self).items()
                 if k not in KEPT_ON_ROLLBACK and k not in self._SHARED_ITEMS}
        shared = {k: copy.copy(v) for k, v in vars(self).items() if k in self._SHARED_ITEMS}
        return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL), shared

    def _restored(self, snapshot: tuple[bytes, dict[str, Any]] | None = None
                  ) -> dict[str, Any]:
        """The state of ``snapshot`` (default: the last good one), as new objects (the
        snapshot stays as it was, for a later rollback to the same point)."""
        blob, shared = self._good[1] if snapshot is None else snapshot
        state = pickle.loads(blob)
        state.update({k: copy.copy(v) for k, v in shared.items()})
        return state

    def _check_health(self) -> None:
        """Check the internal state; keep a copy if it is good, roll back if it is not.

        A fault is repaired by returning to the last good copy (the samples
        since are lost; learning pauses until the past window holds only
        samples after the rollback). More than :data:`identifiers.core.health.MAX_ROLLBACKS`
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
                    if k in KEPT_ON_ROLLBACK or (k in self._SIGNAL_STATE and (
                        not isinstance(v, np.ndarray) or np.all(np.isfinite(v))))}
            vars(self).update(self._restored())
            vars(self).update(kept)
            self.n_rollbacks += 1
            self._quiet = max(self._quiet, self.p + 1)
            self._after_rollback()
        else:
            kept = {k: v for k, v in vars(self).items() if k in KEPT_ON_ROLLBACK}
            self.reset()
            vars(self).update(kept)
            self.n_restarts += 1
            self._good = None
            self._healthy = False

    def _after_rollback(self) -> None:
        """Hook run after a rollback (default: nothing more)."""

    @property
    def health(self) -> IdentifierHealth:
        """The identifier's report on itself
        (:class:`identifiers.core.health.IdentifierHealth`)."""
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

    def _exportable(self) -> bool:
        """False (with one :class:`identifiers.core.health.IdentifierHealthWarning`) while
        the estimator is restarting after a fault; :attr:`model` and :meth:`fit` alike."""
        if not self._healthy:
            if not self._warned:
                self._warned = True
                warn_health(f"{type(self).__name__} restarted its estimator after a fault "
                            f"({self._last_fault}); no model until it is healthy again "
                            "(see .health)")
            return False
        return True
