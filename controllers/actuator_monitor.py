"""Wheels that do not deliver what is commanded, found from the momentum balance and reported.

Per axis the spacecraft's angular momentum changes by the torque the wheels
deliver: over a window of ``W`` samples,

.. math::

    J\\,(\\bar\\omega_k - \\bar\\omega_{k-W}) = \\sum_{j=k-W}^{k-1} u_j\\,dt
    + W dt\\, d_k,

with ``J`` the nominal inertia (kg m^2; the robust design's), ``omega-bar`` the
gyro's rate averaged over :data:`AVERAGE_S` (the flexible modes' momentum
exchange with the hub averages out), ``u`` the commanded torque (N m, the env's
``info["torque"]``, averaged the same way) and ``d`` the torque the wheels did
*not* deliver as commanded (N m): zero for healthy wheels, the bias of a biased
wheel, ``s - u`` for a wheel stuck at ``s``, ``(e - 1) u`` for one delivering
the share ``e``. The nominal inertia is off after a docking or with the paddles
turned, and healthy wheels of a plant family deliver 0.7-1.3 of their command, so
``d`` is judged against the larger of the torque the balance itself sees,
``a = J (omega-bar_k - omega-bar_{k-W}) / (W dt)``, and the torque commanded over the
window, ``c`` (vectors: an inertia error couples the axes through the products of
inertia): an axis is *beyond* when
``|d| > SMALLEST_TORQUE + GAIN_UNCERTAINTY * max(||a||, ||c||)``. A plant whose gain from
command to momentum is ``g`` times the nominal one shows ``|d| = |g - 1| |c|``, within
the allowance for every ``g`` in ``[0.3, 3.3]`` at the default 0.7: the family's heaviest
draw (its hub 1.5x, both 800 kg modules docked) on wheels delivering 0.7 of their
command has ``g = 0.33`` on pitch. A wheel at 10 % of a nominal plant is ``g = 0.1``;
a stuck wheel's ``a`` does not follow ``c`` at all. A fault is declared after
:data:`CONFIRM_S` beyond on end, longer than a one-off step of momentum stays in the
window (``WINDOW_S + AVERAGE_S``): a capture's momentum, or a gyro bias's jump,
is not a wheel fault. The thresholds were set on recorded fault-free episodes of
every scenario (slews, dockings, turning paddles) and the wheel faults of the
fault table.

:class:`ActuatorMonitor` reports each declared axis (a
:class:`controllers.gyro_bias.FaultWarning` and an entry of ``faults``: kind
"actuator torque", the axis, the onset estimate, the torque error ``d`` at
declaration) and, when from then on the torque the balance sees follows less than
:data:`LOST_SLOPE` of the commanded torque (a least-squares slope) over a command
range of :data:`LOST_RANGE`, a second report (kind "axis lost"): the wheel does
not answer, and with one wheel per axis no controller can hold that axis. It
reports only: the loop flies as without it.
"""

from __future__ import annotations

import warnings
from collections import deque
from typing import Any

import numpy as np

from controllers.baselines import nominal_model
from controllers.gyro_bias import FaultWarning
from spacecraft_conventions import AXIS_NAMES

__all__ = ["AVERAGE_S", "AXIS_LOST", "CONFIRM_S", "GAIN_UNCERTAINTY", "LOST_RANGE", "LOST_SLOPE",
           "SMALLEST_TORQUE", "WINDOW_S", "ActuatorMonitor"]

#: Length of the momentum balance's window, s.
WINDOW_S = 8.0
#: The rate and the commanded impulse are averaged over this long at both ends, s.
AVERAGE_S = 2.0
#: Smallest torque error declared, N m.
SMALLEST_TORQUE = 0.04
#: Relative error allowed for in the gain from commanded torque to momentum, on the
#: larger of the torque seen and the torque commanded: a docking adds up to 85 % of the
#: nominal pitch inertia, a family draw's healthy wheels deliver 0.7-1.3 of their command.
GAIN_UNCERTAINTY = 0.7
#: An axis must stay beyond this long to be declared, s: longer than a one-off step of
#: momentum (a capture, a bump, a gyro bias's jump) stays in the balance,
#: ``WINDOW_S + AVERAGE_S``.
CONFIRM_S = WINDOW_S + AVERAGE_S + 0.5
#: A declared axis whose delivered torque follows less than this share of its command...
LOST_SLOPE = 0.1
#: ...over a command range at least this wide (N m) is reported lost.
LOST_RANGE = 1.0

