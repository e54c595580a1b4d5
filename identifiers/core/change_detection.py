"""Detecting abrupt changes of a plant from the residuals of its model.

Two tests:

* :class:`RegressionGLR` watches a linear regression ``y = Theta phi``
  estimated recursively: a change of ``Theta`` in the span of some
  regressors (the rigid-body gain, after a docking) shows as a correlation
  between the a-priori errors and those regressors, which the generalized
  likelihood-ratio statistic accumulates over a short window. It detects a
  20 % inertia change that one-step innovations, absorbed sample by sample
  by a Kalman filter, never reveal.
* :class:`InnovationCUSUM` is the generic test on a filter's normalized
  innovations.

and a confirmation, :func:`misfit_confirms_change`: an alarm is a change only
if a model fitted to the data after it explains them clearly better than the
model held before it (a test that knows the data's misfit, where the
innovation tests know only its level).

InnovationCUSUM
---------------
A structural change (a docking, a capture) makes the current model wrong:
its one-step innovations grow beyond what their predicted covariance
allows. :class:`InnovationCUSUM` is Page's CUSUM test on the normalized
innovation energy ``s_k = e_k^T S_k^-1 e_k / m`` (about 1 while the model
is right)::

    g_k = max(0, g_{k-1} + s_k - 1 - drift),      alarm when g_k > threshold

The statistic is scaled by a slowly learned factor (the running mean of
``s_k``, clipped at :data:`CALM` times itself), so a filter whose ``S_k``
is consistently optimistic or pessimistic does not raise alarms by itself;
after an alarm the test waits ``holdoff`` samples before it can fire again.
Each alarm is recorded as a :class:`ChangeEvent` with the estimated start of
the change (the last time ``g`` was zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["CALM", "CONFIRM_FACTOR", "RESOLUTION", "ChangeEvent", "InnovationCUSUM",
           "RegressionGLR", "misfit_confirms_change", "resolved_variance"]

#: Smallest relative error (of the high-passed signal's RMS) the structure-aware
#: identifiers treat as evidence: 1e-3, a 60 dB signal-to-error ratio. Smaller
#: errors are no evidence of a change, and no finer a noise level for the
#: regressions' drifts.
RESOLUTION = 1e-3


def resolved_variance(error: np.ndarray, signal: np.ndarray) -> np.ndarray:
    """``max(error, RESOLUTION^2 signal)`` elementwise: an error variance no smaller
    than :data:`RESOLUTION` of the signal's mean square allows, below which an error
    is no evidence (the variance a change test or a noise level divides by).

    Returns
    -------
    ndarray
        The floored variance, the shape of ``error``.
    """
    return np.maximum(error, RESOLUTION**2 * signal)

#: The calm level of a statistic is tracked by a running mean of every value
#: clipped at this multiple of the level: nearly unbiased for the
#: chi-square-like statistics here (5 % low for an exponential), while a
#: change cannot raise it much. Updating only in calm periods (values below
#: the level) would drift it down to its lower tail and raise false alarms.
CALM = 3.0

#: An alarm is confirmed when the held model's misfit of the data after it, above
#: the noise floor, is more than this multiple of a refit's
#: (:func:`misfit_confirms_change`). Measured on the drive-scheduled fit's 30 s
#: refits after its CUSUM's alarms (open loop, seeds 0-9), against the held model
#: refined on its whole record: after a docking 13.6-1142 (the first) and 2.45-386
#: (the second) at 40 dB, 92.5-494 and 2.67-224 noise-free; false alarms before a
#: docking 1.02-1.07; on paddle rotation noise-free 1.04-2.3.
CONFIRM_FACTOR = 2.0


def misfit_confirms_change(held: float, refit: float, floor: float, n: int,
                           factor: float = CONFIRM_FACTOR) -> bool:
    """Whether a refit on the data after an alarm explains them clearly better than
    the model held before it.

    The held model's excess misfit ``held - floor`` must exceed ``factor`` times
    the refit's, ``max(refit - floor, 0) + 3 sqrt(2 / n) floor`` (three standard
    errors of a white-noise variance estimated from ``n`` residuals, so that at a
    noise-dominated misfit chance does not confirm). Above the floor both
    misfits scale with the excitation and with the model's unmodelled dynamics, so
    the test reads the same at every noise level: on clean data a refit that
    only re-spreads the unmodelled modes' error is no change.

    Parameters
    ----------
    held, refit : float
        Mean squared (weighted) output error on the same record of the held
        model (its parameters held, its initial state refitted) and of the
        refit.
    floor : float
        The record's white-noise floor in the same units, >= 0.
    n : int
        Number of residuals in each mean, >= 1.
    factor : float
        The multiple, > 1.

    Returns
    -------
    bool
    """
    if not (floor >= 0 and n >= 1 and factor > 1):
        raise ValueError(f"floor >= 0, n >= 1 and factor > 1 required, got {floor}, {n}, "
                         f"{factor}")
    if not (np.isfinite(held) and np.isfinite(refit)):
        return bool(np.isfinite(refit))          # a held model that broke is replaced
    margin = 3.0 * math.sqrt(2.0 / n) * floor
    return held - floor > factor * (max(refit - floor, 0.0) + margin)


@njit(cache=True, nogil=True)
def _glr_level(c: np.ndarray, r: np.ndarray, phi: np.ndarray, error: np.ndarray,
               variance: np.ndarray, lam: float) -> float:
    """Update ``c = lam c + phi e^T``, ``r = lam r + phi phi^T`` in place and return
    ``sum_j c_j^T r^-1 c_j / sigma_j^2 / (d q)`` (NaN if ``r`` cannot be solved)."""
    d, q = c.shape
    for i in range(d):
        for j in range(q):
            c[i, j] = lam * c[i, j] + phi[i] * error[j]
        for j in range(d):
            r[i, j] = lam * r[i, j] + phi[i] * phi[j]
    tr = 0.0
    for i in range(d):
        tr += r[i, i]
    reg = r + 1e-9 * tr * np.eye(d)
    try:
        proj = np.linalg.solve(reg, c)
    except Exception:                  # numba raises a plain exception on a singular matrix
        return np.nan
    total = 0.0
    for i in range(d):
        for j in range(q):
            total += c[i, j] * proj[i, j] / variance[j]
    return total / (d * q)


@dataclass(frozen=True)
class ChangeEvent:
    """A detected change.

    Attributes
    ----------
    sample : int
        Sample at which the test fired.
    onset : int
        Estimated first sample of the change (when the statistic last left 0).
    time : float
        ``sample * dt``, s.
    statistic : float
        CUSUM value at the alarm.
    confirmed : bool or None
        Whether the data after the alarm confirmed it (:func:`misfit_confirms_change`):
        True, the refit replaced the held model; False, it was kept; None, not
        judged (a test without a confirmation, a refit still recording or one that
        failed).
    """

    sample: int
    onset: int
    time: float
    statistic: float
    confirmed: bool | None = None


class InnovationCUSUM:
    """CUSUM on normalized innovations.

    Parameters
    ----------
    threshold : float
        Alarm level of the cumulative sum (larger: fewer false alarms, later
        detection).
    drift : float
        Allowance subtracted per sample: excess normalized energy that is
        not accumulated.
    holdoff : int
        Samples after an alarm (and after start) before the next can fire.
    calibration : float
        Forgetting of the calm-period scale of ``s_k``.
    dt : float
        Sample time, s (to stamp events).
    """

    def __init__(self, threshold: float = 40.0, drift: float = 0.5, holdoff: int = 150,
                 calibration: float = 0.998, dt: float = 0.1) -> None:
        if not (threshold > 0 and drift >= 0 and holdoff >= 0 and 0 < calibration < 1):
            raise ValueError("threshold > 0, drift >= 0, holdoff >= 0, calibration in (0, 1)")
        self.threshold, self.drift = float(threshold), float(drift)
        self.holdoff, self.calibration, self.dt = int(holdoff), float(calibration), float(dt)
        self.reset()

    def reset(self) -> None:
        """Forget the statistic, the scale and the events."""
        self.g = 0.0
        self.scale = 1.0
        self.k = 0
        self._quiet_until = self.holdoff
        self._calibration_start = 0
        self._onset = 0
        self.events: list[ChangeEvent] = []

    def update(self, innovation: np.ndarray, covariance: np.ndarray) -> ChangeEvent | None:
        """Feed one innovation ``e`` (m,) with its predicted covariance ``S`` (m, m).

        Returns
        -------
        ChangeEvent or None
            The event if the test fired at this sample.
        """
        k = self.k
        self.k += 1
        try:
            energy = float(innovation @ np.linalg.solve(covariance, innovation)) / innovation.size
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(energy):
            return None
        if k < self._quiet_until:          # (re)calibration after start or an alarm: an average
            seen = k - self._calibration_start
            self.scale = energy if seen == 0 else self.scale + (energy - self.scale) / (seen + 1)
            return None
        s = energy / self.scale
        self.g = max(0.0, self.g + s - 1.0 - self.drift)
        self.scale = (self.calibration * self.scale
                      + (1 - self.calibration) * min(energy, CALM * self.scale))
        if self.g == 0.0:
            self._onset = k + 1
            return None
        if self.g > self.threshold:
            event = ChangeEvent(sample=k, onset=self._onset, time=k * self.dt, statistic=self.g)
            self.events.append(event)
            self.g = 0.0
            self._quiet_until = k + 1 + self.holdoff
            self._calibration_start = k + 1
            return event
        return None


class RegressionGLR:
    """Generalized likelihood-ratio test for a change of regression parameters.

    For ``e_k = y_k - Theta phi_k`` (the a-priori errors of a recursive
    estimate) and the regressors ``phi_k`` in which a change is expected,
    the exponentially weighted statistic ::

        c_k = sum lam^(k-i) phi_i e_i^T,     R_k = sum lam^(k-i) phi_i phi_i^T
        T_k = sum_j c_k[:, j]^T R_k^-1 c_k[:, j] / sigma_j^2

    is chi-square-like with ``d q`` degrees of freedom while ``Theta`` is
    right (``d`` regressors, ``q`` outputs) and grows with a parameter jump.
    It is divided by its calm level (so coloured residuals do not raise
    alarms by themselves): the mean over the second half of the initial
    ``holdoff``, then a running mean clipped at :data:`CALM` times itself.
    With ``d q = 9`` (three torques, three rates) a threshold of 6 is a
    false-alarm rate below 1e-7 per window on white residuals. An alarm fires when the ratio exceeds
    ``threshold``; the next one can fire ``holdoff`` samples later.

    Parameters
    ----------
    window : float
        Forgetting of the statistic (memory ``1 / (1 - window)`` samples).
    threshold : float
        Alarm level as a multiple of the degrees of freedom.
    holdoff : int
        Samples after start during which the test only calibrates its calm
        level, and after an alarm during which it cannot fire (the calm level
        keeps following, clipped, as at any other time).
    dt : float
        Sample time, s.
    """

    def __init__(self, window: float = 0.98, threshold: float = 4.0, holdoff: int = 200,
                 dt: float = 0.1) -> None:
        if not (0 < window < 1 and threshold > 1 and holdoff >= 0):
            raise ValueError("window in (0, 1), threshold > 1, holdoff >= 0")
        self.window, self.threshold = float(window), float(threshold)
        self.holdoff, self.dt = int(holdoff), float(dt)
        self.reset()

    def reset(self) -> None:
        """Forget the statistic and the events."""
        self._c = self._r = None
        self.k = 0
        self.scale = 1.0
        self._calibrated = 0
        self._quiet_until = self.holdoff
        self.statistic = 0.0
        self.events: list[ChangeEvent] = []

    def restart(self) -> None:
        """Drop the accumulated statistic (e.g. after the regression it watches was
        rebuilt); the calibration and the events stay. The test resumes once one
        window of new data has accumulated (``1 / (1 - window)`` samples)."""
        self._c = self._r = None
        self._quiet_until = max(self._quiet_until, self.k + round(1.0 / (1.0 - self.window)))

    def update(self, phi: np.ndarray, error: np.ndarray, variance: np.ndarray,
               sample: int | None = None) -> ChangeEvent | None:
        """Feed one regressor ``phi`` (d,), a-priori error ``e`` (q,) and the
        error variances (q,) of sample ``sample`` (default: a running count);
        returns the event if the test fired.

        Returns
        -------
        ChangeEvent or None
            The change the test declared at this sample, or None.
        """
        k = self.k
        self.k += 1
        sample = k if sample is None else int(sample)
        lam = self.window
        phi = np.asarray(phi, dtype=float)
        error = np.asarray(error, dtype=float)
        if self._c is None:
            self._c = np.zeros((phi.size, error.size))
            self._r = np.zeros((phi.size, phi.size))
        level = _glr_level(self._c, self._r, phi, error,
                           np.maximum(np.asarray(variance, dtype=float), 1e-30), lam)
        if not math.isfinite(level):
            return None
        if k < self.holdoff:                       # initial calibration, settled half only
            if k >= self.holdoff // 2:
                self._calibrated += 1
                self.scale += (level - self.scale) / self._calibrated
            return None
        self.statistic = level / max(self.scale, 1e-12)
        # follow slow drifts of the calm level (clipped: a change must not raise it)
        self.scale = 0.999 * self.scale + 0.001 * min(level, CALM * self.scale)
        if k < self._quiet_until or self.statistic <= self.threshold:
            return None
        onset = max(0, sample - round(1.0 / (1.0 - lam)))
        event = ChangeEvent(sample=sample, onset=onset, time=sample * self.dt,
                            statistic=self.statistic)
        self.events.append(event)
        self._quiet_until = k + 1 + self.holdoff
        self._c = self._r = None        # the next test sees post-alarm data only
        return event
