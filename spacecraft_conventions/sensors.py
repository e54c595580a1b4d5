"""Nominal signal levels of the sensor groups and of the actuators.

These are the physically known ranges of the signals, fixed before any
data are seen: 1 deg of attitude, 0.1 deg/s of body rate, 1 cm of tip
deflection, 1 N m of torque. Everything that needs a scale uses them:

* the environment's measurement noise (``snr_db`` is relative to them),
* the reward's quadratic cost (errors in units of the nominal level),
* the LQR output weights,
* the identifiers' fixed normalization (every channel divided by its level),
* the identified-model features handed to RL agents.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from spacecraft_conventions.units import RAD_PER_DEG

__all__ = ["NOMINAL_SCALE", "NOMINAL_TORQUE", "nominal_scale"]

#: Nominal level of each observed group, SI units (rad, rad/s, m). The task
#: channels ``attitude_error`` and ``reference`` are angles like ``attitude``.
NOMINAL_SCALE: Mapping[str, float] = MappingProxyType({
    "attitude": 1.0 * RAD_PER_DEG,
    "rate": 0.1 * RAD_PER_DEG,
    "deflection": 0.01,
    "attitude_error": 1.0 * RAD_PER_DEG,
    "reference": 1.0 * RAD_PER_DEG,
})

#: Nominal torque level, N m per axis.
NOMINAL_TORQUE: float = 1.0


def nominal_scale(group: str) -> float:
    """Nominal level of one group (SI units).

    Parameters
    ----------
    group : str
        A sensor group: ``"attitude"``, ``"rate"``, ``"deflection"``,
        ``"attitude_error"`` or ``"reference"`` (the keys of :data:`NOMINAL_SCALE`).

    Returns
    -------
    float
        The group's nominal level: rad for the angles (1 deg), rad/s for
        ``"rate"`` (0.1 deg/s), m for ``"deflection"`` (1 cm).

    Raises
    ------
    ValueError
        For a group that is not one of :data:`NOMINAL_SCALE`'s keys.
    """
    try:
        return NOMINAL_SCALE[group]
    except KeyError:
        raise ValueError(f"unknown group {group!r}; expected one of {sorted(NOMINAL_SCALE)}"
                         ) from None