#: The kind of the report of an axis whose wheel does not answer (no controller holds it).
AXIS_LOST = "axis lost"


class ActuatorMonitor:
    """Checks each axis's momentum balance against the commanded torque; reports the wheels
    that do not deliver it.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft env: its observation layout (the ``"rate"`` group), ``dt``,
        ``max_torque`` (N m) and the nominal inertia of its model (kg m^2) are read.

    Attributes
    ----------
    torque_error : (3,) ndarray
        The latest ``d`` per axis, N m (0 until a window has filled).
    declared : (3,) bool ndarray
        The axes declared.
    faults : list of dict
        One entry per report: ``kind`` ("actuator torque" or "axis lost"), ``axis``,
        ``onset_s`` (when the run of beyond samples that led to the declaration
        started, less the share of a window a constant error of the declared size
        takes to cross the threshold), ``detected_s`` and ``value`` (``d``, N m).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraft-v2", task="regulation",
    ...                initial_attitude_deg=0.0)
    >>> monitor = ActuatorMonitor(env)
    >>> obs, info = env.reset(seed=0)
    >>> for _ in range(400):      # 40 s: 1 N m commanded on yaw, none delivered
    ...     monitor(obs, info)
    ...     obs, _, _, _, info = env.step(np.zeros(3, dtype=np.float32))
    ...     info = {**info, "torque": np.array([0.0, 0.0, 1.0])}
    >>> [(f["kind"], f["axis"]) for f in monitor.faults]
    [('actuator torque', 2)]
    """

    def __init__(self, env: Any) -> None:
        env = getattr(env, "unwrapped", env)
        self._rate = env.observation_layout.indices("rate")
        self.dt = float(env.model.dt)
        self.max_torque = float(env.max_torque)
        self.inertia = np.asarray(nominal_model(env.model).inertia(0.0), dtype=float)
        self._window = max(1, round(WINDOW_S / self.dt))
        self._average = max(1, round(AVERAGE_S / self.dt))
        self._confirm = max(1, round(CONFIRM_S / self.dt))
        self.reset()

    def reset(self) -> None:
        """A new episode: no history, nothing declared."""
        self._k = 0
        self._impulse = np.zeros(3)                       # N m s commanded since reset
        self._raw = deque(maxlen=self._average)           # (momentum, impulse) pairs
        self._smooth = deque(maxlen=self._window + 1)     # their averages
        self._last_rate = np.zeros(3)
        self._beyond = np.zeros(3, dtype=int)
        self._answer = np.zeros((3, 5))      # per axis: n, sum c, sum s, sum c^2, sum c s
        self._range = np.stack([np.full(3, np.inf), np.full(3, -np.inf)])
        self.torque_error = np.zeros(3)
        self._scale = 0.0
        self.declared = np.zeros(3, dtype=bool)
        self.lost = np.zeros(3, dtype=bool)
        self.faults: list[dict[str, Any]] = []

    def __call__(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> None:
        """Advance by one sample.

        Parameters
        ----------
        obs : ndarray
            The env's observation after the last step (a NaN rate: the last finite
            reading held).
        info : dict, optional
            The step's ``info``; its ``"torque"`` (N m, (3,)) is the torque commanded
            over the step that ended at ``obs`` (absent at a reset: none).

        Returns
        -------
        None
        """
        rate = np.asarray(obs, dtype=float)[self._rate]
        rate = np.where(np.isfinite(rate), rate, self._last_rate)
        self._last_rate = rate
        torque = None if info is None else info.get("torque")
        if torque is not None and self._k > 0:
            torque = np.asarray(torque, dtype=float)
            if np.isfinite(torque).all():
                self._impulse = self._impulse + torque * self.dt
        self._raw.append((self.inertia @ rate, self._impulse.copy()))
        if len(self._raw) == self._average:
            self._smooth.append(np.mean(np.array(self._raw), axis=0))   # (2, 3)
        if len(self._smooth) == self._smooth.maxlen:
            (h0, i0), (h1, i1) = self._smooth[0], self._smooth[-1]
            span = self._window * self.dt
            seen = (h1 - h0) / span                    # the torque the balance sees
            commanded = (i1 - i0) / span
            self.torque_error = seen - commanded
            # an inertia error couples the axes (products of inertia): whole vectors; a
            # weak healthy wheel shows as seen < commanded, a strong one as seen > commanded
            self._scale = max(float(np.linalg.norm(seen)), float(np.linalg.norm(commanded)))
            beyond = (np.abs(self.torque_error)
                      > SMALLEST_TORQUE + GAIN_UNCERTAINTY * self._scale)
            self._beyond = np.where(beyond, self._beyond + 1, 0)
            self._declare()
            self._track_answer(seen, commanded)
        self._k += 1

    def _track_answer(self, seen: np.ndarray, commanded: np.ndarray) -> None:
        """From each axis's declaration on, the least-squares slope of the torque the
        balance sees on the commanded one; an axis whose slope stays under
        :data:`LOST_SLOPE` over a command range of :data:`LOST_RANGE` is reported lost."""
        on = self.declared & ~self.lost
        if not on.any():
            return
        self._answer[on] += np.stack([np.ones(3), commanded, seen, commanded**2,
                                      commanded * seen], axis=1)[on]
        self._range[0] = np.where(on, np.minimum(self._range[0], commanded), self._range[0])
        self._range[1] = np.where(on, np.maximum(self._range[1], commanded), self._range[1])
        n, c, sv, cc, cs = self._answer.T
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = (n * cs - c * sv) / (n * cc - c * c)
        wide = self._range[1] - self._range[0] >= LOST_RANGE
        for axis in np.flatnonzero(on & wide & (np.abs(slope) < LOST_SLOPE)):
            self.lost[axis] = True
            self._report(AXIS_LOST, int(axis),
                         f"the {AXIS_NAMES[axis]} wheel does not answer: it delivered "
                         f"{slope[axis]:.2f} of its command over a "
                         f"{self._range[1, axis] - self._range[0, axis]:.2g} N m range; "
                         f"with one wheel per axis no controller can hold {AXIS_NAMES[axis]}")

    def _declare(self) -> None:
        for axis in np.flatnonzero((self._beyond >= self._confirm) & ~self.declared):
            self.declared[axis] = True
            self._report("actuator torque", int(axis),
                         f"the {AXIS_NAMES[axis]} wheel delivers "
                         f"{self.torque_error[axis]:+.3g} N m from what it is commanded")

    def _report(self, kind: str, axis: int, what: str) -> None:
        detected = self._k * self.dt
        # a torque error from t0 on fills the window linearly, the torques seen and
        # commanded with it: a share f of the window holds f |d| against an allowance of
        # SMALLEST_TORQUE + f GAIN_UNCERTAINTY scale; it crossed at the f where they meet
        margin = abs(self.torque_error[axis]) - GAIN_UNCERTAINTY * self._scale
        filled = min(1.0, SMALLEST_TORQUE / margin) if margin > 0 else 1.0
        crossed = self._k - self._beyond[axis] + 1
        onset = max(0.0, (crossed - filled * self._window - self._average / 2) * self.dt)
        fault = {"kind": kind, "axis": axis, "onset_s": float(onset),
                 "detected_s": float(detected), "value": float(self.torque_error[axis])}
        self.faults.append(fault)
        warnings.warn(f"{kind} on axis {axis} ({AXIS_NAMES[axis]}) from about {onset:.1f} s "
                      f"(declared at {detected:.1f} s): {what}", FaultWarning, stacklevel=3)
