"""A gyro bias, estimated from the star tracker and reported: the loop's sensor front end.

A rate gyro whose zero drifts or jumps (a bias of 0.01 deg/s is 36 deg/h) tells
every filter downstream that the spacecraft turns when it does not; the attitude
sensor integrates the truth. Per axis, the attitude's kinematics driven by the
gyro,

.. math::

    \\theta_{k+1} = \\theta_k + \\tfrac{dt}{2} (g_k + g_{k+1}) - dt\\, b_k, \\qquad
    b_{k+1} = b_k + w_k,

(``g`` the gyro's reading, rad/s; the trapezoid is exact for the piecewise-linear
rate a zero-order-held torque gives a rigid body) observed through the star
tracker's ``theta`` (rad) makes the bias ``b`` a state of a two-state Kalman
filter (the gyro-stellar estimator of Farrenkopf 1978) for the sensors' specified
noise and a bias random walk of :data:`BIAS_WALK` (in steady state a time
constant of about 10 s at the env's 40 dB, 36 s at 20 dB), started from a prior
of :data:`PRIOR_BIAS_STD`. :class:`GyroBiasMonitor` runs it on the observations, declares a bias
when the estimate leaves its noise band (:data:`DETECTION_SIGMAS` of its current
standard deviations, and at least :data:`SMALLEST_BIAS`) for :data:`CONFIRM_STEPS` samples,
reports it (a :class:`FaultWarning` naming the axis, the onset estimate and the
value; ``faults``) and from then on subtracts the estimate from that axis's gyro
reading before any filter, identifier or law sees it. A declared bias is taken for a
step: its onset is dated by the least-squares hinge of the star tracker's attitude less
the gyro's integral, and the estimate is run again from there with its prior
uncertainty (the random walk's gain, meant for a drift, takes about 20 s to follow a
step: at its declaration the running estimate is about a quarter of the bias). Until
then the readings pass untouched, so a loop with no fault flies as without the monitor.
"""

from __future__ import annotations

import warnings
from collections import deque
from typing import Any

import numpy as np

from identifiers import steady_state_gain

__all__ = ["BIAS_WALK", "CONFIRM_STEPS", "DETECTION_SIGMAS", "PRIOR_BIAS_STD", "SMALLEST_BIAS",
           "FaultWarning", "GyroBiasMonitor"]

#: The bias random walk the estimator assumes, rad/s per sqrt(s).
BIAS_WALK = 1e-6
#: A bias is declared beyond this many standard deviations of the estimate's noise...
DETECTION_SIGMAS = 8.0
#: ...and beyond this size, rad/s (0.002 deg/s, 7 deg/h): below it the estimator's
#: model error (flexible motion, a noise-free sensor) is as large as the bias.
SMALLEST_BIAS = np.deg2rad(0.002)
#: Samples the estimate must stay beyond both before the bias is declared (1 s).
CONFIRM_STEPS = 10
#: Seconds of estimates kept to date a detected bias's onset.
ONSET_MEMORY_S = 120.0
#: The bias's prior standard deviation at the first sample, rad/s (0.05 deg/s): the
#: estimate's own uncertainty, not a steady state, judges it while it converges.
PRIOR_BIAS_STD = np.deg2rad(0.05)
#: Seconds before the estimate's last quiet sample searched for a declared bias's onset.
DATING_LOOKBACK_S = 10.0


class FaultWarning(UserWarning):
    """A controller inferred a fault of the spacecraft (kind, axis, onset) and says how
    it flies on."""


