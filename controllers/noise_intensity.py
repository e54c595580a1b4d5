"""The process-noise intensity of a loop's Kalman filter, chosen online from its
innovations.

A Kalman filter is optimal only for the noise it assumes. Every LQG filter of
the package assumes :data:`controllers.baselines.PROCESS_NOISE` (0.05 N m) of
white torque; a plant without such a disturbance, flown on a model that fits it,
is then estimated with a gain several times too large, and the sensor noise that
gain lets through is most of the stationary cost (a quiet spacecraft: 45x the
same law with the plant's true statistics, median of 10 seeds). The intensity the data support
depends on the plant's disturbances *and* on how well the identified model fits
(a model's error acts as process noise), so it cannot be fixed in advance.

:class:`ProcessNoiseBank` runs one time-varying Kalman filter per intensity of
a logarithmic grid (:data:`NOISE_LEVELS`, 0.05 N m down to none) on the same
model, inputs and measurements, scores each by the Gaussian log-likelihood of
its innovations ``e_k`` with covariance ``S_k`` (Mehra 1970; multiple-model
adaptive estimation, Magill 1965),

    l_j <- lambda l_j - (log det S_k + e_k^T S_k^-1 e_k) / 2,
    lambda = exp(-dt / memory),

and hands out the state of the quietest filter the data do not reject: the
lowest intensity whose score is within :data:`SWITCH_NATS` of the best, once
one memory of samples has been scored (the noisiest filter until then). In
stationary flight the innovations are mostly sensor noise and tell the low
intensities apart only slowly (a fraction of a nat per 100 s between 4e-4 N m
and none), while the control cost of the noisier gain is several times larger;
a model that stops predicting (a refit, a docking, a poorly identified mode's
ringing) puts the quiet filters' scores behind by many nats within seconds, and
the choice moves up. No score falls more than :data:`LAG_NATS` behind the
best, so the evidence of a transient is forgotten within a few memories.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from numba import njit

from controllers.baselines import process_noise, regularizer
from identifiers import KalmanPredictor
from spacecraft_conventions import KeptWhileEqual

__all__ = ["LAG_NATS", "NOISE_LEVELS", "SWITCH_NATS", "ProcessNoiseBank"]

#: Torque-noise standard deviations, N m, of the bank's filters: from the
#: baselines' assumption (:data:`controllers.baselines.PROCESS_NOISE`) down by
#: factors of 5 to none.
NOISE_LEVELS: tuple[float, ...] = (0.05, 0.01, 2e-3, 4e-4, 8e-5, 0.0)

#: Log-likelihood margin (nats) by which another filter must lead the one in use
#: before the bank changes to it (a likelihood ratio of about 7): two intensities
#: that fit equally well do not take turns at every sample.
SWITCH_NATS = 2.0

#: Furthest a filter's score may fall behind the leader's, nats (a probability
#: floor of 2e-9, as multiple-model estimators bound their hypotheses'): the
#: evidence of a transient (a warm-up's changing models favour the noisiest
#: filter by hundreds of nats) is not carried for several memories after it ends.
LAG_NATS = 20.0


class ProcessNoiseBank:
    """Kalman filters at several process-noise intensities; the state of the quietest
    one the innovations do not reject.

    Parameters
    ----------
    dt : float
        Sample time, s.
    levels : sequence of float
        Torque-noise standard deviations, N m, one filter each (default
        :data:`NOISE_LEVELS`), in decreasing order; the first is the one in use
        until the scores tell them apart.
    memory_s : float
        Time constant of the log-likelihood's exponential forgetting, s
        (default 20).
    initial_covariance : float
        Each filter's prior ``P_0 = initial_covariance * I`` (default 1e-3, as
        the LQG controllers' filters).

    Attributes
    ----------
    chosen : int
        Index in ``levels`` of the filter whose state is handed out.
    scores : (len(levels),) ndarray
        The discounted log-likelihoods, nats.

    Examples
    --------
    A double integrator with no disturbance, seen through a noisy position
    sensor: the bank settles on the filter that assumes none.

    >>> import numpy as np
    >>> from controllers.noise_intensity import ProcessNoiseBank
    >>> a, b, c = np.array([[1.0, 0.1], [0.0, 1.0]]), np.array([[0.005], [0.1]]), np.eye(1, 2)
    >>> bank = ProcessNoiseBank(0.1, levels=(0.05, 0.0), memory_s=50.0)
    >>> rng = np.random.default_rng(0)
    >>> x = np.array([1e-3, 0.0])
    >>> for k in range(2000):
    ...     y = c @ x + 1e-4 * rng.standard_normal(1)
    ...     _ = bank.step(a, b, c, np.array([1e-8]), y, np.zeros(1))
    ...     x = a @ x
    >>> bank.level
    0.0
    """

    def __init__(self, dt: float, levels: tuple[float, ...] = NOISE_LEVELS,
                 memory_s: float = 20.0, initial_covariance: float = 1e-3) -> None:
        levels = tuple(float(v) for v in levels)
        if not levels or any(not np.isfinite(v) or v < 0 for v in levels) \
                or any(b >= a for a, b in pairwise(levels)):
            raise ValueError(f"levels must be finite, >= 0 and strictly decreasing, got "
                             f"{levels}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0 s, got {dt}")
        if not (np.isfinite(memory_s) and memory_s > 0):
            raise ValueError(f"memory_s must be > 0 s, got {memory_s}")
        if not (np.isfinite(initial_covariance) and initial_covariance >= 0):
            raise ValueError(f"initial_covariance must be finite and >= 0, got "
                             f"{initial_covariance}")
        self.levels = levels
        self.dt = float(dt)
        self.memory_s = float(memory_s)
        self.initial_covariance = float(initial_covariance)
        self._forget = float(np.exp(-self.dt / self.memory_s))
        self._memory_samples = round(self.memory_s / self.dt)
        self.reset()

    def reset(self) -> None:
        """No filters (the next :meth:`step` starts them), scores zero, first level."""
        self.filters: list[KalmanPredictor] = []
        self.scores = np.zeros(len(self.levels))
        self.chosen = 0
        self._evidence = 0
        self.switches = 0
        #: the last step's (A, B, the levels' noise covariances), for the time update
        self._pending: tuple[np.ndarray, np.ndarray, list[np.ndarray]] | None = None
        #: every level's state noise covariance, for the last input matrix
        self._noise: KeptWhileEqual[list[np.ndarray]] = KeptWhileEqual()
        #: the output matrix the filters' states are in
        self._output: KeptWhileEqual[bool] = KeptWhileEqual()

    def _restart_quiet(self) -> None:
        """Every filter from the noisiest one's estimate and covariance, scores level:
        a new output matrix re-scales the states (a refit's tip gains), which a quiet
        filter's small covariance would take hundreds of samples to follow."""
        first = self.filters[0]
        for kf in self.filters[1:]:
            kf.reset()
            kf.x, kf.P = first.x.copy(), first.P.copy()
        self.scores[:] = 0.0
        self.chosen = 0
        self._evidence = 0

    @property
    def level(self) -> float:
        """The torque-noise standard deviation (N m) of the filter in use."""
        return self.levels[self.chosen]

    def _covariances(self, b: np.ndarray) -> list[np.ndarray]:
        """:func:`controllers.baselines.process_noise` of every level, for input matrix
        ``b`` (n, 3)."""
        def compute() -> list[np.ndarray]:
            # the first level as every fixed design's filter (the same bits); the others
            # from one product
            bbt = b @ b.T
            return [process_noise(b, self.levels[0])] + [_quiet_noise(bbt, v)
                                                         for v in self.levels[1:]]

        return self._noise.get((b,), compute)

    def step(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, noise_var: np.ndarray,
             y: np.ndarray, torque: np.ndarray) -> np.ndarray:
        """Advance every filter to this sample and return the chosen one's ``x_{k|k}``.

        Parameters
        ----------
        a, b, c : ndarray
            This step's model, (n, n), (n, 3) and (m, n); the time update from the
            last sample uses the last call's ``a`` and ``b``.
        noise_var : (m,) ndarray
            The measurement noise variances.
        y : (m,) ndarray
            This sample's measurements (non-finite entries are not used, and a
            sample with one is not scored).
        torque : (3,) ndarray
            The torque applied since the last sample, N m.

        Returns
        -------
        (n,) ndarray
            ``x_{k|k}`` of the chosen filter.
        """
        pending = self._pending
        noise = self._covariances(b)
        self._pending = (a, b, noise)
        if not self.filters or self.filters[0].n != a.shape[0] or pending is None:
            self.filters = [KalmanPredictor(a.shape[0], self.initial_covariance)
                            for _ in self.levels]
            self.scores[:] = 0.0
            self.chosen = 0
            self._evidence = 0
            self._output.keep((c,), True)
            for kf in self.filters:
                kf.correct(c, noise_var, y, a=a)
            return self.filters[self.chosen].x
        a0, b0, noise0 = pending
        if not self._output.holds((c,)):
            self._restart_quiet()
            self._output.keep((c,), True)
        scored = np.isfinite(y).all()
        for j, kf in enumerate(self.filters):
            kf.advance(a0, b0, noise0[j], torque, c, noise_var, y, a_now=a)
            if scored:
                self.scores[j] = self._forget * self.scores[j] + _log_likelihood(
                    kf.innovation, kf.innovation_covariance)
        np.maximum(self.scores, self.scores.max() - LAG_NATS, out=self.scores)
        self._evidence += scored
        # the quietest filter the data do not reject: within SWITCH_NATS of the best, once
        # one memory of samples has been scored since the filters (re)started
        best = 0 if self._evidence < self._memory_samples else int(
            np.flatnonzero(self.scores >= self.scores.max() - SWITCH_NATS)[-1])
        if best != self.chosen:
            self.chosen = best
            self.switches += 1
        return self.filters[self.chosen].x


def _log_likelihood(e: np.ndarray | None, s: np.ndarray | None) -> float:
    """``-(log det S + e^T S^-1 e) / 2`` (the Gaussian's constant left out); 0 for a
    sample without an innovation, -1e12 where ``S`` is not positive definite."""
    if e is None or s is None:
        return 0.0
    return float(_gaussian_score(np.ascontiguousarray(e, dtype=float),
                                 np.ascontiguousarray(s, dtype=float)))


def _quiet_noise(bbt: np.ndarray, level: float) -> np.ndarray:
    """:func:`controllers.baselines.process_noise` from ``B B^T``: its regularizer, the
    product's rounding aside."""
    q = level**2 * bbt
    q.flat[::q.shape[0] + 1] += regularizer(level)
    return q


@njit(cache=True, nogil=True)
def _gaussian_score(e, s):  # pragma: no cover - compiled
    """``-(log det S + e^T S^-1 e) / 2`` by a Cholesky factor of ``S`` (m <= a few tens:
    numpy's generic path cost 15 us of call overhead per filter and sample)."""
    m = e.shape[0]
    low = np.zeros((m, m))
    z = np.empty(m)
    half_log_det = 0.0
    for j in range(m):
        d = s[j, j]
        for k in range(j):
            d -= low[j, k] * low[j, k]
        if not d > 0.0:
            return -1e12
        low[j, j] = np.sqrt(d)
        half_log_det += np.log(low[j, j])
        for i in range(j + 1, m):
            v = s[i, j]
            for k in range(j):
                v -= low[i, k] * low[j, k]
            low[i, j] = v / low[j, j]
    quad = 0.0
    for i in range(m):
        v = e[i]
        for k in range(i):
            v -= low[i, k] * z[k]
        z[i] = v / low[i, i]
        quad += z[i] * z[i]
    return -half_log_det - 0.5 * quad
