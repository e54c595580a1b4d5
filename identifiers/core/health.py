"""Health of a streaming identifier: detect a broken internal state, roll back, report.

An online estimator that runs for hours meets what a test record never
shows: an overflow in a state that drifts, a covariance that rounding has
made indefinite, a stretch of data with no information at all. Each of
these leaves the estimator *finite-looking but wrong*, and a model read
from it goes stale without a word. :class:`identifiers.core.online.OnlineIdentifier`
therefore checks its own internal state (:func:`state_problem`) at a fixed
period, keeps a copy of the last state that passed, and when a check fails
rolls back to that copy, counts the fault and reports it in
:class:`IdentifierHealth`. An identifier whose faults repeat, or that has no
good copy to return to, restarts its estimator and says so: ``health.healthy``
is False, and its ``model`` is None (with an :class:`IdentifierHealthWarning`)
until a check passes again.

What a check looks at (:func:`state_problem`): every recursive-least-squares
estimate and Kalman-filter state (finite), every covariance (finite,
positive definite by a Cholesky factorization for an RLS, positive
semi-definite for a Kalman filter, whose covariance is singular along states
a model leaves inert) and the exported model matrices and state (finite). A
finite model learnt from nothing (:func:`degenerate`: a zero A or C) is not a
broken state but no model either: it is not exported, and the health report
says so. What the *data* show (a stuck sensor, most samples skipped) is the
:class:`identifiers.core.data_monitor.DataMonitor`'s part.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import spacecraft_conventions
from identifiers.core.kalman import KalmanPredictor
from identifiers.core.rls import RecursiveLeastSquares

__all__ = ["HEALTH_EVERY", "MAX_ROLLBACKS", "IdentifierHealth", "IdentifierHealthWarning",
           "degenerate", "state_problem", "warn_health"]

#: Samples between full health checks (Cholesky of every covariance; 10 s at
#: dt = 0.1 s). The rollback copy is taken at each passing check.
HEALTH_EVERY = 100
#: Faults within :data:`HEALTH_EVERY` x 10 samples after which the identifier stops
#: rolling back (the fault comes back from the data) and restarts its estimator.
MAX_ROLLBACKS = 3


class IdentifierHealthWarning(UserWarning):
    """A streaming identifier found its internal state broken and could not roll back."""


#: Source folders whose frames a health warning skips, so that it points at the caller.
_INTERNAL = (str(Path(__file__).parents[1]), str(Path(spacecraft_conventions.__file__).parent))


def warn_health(message: str) -> None:
    """Issue an :class:`IdentifierHealthWarning` attributed to the first caller outside
    the identifiers package (the user's ``update``, ``fit`` or ``model`` line)."""
    frame, level = sys._getframe(1), 2
    while frame is not None and frame.f_code.co_filename.startswith(_INTERNAL):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, IdentifierHealthWarning, stacklevel=level)


@dataclass(frozen=True)
class IdentifierHealth:
    """What an identifier reports about itself (``identifier.health``).

    Attributes
    ----------
    healthy : bool
        False after the estimator had to be restarted (no good state to
        return to, repeated faults, or automatic scales taken again), until
        its next check passes (the identifier's ``model`` is None
        meanwhile), and while the data show a fault (``faults``; the model
        is still returned then: it is what the data allow).
    samples : int
        Samples received.
    skipped : int
        Samples not learned from (non-finite, beyond ``max_abs``, outliers).
    outliers : int
        Of those, the ones the outlier guard rejected.
    idle : int
        Samples passed over as carrying no information (zero input, output
        unchanged bit for bit).
    rollbacks : int
        Faults of the internal state repaired by returning to the last
        good copy.
    restarts : int
        Faults that restarted the estimator.
    rescales : int
        Restarts because the data left the level the automatic scales were
        taken at by more than ``max_abs`` (the scales are taken again).
    faults : tuple of str
        What the data show now (:class:`identifiers.core.data_monitor.DataMonitor`:
        a stuck, clipped or noisier output, most samples skipped, an input
        that stopped exciting), one message each; empty when none.
    last_fault : str or None
        What the last failed check found (e.g. ``"covariance 2 not positive
        definite"``), None if none has failed.
    last_good_sample : int or None
        Sample count at the last passing check (the copy a rollback returns
        to), None before the first.
    last_good_time_s : float or None
        The same as a time, s (``last_good_sample * dt``).
    """

    healthy: bool
    samples: int
    skipped: int
    outliers: int
    idle: int
    rollbacks: int
    restarts: int
    rescales: int
    faults: tuple[str, ...]
    last_fault: str | None
    last_good_sample: int | None
    last_good_time_s: float | None


