"""The accepted range of every physical parameter a user sets: one table, one check.

The environment's constructor, its scenarios, the task family's plant
draws, the command line and sweep files all check a value through
:func:`check_parameter`, so a parameter has one range, one unit and one
error message wherever it is set::

    >>> check_parameter("rotation_rate", 0.36)
    0.36
    >>> check_parameter("rotation_rate", 1e9)
    Traceback (most recent call last):
    ...
    ValueError: rotation_rate must be a number in [-10, 10] deg/s, got 1000000000.0

The ranges are those the model is meant for, with a wide margin: the
small-angle, slow-rotation model of :mod:`spacecraft_env.dynamics` says
nothing useful about a paddle turning at 1e6 deg/s, and a value that only a
typo gives (``1e300``) is refused before any work starts.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

__all__ = ["PARAMETER_LIMITS", "Limit", "check_parameter"]


@dataclass(frozen=True)
class Limit:
    """The accepted values of one parameter.

    Attributes
    ----------
    low, high : float
        Bounds (inclusive unless ``low_open``).
    unit : str
        Unit shown in messages (``""`` for a factor).
    integer : bool
        Only integers (``True`` and ``150.7`` are refused; ``150.0`` is taken).
    low_open : bool
        ``low`` itself is refused.
    """

    low: float
    high: float
    unit: str = ""
    integer: bool = False
    low_open: bool = False

    def describe(self) -> str:
        """``"a number in [-10, 10] deg/s"``, the range in words.

        Returns
        -------
        str
            The range in words.
        """
        kind = "an integer" if self.integer else "a number"
        unit = f" {self.unit}" if self.unit else ""
        return f"{kind} in {'(' if self.low_open else '['}{self.low:g}, {self.high:g}]{unit}"

    def check(self, name: str, value: Any) -> float | int:
        """``value`` as a float (an int when ``integer``) if it is in range.

        Returns
        -------
        float or int
            ``value``.

        Raises
        ------
        ValueError
            Not a number (a bool, a string, an array), not an integer when one
            is needed, or out of range; the message names ``name`` and the range.
        """
        ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(
            value, bool | np.bool_)
        number = float(value) if ok else math.nan
        if ok and self.integer:
            ok = math.isfinite(number) and number == int(number)
        ok = ok and (self.low < number if self.low_open else self.low <= number) \
            and number <= self.high
        if not ok:
            raise ValueError(f"{name} must be {self.describe()}, got {value!r}")
        return int(number) if self.integer else number


#: Every physical parameter's accepted values, by the name the command line and sweep
#: files use. The environment's and scenarios' own fields map onto these names.
PARAMETER_LIMITS: Mapping[str, Limit] = MappingProxyType({
    # sensors and actuators
    "snr_db": Limit(-40.0, 300.0, "dB"),           # noise 100x nominal to 1e-15 of it
    "max_torque": Limit(0.0, 1e4, "N m", low_open=True),
    "actuator_delay_steps": Limit(0, 100, "steps", integer=True),     # 10 s at dt = 0.1 s
    "torque_rate_limit": Limit(0.0, 1e6, "N m/s", low_open=True),
    "disturbance_torque": Limit(-100.0, 100.0, "N m"),
    "disturbance_std": Limit(0.0, 100.0, "N m"),
    # the task
    "initial_attitude_deg": Limit(0.0, 90.0, "deg"),
    "slew_range_deg": Limit(0.0, 90.0, "deg"),
    "max_steps": Limit(1, 10_000_000, "steps", integer=True),
    "torque_weight": Limit(0.0, 1e6, "per (N m)^2", low_open=True),
    # the plant and its scenarios
    "module_mass": Limit(0.0, 1e5, "kg"),
    "docking_time": Limit(0.0, 1e6, "s"),
    "capture_momentum": Limit(-1e4, 1e4, "N m s"),
    "rotation_rate": Limit(-10.0, 10.0, "deg/s"),
    "paddle_angle": Limit(-360.0, 360.0, "deg"),
    "inertia_scale": Limit(0.01, 100.0),
    "stiffness_scale": Limit(0.01, 100.0),
    "actuator_gain": Limit(0.01, 100.0),
})


def check_parameter(key: str, value: Any, name: str | None = None) -> float | int:
    """``value`` checked against ``PARAMETER_LIMITS[key]``; the message says ``name``
    (default ``key``), the field the user set.

    Parameters
    ----------
    key : str
        The parameter's name in :data:`PARAMETER_LIMITS` (e.g. ``"rotation_rate"``).
    value : Any
        The value to check, in the unit of ``PARAMETER_LIMITS[key]`` (e.g.
        deg/s for ``"rotation_rate"``, N m for ``"max_torque"``).
    name : str, optional
        The name the error message uses (default: ``key``).

    Returns
    -------
    float or int
        ``value`` as a float, or as an int for the integer parameters.

    Raises
    ------
    KeyError
        ``key`` is not in :data:`PARAMETER_LIMITS` (a programming error).
    ValueError
        The value is refused (see :meth:`Limit.check`).

    Examples
    --------
    >>> from spacecraft_env import check_parameter
    >>> check_parameter("rotation_rate", 0.36)
    0.36
    >>> check_parameter("actuator_delay_steps", 3.0)
    3
    >>> check_parameter("rotation_rate", 1e9, "rate_deg_s")
    Traceback (most recent call last):
    ...
    ValueError: rate_deg_s must be a number in [-10, 10] deg/s, got 1000000000.0
    """
    return PARAMETER_LIMITS[key].check(key if name is None else name, value)
