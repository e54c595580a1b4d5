"""A family of spacecraft that no single fixed design serves: the adaptation task.

Every episode of ``FlexibleSpacecraftFamily-v2`` flies a plant drawn from
:class:`TaskFamily`: the hub's inertia scaled, the appendages' modal
stiffness scaled (their cantilever frequencies by its square root), an
actuator efficiency (the torque the wheels deliver per torque commanded:
unknown to the controller, which is told the commanded torque), two modules
of random mass docking at random times, and the solar paddles starting at
any angle and turning at a random rate, so the episodes cover the angles
where a design made at 0 deg is unstable (about 87-236 deg). The draw is a
:class:`PlantDraw`: reported in ``reset``'s ``info["plant"]`` and accepted
back as ``reset(options={"plant": {...}})``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacecraft_env.limits import check_parameter
from spacecraft_env.parameters import DockingModule, SpacecraftParameters
from spacecraft_env.scenarios import CombinedScenario, DockingScenario, SolarRotationScenario

__all__ = ["PlantDraw", "TaskFamily"]


#: The parameter (:data:`spacecraft_env.limits.PARAMETER_LIMITS`) each range of
#: :class:`TaskFamily` draws.
_LIMIT_OF = {"inertia_scale": "inertia_scale", "stiffness_scale": "stiffness_scale",
             "actuator_gain": "actuator_gain", "module_mass_kg": "module_mass",
             "first_docking_s": "docking_time", "second_docking_s": "docking_time",
             "paddle_angle_deg": "paddle_angle", "paddle_rate_deg_s": "rotation_rate"}


def _range(name: str, value: Any, key: str) -> tuple[float, float]:
    """``(low, high)`` with both ends in ``key``'s limits and ``low <= high``."""
    if not isinstance(value, tuple | list) or len(value) != 2:
        raise ValueError(f"{name} must be (low, high), got {value!r}")
    lo, hi = (check_parameter(key, v, name) for v in value)
    if lo > hi:
        raise ValueError(f"{name} must be (low, high) with low <= high, got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class PlantDraw:
    """One plant of the family.

    Attributes
    ----------
    inertia_scale : float
        Factor on the hub's own inertia.
    stiffness_scale : float
        Factor on every appendage mode's stiffness (its frequency scales by the
        square root).
    actuator_gain : float
        Torque delivered per torque commanded.
    module_masses_kg : (float, float)
        Masses of the two docking modules (0: none docks).
    docking_times_s : (float, float)
    paddle_angle_deg : float
        Paddle angle at t = 0.
    paddle_rate_deg_s : float
    """

    inertia_scale: float = 1.0
    stiffness_scale: float = 1.0
    actuator_gain: float = 1.0
    module_masses_kg: tuple = (0.0, 0.0)
    docking_times_s: tuple = (100.0, 180.0)
    paddle_angle_deg: float = 0.0
    paddle_rate_deg_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("inertia_scale", "stiffness_scale", "actuator_gain"):
            object.__setattr__(self, name, check_parameter(name, getattr(self, name)))
        for name, key in (("module_masses_kg", "module_mass"), ("docking_times_s", "docking_time")):
            pair = getattr(self, name)
            if not isinstance(pair, tuple | list) or len(pair) != 2:
                raise ValueError(f"{name} must be two numbers, got {pair!r}")
            object.__setattr__(self, name, tuple(check_parameter(key, v, name) for v in pair))
        for name, key in (("paddle_angle_deg", "paddle_angle"),
                          ("paddle_rate_deg_s", "rotation_rate")):
            object.__setattr__(self, name, check_parameter(key, getattr(self, name), name))

    def parameters(self, base: SpacecraftParameters) -> SpacecraftParameters:
        """``base`` with the hub inertia and the modal stiffness of this draw.

        Returns
        -------
        SpacecraftParameters
            The drawn spacecraft's parameters.
        """
        hub = tuple(tuple(self.inertia_scale * v for v in row) for row in base.hub_inertia)
        factor = float(np.sqrt(self.stiffness_scale))
        appendages = tuple(dataclasses.replace(a, frequencies_hz=tuple(
            factor * f for f in a.frequencies_hz)) for a in base.appendages)
        return dataclasses.replace(base, hub_inertia=hub, appendages=appendages)

    def scenario(self) -> CombinedScenario:
        """The docking and paddle rotation of this draw (modules of zero mass left out).

        Returns
        -------
        Scenario
            The drawn scenario.
        """
        modules = tuple(DockingModule(mass=m, time=t, position=(0.0, 0.0, z))
                        for m, t, z in zip(self.module_masses_kg, self.docking_times_s,
                                           (3.0, -3.0), strict=True) if m > 0)
        return CombinedScenario(DockingScenario(modules=modules),
                                SolarRotationScenario(rate_deg_s=self.paddle_rate_deg_s,
                                                      initial_angle_deg=self.paddle_angle_deg))

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready values (what ``info["plant"]`` holds).

        Returns
        -------
        dict
            Plain floats and lists, keyed by the draw's fields.
        """
        return {f.name: (list(getattr(self, f.name))
                         if isinstance(getattr(self, f.name), tuple) else getattr(self, f.name))
                for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PlantDraw:
        """A draw from :meth:`as_dict`'s keys (missing ones take the defaults).

        Returns
        -------
        PlantDraw
            The draw.

        Raises
        ------
        ValueError
            For an unknown key or a bad value.
        """
        known = {f.name for f in dataclasses.fields(cls)}
        if not isinstance(values, Mapping):
            raise ValueError(f"plant must be a mapping with keys from {sorted(known)}, "
                             f"got {type(values).__name__} {values!r}")
        unknown = set(values) - known
        if unknown:
            raise ValueError(f"unknown plant keys {sorted(unknown)}; expected {sorted(known)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


@dataclass(frozen=True)
class TaskFamily:
    """The distribution of plants of the adaptation task (uniform draws).

    Attributes
    ----------
    inertia_scale : (float, float)
        Hub inertia factor (default 0.7-1.5).
    stiffness_scale : (float, float)
        Modal stiffness factor (default 0.7-1.3: frequencies +-16 %).
    actuator_gain : (float, float)
        Actuator efficiency (default 0.7-1.3).
    module_mass_kg : (float, float)
        Mass of each of the two modules (default 0-800 kg).
    first_docking_s, second_docking_s : (float, float)
        Docking-time windows (defaults 40-140 s and 140-240 s).
    paddle_angle_deg : (float, float)
        Initial paddle angle (default 0-360 deg).
    paddle_rate_deg_s : (float, float)
        Paddle rate (default -0.5 to 0.5 deg/s).
    """

    inertia_scale: tuple = (0.7, 1.5)
    stiffness_scale: tuple = (0.7, 1.3)
    actuator_gain: tuple = (0.7, 1.3)
    module_mass_kg: tuple = (0.0, 800.0)
    first_docking_s: tuple = (40.0, 140.0)
    second_docking_s: tuple = (140.0, 240.0)
    paddle_angle_deg: tuple = (0.0, 360.0)
    paddle_rate_deg_s: tuple = (-0.5, 0.5)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, _range(f.name, getattr(self, f.name),
                                                    _LIMIT_OF[f.name]))

    def draw(self, rng: np.random.Generator) -> PlantDraw:
        """One plant, from ``rng`` (its draws in a fixed order: reproducible).

        Returns
        -------
        PlantDraw
            The drawn plant.
        """
        u = lambda r: float(rng.uniform(*r))  # noqa: E731
        return PlantDraw(
            inertia_scale=u(self.inertia_scale), stiffness_scale=u(self.stiffness_scale),
            actuator_gain=u(self.actuator_gain),
            module_masses_kg=(u(self.module_mass_kg), u(self.module_mass_kg)),
            docking_times_s=(u(self.first_docking_s), u(self.second_docking_s)),
            paddle_angle_deg=u(self.paddle_angle_deg),
            paddle_rate_deg_s=u(self.paddle_rate_deg_s))
