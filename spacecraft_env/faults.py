"""Faults a spacecraft meets in flight, injected on a schedule: :class:`FaultInjection`.

Actuator faults act where the torque leaves the wheels (after the env's
saturation, delay and rate limit), so the spacecraft feels them while
``info["torque"]``, the torque the flight computer commanded, does not show
them; sensor faults act on the observation. Each fault has an onset, a
duration (default: for good) and the axis or sensor channels it strikes:

=========================  ========  =====================================================
kind                       strikes   ``value``
=========================  ========  =====================================================
``loss_of_effectiveness``  actuator  share of the commanded torque delivered, in [0, 1]
                                     (0: a dead wheel)
``stuck_actuator``         actuator  torque the wheel delivers whatever is commanded, N m
``actuator_bias``          actuator  torque added to the commanded one, N m
``sensor_dropout``         sensor    (none) the channels read NaN
``stuck_sensor``           sensor    (none) the channels hold their reading at the onset
``sensor_bias``            sensor    offset added, in the group's unit (rad, rad/s, m)
``noise_burst``            sensor    standard deviation of white noise added, same unit
=========================  ========  =====================================================

``info["faults"]`` lists the faults active after each step, for scoring and
plots: a controller must not read it (the privileged part of ``info``, like
``"state"``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["ACTUATOR_FAULTS", "FAULT_KINDS", "SENSOR_FAULTS", "Fault", "FaultInjection",
           "parse_fault"]

#: Faults of the wheels (``axis``: 0, 1, 2 for roll, pitch, yaw; None: every axis).
ACTUATOR_FAULTS = ("loss_of_effectiveness", "stuck_actuator", "actuator_bias")
#: Faults of a sensor group (``group``: "attitude", "rate" or "deflection"; ``axis``: the
#: channel within it, None: every channel of the group).
SENSOR_FAULTS = ("sensor_dropout", "stuck_sensor", "sensor_bias", "noise_burst")
FAULT_KINDS = ACTUATOR_FAULTS + SENSOR_FAULTS


@dataclass(frozen=True)
class Fault:
    """One fault: what, when, where and how much.

    Attributes
    ----------
    kind : str
        One of :data:`FAULT_KINDS`.
    onset_s : float
        Time it strikes, s (>= 0).
    duration_s : float
        How long it lasts, s (> 0; default inf: for good).
    axis : int or None
        Actuator faults: the wheel (0, 1, 2); sensor faults: the channel within
        ``group``; None: all of them.
    group : str or None
        Sensor faults: the sensor group ("attitude", "rate", "deflection").
    value : float
        See the table of :mod:`spacecraft_env.faults` (N m, rad, rad/s or m).

    Raises
    ------
    ValueError
        For an unknown kind, a negative onset, a non-positive duration, a
        sensor fault without a group (or an actuator fault with one), an
        effectiveness outside [0, 1] or a non-finite value.
    """

    kind: str
    onset_s: float
    duration_s: float = math.inf
    axis: int | None = None
    group: str | None = None
    value: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"unknown fault kind {self.kind!r}; expected one of {FAULT_KINDS}")
        if not (math.isfinite(self.onset_s) and self.onset_s >= 0):
            raise ValueError(f"onset_s must be a finite time >= 0 s, got {self.onset_s}")
        if not self.duration_s > 0:
            raise ValueError(f"duration_s must be > 0 s (inf: for good), got {self.duration_s}")
        if not math.isfinite(self.value):
            raise ValueError(f"value must be finite, got {self.value}")
        if self.kind in ACTUATOR_FAULTS:
            if self.group is not None:
                raise ValueError(f"{self.kind} strikes a wheel: no sensor group, got "
                                 f"{self.group!r}")
            if self.axis is not None and self.axis not in (0, 1, 2):
                raise ValueError(f"axis of an actuator fault must be 0, 1, 2 or None, got "
                                 f"{self.axis!r}")
            if self.kind == "loss_of_effectiveness" and not 0.0 <= self.value <= 1.0:
                raise ValueError(f"loss_of_effectiveness value is the share delivered, in "
                                 f"[0, 1], got {self.value}")
        elif self.group not in ("attitude", "rate", "deflection"):
            raise ValueError(f"{self.kind} needs a sensor group ('attitude', 'rate' or "
                             f"'deflection'), got {self.group!r}")
        elif self.axis is not None and (isinstance(self.axis, bool) or self.axis < 0):
            raise ValueError(f"axis must be a channel index >= 0 or None, got {self.axis!r}")

    def active(self, t: float) -> bool:
        """Whether the fault acts at time ``t`` (s).

        Returns
        -------
        bool
            True from the onset for the fault's duration.
        """
        return self.onset_s <= t + 1e-9 < self.onset_s + self.duration_s


def parse_fault(text: str) -> Fault:
    """A :class:`Fault` from its command-line form (``spacecraft control --fault``).

    Parameters
    ----------
    text : str
        ``"kind,onset=S[,duration=S][,axis=I][,group=G][,value=V]"``, e.g.
        ``"loss_of_effectiveness,onset=120,axis=0,value=0.1"`` (hyphens in the kind
        are taken for underscores; times in s, values in SI units).

    Returns
    -------
    Fault

    Raises
    ------
    ValueError
        For a malformed text or an invalid fault (the message says which).
    """
    kind, *pairs = [p.strip() for p in text.split(",")]
    fields: dict[str, Any] = {"kind": kind.replace("-", "_")}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in ("onset", "duration", "axis", "group", "value"):
            raise ValueError(f"fault {text!r}: expected key=value pairs of onset, duration, "
                             f"axis, group and value after the kind, got {pair!r}")
        try:
            if key in ("onset", "duration"):
                fields[f"{key}_s"] = float(value)
            elif key == "axis":
                fields["axis"] = int(value)
            elif key == "group":
                fields["group"] = value.strip()
            else:
                fields["value"] = float(value)
        except ValueError:
            raise ValueError(f"fault {text!r}: {key} must be a number, got {value!r}") from None
    if "onset_s" not in fields:
        raise ValueError(f"fault {text!r}: onset=S is required")
    return Fault(**fields)


class FaultInjection(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Inject a schedule of :class:`Fault` s into a flexible-spacecraft environment.

    Parameters
    ----------
    env : gymnasium.Env
        A flexible-spacecraft env (``spacecraft_env``), wrappers allowed
        inside; its observation must be the env's own (the sensor groups are
        read from ``env.unwrapped.observation_layout``).
    faults : iterable of Fault
        The schedule.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> from spacecraft_env import Fault, FaultInjection
    >>> env = FaultInjection(gym.make("spacecraft_env:FlexibleSpacecraft-v2"),
    ...                      [Fault("sensor_dropout", onset_s=0.2, group="rate", axis=1)])
    >>> obs, info = env.reset(seed=0)
    >>> for _ in range(2):
    ...     obs, *_, info = env.step(np.zeros(3, dtype=np.float32))
    >>> [f["kind"] for f in info["faults"]], bool(np.isnan(obs[4]))
    (['sensor_dropout'], True)
    """

    def __init__(self, env: gym.Env, faults: Iterable[Fault]) -> None:
        faults = tuple(faults)
        if not all(isinstance(f, Fault) for f in faults):
            raise TypeError("faults must be Fault instances (spacecraft_env.Fault, or "
                            "parse_fault('kind,onset=S,...'))")
        gym.utils.RecordConstructorArgs.__init__(self, faults=faults)
        gym.Wrapper.__init__(self, env)
        base = env.unwrapped
        if not hasattr(base, "observation_layout") or not hasattr(base, "actuator_fault"):
            raise TypeError(f"FaultInjection wraps a flexible-spacecraft environment "
                            f"(spacecraft_env), got {type(base).__name__}")
        layout = base.observation_layout
        self._channels: list[np.ndarray | None] = []
        for fault in faults:
            if fault.kind in ACTUATOR_FAULTS:
                self._channels.append(None)
                continue
            if fault.group not in layout.names:
                raise ValueError(f"{fault.kind} strikes the {fault.group!r} sensors, which "
                                 f"the env does not observe ({layout.names})")
            rows = layout.indices(fault.group)
            if fault.axis is not None and fault.axis >= rows.size:
                raise ValueError(f"the {fault.group!r} group has {rows.size} channels, got "
                                 f"axis {fault.axis}")
            self._channels.append(rows if fault.axis is None else rows[[fault.axis]])
        self.faults = faults
        self._rng = np.random.default_rng()
        self._held: dict[int, np.ndarray] = {}
        self._time = 0.0

    # ------------------------------------------------------------ actuators
    def _deliver(self, torque: np.ndarray) -> np.ndarray:
        """The torque the wheels deliver for the commanded ``torque`` (N m, (3,))."""
        out = np.array(torque, dtype=float)
        for fault in self.faults:
            if fault.kind not in ACTUATOR_FAULTS or not fault.active(self._time):
                continue
            axes = slice(None) if fault.axis is None else fault.axis
            if fault.kind == "loss_of_effectiveness":
                out[axes] = fault.value * out[axes]
            elif fault.kind == "stuck_actuator":
                out[axes] = fault.value
            else:
                out[axes] = out[axes] + fault.value
        return out

    # ------------------------------------------------------------ sensors
    def _observe(self, obs: np.ndarray, t: float) -> np.ndarray:
        obs = np.array(obs, dtype=np.float32)
        for i, (fault, rows) in enumerate(zip(self.faults, self._channels, strict=True)):
            if rows is None:
                continue
            if not fault.active(t):
                self._held.pop(i, None)
                continue
            if fault.kind == "sensor_dropout":
                obs[rows] = np.nan
            elif fault.kind == "stuck_sensor":
                held = self._held.setdefault(i, obs[rows].copy())
                obs[rows] = held
            elif fault.kind == "sensor_bias":
                obs[rows] = obs[rows] + np.float32(fault.value)
            else:
                obs[rows] = obs[rows] + (fault.value * self._rng.standard_normal(rows.size)
                                         ).astype(np.float32)
        return obs

    def _active(self, t: float) -> list[dict[str, Any]]:
        return [asdict(f) for f in self.faults if f.active(t)]

    # ------------------------------------------------------------ gym
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env; no fault acts before its onset.

        Returns
        -------
        (observation, info)
            The first observation and the env's info (``info["faults"]`` lists the
            faults acting).
        """
        obs, info = self.env.reset(seed=seed, options=options)
        # the noise bursts' own generator: the env's noise stream is left as it is, so a
        # faulted episode and a fault-free one of the same seed stay paired
        self._rng = np.random.default_rng(None if seed is None else [seed, 0xFA017])
        self._held = {}
        self._time = 0.0
        self.env.unwrapped.actuator_fault = self._deliver
        info["faults"] = self._active(0.0)
        return self._observe(obs, 0.0), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Step the env with the faults acting at this time applied to the action and the
        observation.

        Returns
        -------
        (observation, reward, terminated, truncated, info)
            The step of the faulted plant (``info["faults"]`` lists the faults acting;
            for scoring, not for controllers).
        """
        base = self.env.unwrapped
        self._time = float(base.time)          # the step's start: the actuators' time
        base.actuator_fault = self._deliver
        obs, reward, terminated, truncated, info = self.env.step(action)
        t = float(info["time"])
        info["faults"] = self._active(t)
        return self._observe(obs, t), reward, terminated, truncated, info