def _estimators(obj: Any) -> Iterator[Any]:
    """The RLS estimators and Kalman filters held by ``obj``'s attributes, directly or
    in a list or tuple (one level down)."""
    kinds = (RecursiveLeastSquares, KalmanPredictor)
    for value in vars(obj).values():
        if isinstance(value, kinds):
            yield value
        elif isinstance(value, (list, tuple)):
            for item in value:
                if isinstance(item, kinds):
                    yield item
                elif isinstance(item, tuple):
                    yield from (v for v in item if isinstance(v, kinds))


def _positive_definite(p: np.ndarray) -> bool:
    """Finite, positive diagonal, and a Cholesky factor exists."""
    if not np.isfinite(p).all() or np.any(np.diag(p) <= 0):
        return False
    try:
        np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        return False
    return True


def _positive_semidefinite(p: np.ndarray) -> bool:
    """Finite, symmetric to rounding, no eigenvalue below -1e-9 of the largest diagonal
    entry (a Kalman filter's covariance is singular along states the model leaves
    inert)."""
    if not np.isfinite(p).all():
        return False
    scale = max(float(np.abs(np.diag(p)).max(initial=0.0)), 1e-300)
    if np.abs(p - p.T).max(initial=0.0) > 1e-9 * scale:
        return False
    return bool(np.linalg.eigvalsh(0.5 * (p + p.T)).min(initial=0.0) >= -1e-9 * scale)


def degenerate(matrices: tuple | None) -> str | None:
    """Why a finite model ``(A, B, C, D, K)`` is no model at all (A or C zero), or None.

    Returns
    -------
    str or None
        A sentence naming the zero matrix, or None.
    """
    if matrices is None:
        return None
    for name, index in (("A", 0), ("C", 2)):
        if not np.asarray(matrices[index]).any():
            return f"degenerate: the model's {name} is zero (nothing learnt)"
    return None


def state_problem(identifier: Any, matrices: tuple | None, state: np.ndarray | None) -> str | None:
    """What is wrong with an identifier's internal state, or None.

    Parameters
    ----------
    identifier : OnlineIdentifier
        Its RLS estimators and Kalman filters are found among its attributes.
    matrices : tuple of ndarray or None
        The model ``(A, B, C, D, K)`` it would export now.
    state : ndarray or None
        Its state estimate.

    Returns
    -------
    str or None
        A sentence naming the problem, or None for a healthy state.
    """
    for i, est in enumerate(_estimators(identifier)):
        if isinstance(est, RecursiveLeastSquares):
            if not np.isfinite(est.theta).all():
                return f"estimate {i} not finite"
            if not _positive_definite(est.P):
                return f"covariance {i} not positive definite"
        else:
            if est.x is not None and not np.isfinite(est.x).all():
                return f"filter state {i} not finite"
            if not _positive_semidefinite(est.P):
                return f"filter covariance {i} not positive semi-definite"
    if matrices is not None and not all(np.isfinite(m).all() for m in matrices
                                        if m is not None):
        return "model not finite"
    if state is not None and not np.isfinite(state).all():
        return "state not finite"
    return None
