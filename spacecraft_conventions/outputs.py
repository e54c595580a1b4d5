"""Sensor groups, their order and channel labels, and their rows by name.

The plant measures three sensor groups, always stacked in this order:

===============  =====  ======================================  =========
group            size   what                                    label
===============  =====  ======================================  =========
``attitude``     3      roll, pitch, yaw angles psi (rad)        ``psi_x``
``rate``         3      body rates omega (rad/s)                 ``omega_x``
``deflection``   s      out-of-plane appendage deflections (m)   ``w_...``
===============  =====  ======================================  =========

Observations may add two task groups of 3 channels each:
``attitude_error`` (measured psi minus the reference, rad, ``e_x``) and
``reference`` (rad, ``ref_x``).

:class:`OutputLayout` records which groups a vector holds and how many
channels each has, and answers "which rows are the rates?" by name, so no
code parses labels or hard-codes ``C[6:]``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from spacecraft_conventions.sensors import NOMINAL_SCALE

__all__ = [
    "AXES",
    "AXIS_NAMES",
    "LABEL_PREFIX",
    "MEASURES",
    "OBSERVATION_GROUPS",
    "OUTPUT_GROUPS",
    "STANDARD_OUTPUTS",
    "TASK_GROUPS",
    "OutputLayout",
    "match_groups",
]

#: Sensor groups of the plant, in the order they are stacked.
OUTPUT_GROUPS: tuple[str, ...] = ("attitude", "rate", "deflection")
#: Task channels an observation may add after the sensors.
TASK_GROUPS: tuple[str, ...] = ("attitude_error", "reference")
#: Every group an observation may hold.
OBSERVATION_GROUPS: tuple[str, ...] = OUTPUT_GROUPS + TASK_GROUPS
#: What each sensor group measures of the structure: a ``"displacement"``
#: (a coordinate: angles, deflections) or a ``"velocity"`` (its time
#: derivative: body rates). A flexible mode enters a displacement output
#: through its modal coordinate and a velocity output through its rate.
MEASURES: Mapping[str, str] = MappingProxyType({
    "attitude": "displacement", "rate": "velocity", "deflection": "displacement",
})
#: The three body axes, roll / pitch / yaw.
AXES: tuple[str, ...] = ("x", "y", "z")
#: Their names in text, in the same order.
AXIS_NAMES: tuple[str, ...] = ("roll", "pitch", "yaw")
#: Label prefix of each group's channels.
LABEL_PREFIX: Mapping[str, str] = MappingProxyType({
    "attitude": "psi", "rate": "omega", "deflection": "w",
    "attitude_error": "e", "reference": "ref",
})


@dataclass(frozen=True)
class OutputLayout:
    """Which groups a measurement or observation vector holds, in order.

    Parameters
    ----------
    groups : tuple of (str, int)
        ``(group name, number of channels)`` in the order they are stacked;
        names from :data:`OBSERVATION_GROUPS`, each at most once; every
        group but ``deflection`` has 3 channels.

    Examples
    --------
    >>> layout = OutputLayout.of(("attitude", "rate", "deflection"), n_sensors=4)
    >>> layout.slice("rate")
    slice(3, 6, None)
    >>> layout.size
    10
    """

    groups: tuple[tuple[str, int], ...]

    def __post_init__(self) -> None:
        groups = tuple((str(name), int(size)) for name, size in self.groups)
        names = [name for name, _ in groups]
        unknown = [name for name in names if name not in OBSERVATION_GROUPS]
        if unknown or not names or len(set(names)) != len(names):
            raise ValueError(f"groups must be distinct names from {OBSERVATION_GROUPS}, "
                             f"got {tuple(names)}")
        for name, size in groups:
            expected_ok = size >= 1 if name == "deflection" else size == 3
            if not expected_ok:
                raise ValueError(f"group {name!r} has {'>= 1' if name == 'deflection' else 3} "
                                 f"channels, got {size}")
        object.__setattr__(self, "groups", groups)

    @classmethod
    def of(cls, groups: Sequence[str], n_sensors: int) -> OutputLayout:
        """Layout of ``groups`` (in the order given) with ``n_sensors`` deflection channels.

        Returns
        -------
        OutputLayout
            The layout, three channels per group but ``n_sensors`` for "deflection".
        """
        if isinstance(groups, str):
            groups = (groups,)
        return cls(tuple((g, n_sensors if g == "deflection" else 3) for g in groups))

    @property
    def names(self) -> tuple[str, ...]:
        """Group names in order."""
        return tuple(name for name, _ in self.groups)

    @property
    def size(self) -> int:
        """Total number of channels."""
        return sum(size for _, size in self.groups)

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def __iter__(self) -> Iterator[tuple[str, slice]]:
        """``(name, slice)`` of every group in order."""
        start = 0
        for name, size in self.groups:
            yield name, slice(start, start + size)
            start += size

    def slice(self, name: str) -> slice:
        """Rows of group ``name``.

        Returns
        -------
        slice
            The group's rows in the output vector.

        Raises
        ------
        KeyError
            If the layout has no such group (the message lists those it has).
        """
        for group, rows in self:
            if group == name:
                return rows
        raise KeyError(f"no {name!r} channels in this layout; it holds {self.names}")

    def indices(self, name: str) -> np.ndarray:
        """Rows of group ``name`` as an integer array.

        Returns
        -------
        (size,) ndarray of int
            The group's rows in the output vector.
        """
        rows = self.slice(name)
        return np.arange(rows.start, rows.stop)

    def sensor_indices(self) -> np.ndarray:
        """Rows of the sensor groups (not the task channels), in layout order.

        Returns
        -------
        ndarray of int
            The rows of the attitude, rate and deflection groups the layout holds.
        """
        parts = [self.indices(name) for name in self.names if name in OUTPUT_GROUPS]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=int)

    def scales(self) -> np.ndarray:
        """Nominal level of every channel, SI units (see :mod:`.sensors`).

        Returns
        -------
        (size,) ndarray
            Each channel's nominal level: rad, rad/s or m.
        """
        return np.concatenate([np.full(size, NOMINAL_SCALE[name]) for name, size in self.groups])

    def sensors(self) -> OutputLayout:
        """The same layout restricted to the sensor groups.

        Returns
        -------
        OutputLayout
            The sensor groups of this layout, in its order.
        """
        return OutputLayout(tuple((n, s) for n, s in self.groups if n in OUTPUT_GROUPS))


def match_groups(source: OutputLayout, target: OutputLayout) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the groups both layouts hold: ``source[i]`` is ``target[j]``.

    Parameters
    ----------
    source, target : OutputLayout
        E.g. an environment's observation layout and its plant's output
        layout (every plant output, canonical order).

    Returns
    -------
    i, j : ndarray of int
        Equal-length index arrays, in ``source`` order.

    Raises
    ------
    ValueError
        If a shared group has a different number of channels in each.
    """
    src, tgt = [], []
    for name, rows in source:
        if name not in target:
            continue
        other = target.slice(name)
        if other.stop - other.start != rows.stop - rows.start:
            raise ValueError(f"group {name!r} has {rows.stop - rows.start} channels in one "
                             f"layout and {other.stop - other.start} in the other")
        src.append(np.arange(rows.start, rows.stop))
        tgt.append(np.arange(other.start, other.stop))
    if not src:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    return np.concatenate(src), np.concatenate(tgt)


#: The environments' default observation: attitude, rate and one tip
#: deflection sensor on each of the four appendages (10 channels).
STANDARD_OUTPUTS: OutputLayout = OutputLayout.of(OUTPUT_GROUPS, n_sensors=4)