class GyroBiasMonitor:
    """Estimates each axis's gyro bias from the star tracker, declares and compensates it.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft env: its observation layout (the ``"attitude"`` and ``"rate"``
        groups), ``noise_std`` (the sensors' specified noise) and ``dt`` are read.
    bias_walk : float
        The bias random walk assumed, rad/s per sqrt(s) (> 0).

    Attributes
    ----------
    bias : (3,) ndarray
        The current estimate per axis, rad/s.
    bias_std : float
        The estimate's steady-state standard deviation, rad/s (the filter starts from
        :data:`PRIOR_BIAS_STD` and converges to it).
    compensated : (3,) bool ndarray
        The axes whose bias has been declared (and is subtracted).
    faults : list of dict
        One entry per declared bias: ``kind`` ("gyro bias"), ``axis``, ``onset_s``
        (the step's dated onset), ``detected_s`` and ``value`` (rad/s, the estimate
        at detection, run again from the onset).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraft-v2", task="regulation",
    ...                initial_attitude_deg=0.0)
    >>> monitor = GyroBiasMonitor(env)
    >>> obs, _ = env.reset(seed=0)
    >>> for _ in range(300):             # 30 s at rest, a 0.01 deg/s bias on roll
    ...     obs[3] += np.deg2rad(0.01)
    ...     corrected = monitor(obs)
    ...     obs, *_ = env.step(np.zeros(3, dtype=np.float32))
    >>> [f["axis"] for f in monitor.faults], bool(abs(corrected[3] - obs[3]) < 1e-3)
    ([0], True)
    """

    def __init__(self, env: Any, bias_walk: float = BIAS_WALK) -> None:
        if not (np.isfinite(bias_walk) and bias_walk > 0):
            raise ValueError(f"bias_walk must be a finite rate > 0 in rad/s per sqrt(s), "
                             f"got {bias_walk!r}")
        env = getattr(env, "unwrapped", env)
        layout, outputs = env.observation_layout, env.model.output_layout
        self._att = layout.indices("attitude")
        self._rate = layout.indices("rate")
        self.dt = float(env.model.dt)
        noise = np.asarray(env.noise_std, dtype=float)
        # floors for noise-free sensors: the filter needs a positive measurement noise
        att_var = max(float(np.max(noise[outputs.indices("attitude")])), 1e-9) ** 2
        gyro_var = max(float(np.max(noise[outputs.indices("rate")])), 1e-10) ** 2
        dt = self.dt
        self._a = np.array([[1.0, -dt], [0.0, 1.0]])
        self._q = np.diag([0.5 * dt * dt * gyro_var, bias_walk**2 * dt])
        self._r = att_var
        self._prior = np.diag([att_var, PRIOR_BIAS_STD**2])
        gain, prior = steady_state_gain(self._a, np.array([[1.0, 0.0]]), self._q, att_var)
        posterior = prior - np.outer(gain[:, 0], prior[0])
        self.bias_std = float(np.sqrt(posterior[1, 1]))
        self._history = deque(maxlen=max(1, round(ONSET_MEMORY_S / dt)))
        # per sample: the estimate before its update (attitude, bias, gyro) and the raw
        # readings (attitude, gyro, held), to run it again from a declared bias's onset
        self._replay: deque = deque(maxlen=self._history.maxlen)
        self.reset()

    def reset(self) -> None:
        """A new episode: no estimate, nothing declared."""
        self._theta: np.ndarray | None = None
        self._last_theta = np.full(3, np.nan)
        self._p = np.broadcast_to(self._prior, (3, 2, 2)).copy()
        self.bias = np.zeros(3)
        self._gyro = np.zeros(3)
        self._beyond = np.zeros(3, dtype=int)
        self.compensated = np.zeros(3, dtype=bool)
        self.faults: list[dict[str, Any]] = []
        self._history.clear()
        self._replay.clear()
        self._k = 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """This sample's observation with each declared bias subtracted from its gyro axis
        (a copy; the estimate advanced by the sample).

        Parameters
        ----------
        obs : ndarray
            The env's observation (NaN entries, or an attitude bit-for-bit equal to the
            last sample's, a held sensor: that axis predicts only).

        Returns
        -------
        ndarray
            ``obs``, float, with the compensated rates.
        """
        obs = np.array(obs, dtype=float)
        theta, gyro = obs[self._att], obs[self._rate]
        # a reading bit-for-bit equal to the last is a held or stuck sensor (noise never
        # repeats): that axis predicts only, so a frozen star tracker is not read as a bias
        held = theta == self._last_theta
        self._last_theta = theta.copy()
        if self._theta is None:
            self._theta = np.where(np.isfinite(theta), theta, 0.0)
            self._gyro = np.where(np.isfinite(gyro), gyro, 0.0)
            self._replay.append(None)
        else:
            self._replay.append((self._theta.copy(), self.bias.copy(), self._gyro.copy(),
                                 theta.copy(), gyro.copy(), held.copy()))
            self._theta, self.bias, self._gyro, self._p = self._advance(
                self._theta, self.bias, self._gyro, self._p, theta, gyro, held)
        self._history.append(self.bias.copy())
        self._declare()
        self._k += 1
        obs[self._rate] = gyro - np.where(self.compensated, self.bias, 0.0)
        return obs

    def _advance(self, theta_hat: np.ndarray, bias: np.ndarray, gyro_prev: np.ndarray,
                 p: np.ndarray, theta: np.ndarray, gyro: np.ndarray, held: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One sample of the two-state filter of the axes given (arrays over them: the
        estimates, the last gyro reading, the covariances ``(k, 2, 2)``, this sample's
        readings): the new estimates, gyro reading and covariances. A missing or held
        attitude predicts only; a missing gyro reading is taken as the last."""
        gyro_now = np.where(np.isfinite(gyro), gyro, gyro_prev)
        predicted = theta_hat + 0.5 * self.dt * (gyro_prev + gyro_now) - self.dt * bias
        p = self._a @ p @ self._a.T + self._q                   # (k, 2, 2), per axis
        seen = np.isfinite(theta) & ~held
        gain = p[:, :, 0] / (p[:, 0, 0] + self._r)[:, None]     # (k, 2)
        gain[~seen] = 0.0                                      # a missing sample: predict
        innovation = np.where(seen, theta - predicted, 0.0)
        p = p - gain[:, :, None] * p[:, None, 0, :]
        return (predicted + gain[:, 0] * innovation, bias + gain[:, 1] * innovation, gyro_now,
                0.5 * (p + np.swapaxes(p, 1, 2)))

    def _declare(self) -> None:
        std = np.sqrt(self._p[:, 1, 1])
        beyond = np.abs(self.bias) > np.maximum(DETECTION_SIGMAS * std, SMALLEST_BIAS)
        self._beyond = np.where(beyond, self._beyond + 1, 0)
        for axis in np.flatnonzero((self._beyond >= CONFIRM_STEPS) & ~self.compensated):
            self.compensated[axis] = True
            past = np.array(self._history)[:, axis]
            quiet = np.flatnonzero(np.abs(past) <= 3.0 * std[axis])
            # the samples in the history before this one: the onset is after the last quiet
            start = self._k - len(past) + 1
            onset = self._date_step(axis, (start + (quiet[-1] + 1 if quiet.size else 0))
                                    * self.dt)
            self._restep(axis, onset)
            fault = {"kind": "gyro bias", "axis": int(axis), "onset_s": float(onset),
                     "detected_s": float(self._k * self.dt),
                     "value": float(self.bias[axis])}
            self.faults.append(fault)
            warnings.warn(
                f"gyro bias on axis {axis}: {np.rad2deg(fault['value']):.4g} deg/s from about "
                f"{onset:.1f} s (declared at {fault['detected_s']:.1f} s); its estimate is "
                "subtracted from that gyro from now on", FaultWarning, stacklevel=3)

    def _readings(self, onset_s: float) -> tuple[int, list] | None:
        """The index in the replay of the sample at ``onset_s`` and the replay, or None
        where it does not reach back that far."""
        first = len(self._replay) - 1 - (self._k - round(onset_s / self.dt))
        if first < 0 or any(item is None for item in list(self._replay)[first:]):
            return None
        return first, list(self._replay)

    def _date_step(self, axis: int, onset_s: float) -> float:
        """The onset, s, of a step in ``axis``'s bias: the least-squares hinge of the star
        tracker's attitude less the gyro's integral, searched from
        :data:`DATING_LOOKBACK_S` before ``onset_s`` (the estimate's last quiet sample,
        which lags a step by the estimate's convergence) to :data:`CONFIRM_STEPS` before
        now; ``onset_s`` where the replay does not reach back."""
        found = self._readings(onset_s - DATING_LOOKBACK_S)
        if found is None:
            return onset_s
        first, replay = found
        _, _, previous, theta, gyro, held = (np.array([item[i][axis] for item in replay[first:]])
                                             for i in range(6))
        gyro = np.where(np.isfinite(gyro), gyro, previous)
        drift = theta - np.cumsum(0.5 * self.dt * (previous + gyro))
        use = np.isfinite(drift) & ~held
        t = (self._k - drift.size + 1 + np.arange(drift.size)) * self.dt
        best, best_sse = onset_s, np.inf
        for start in t[:drift.size - CONFIRM_STEPS]:
            x = np.column_stack([np.ones(drift.size), -np.maximum(t - start, 0.0)])[use]
            coef, *_ = np.linalg.lstsq(x, drift[use], rcond=None)
            sse = float(np.sum((drift[use] - x @ coef) ** 2))
            if sse < best_sse:
                best, best_sse = float(start), sse
        return best

    def _restep(self, axis: int, onset_s: float) -> None:
        """Run ``axis``'s estimate again over the samples since ``onset_s``, the bias's
        covariance opened to its prior there: a step, given its onset, is a constant."""
        found = self._readings(onset_s)
        if found is None:
            return
        first, replay = found
        one = [axis]                                     # the filter's arrays, this axis
        theta_hat, bias, gyro_prev = (replay[first][i][one] for i in range(3))
        p = self._prior[None].copy()
        for *_, theta, gyro, held in replay[first:]:
            theta_hat, bias, gyro_prev, p = self._advance(theta_hat, bias, gyro_prev, p,
                                                          theta[one], gyro[one], held[one])
        self._theta[axis], self.bias[axis], self._p[axis] = theta_hat[0], bias[0], p[0]
