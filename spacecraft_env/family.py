"""A family of spacecraft that no single fixed design serves: the adaptation task.

Every episode of ``FlexibleSpacecraftFamily-v1`` flies a plant drawn from
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
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacecraft_env.parameters import DockingModule, SpacecraftParameters
from spacecraft_env.scenarios import CombinedScenario, DockingScenario, SolarRotationScenario

__all__ = ["PlantDraw", "TaskFamily"]


def _range(name: str, value: Any, low: float = -np.inf) -> tuple[float, float]:
    lo, hi = (float(v) for v in value)
    if not (np.isfinite(lo) and np.isfinite(hi) and low <= lo <= hi):
        raise ValueError(f"{name} must be (low, high) with {low:g} <= low <= high, got {value}")
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
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive factor, got {value}")
            object.__setattr__(self, name, value)
        masses = tuple(float(m) for m in self.module_masses_kg)
        times = tuple(float(t) for t in self.docking_times_s)
        if len(masses) != 2 or len(times) != 2 or min(masses) < 0 \
                or not all(np.isfinite([*masses, *times])):
            raise ValueError("module_masses_kg (>= 0) and docking_times_s need two finite "
                             f"entries each, got {self.module_masses_kg}, {self.docking_times_s}")
        object.__setattr__(self, "module_masses_kg", masses)
        object.__setattr__(self, "docking_times_s", times)
        for name in ("paddle_angle_deg", "paddle_rate_deg_s"):
            value = float(getattr(self, name))
            if not np.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value}")
            object.__setattr__(self, name, value)

    def parameters(self, base: SpacecraftParameters) -> SpacecraftParameters:
        """``base`` with the hub inertia and the modal stiffness of this draw."""
        hub = tuple(tuple(self.inertia_scale * v for v in row) for row in base.hub_inertia)
        factor = float(np.sqrt(self.stiffness_scale))
        appendages = tuple(dataclasses.replace(a, frequencies_hz=tuple(
            factor * f for f in a.frequencies_hz)) for a in base.appendages)
        return dataclasses.replace(base, hub_inertia=hub, appendages=appendages)

    def scenario(self) -> CombinedScenario:
        """The docking and paddle rotation of this draw (modules of zero mass left out)."""
        modules = tuple(DockingModule(mass=m, time=t, position=(0.0, 0.0, z))
                        for m, t, z in zip(self.module_masses_kg, self.docking_times_s,
                                           (3.0, -3.0), strict=True) if m > 0)
        return CombinedScenario(DockingScenario(modules=modules),
                                SolarRotationScenario(rate_deg_s=self.paddle_rate_deg_s,
                                                      initial_angle_deg=self.paddle_angle_deg))

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready values (what ``info["plant"]`` holds)."""
        return {f.name: (list(getattr(self, f.name))
                         if isinstance(getattr(self, f.name), tuple) else getattr(self, f.name))
                for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PlantDraw:
        """A draw from :meth:`as_dict`'s keys (missing ones take the defaults).

        Raises
        ------
        ValueError
            For an unknown key or a bad value.
        """
        known = {f.name for f in dataclasses.fields(cls)}
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
            low = 0.0 if f.name in ("module_mass_kg", "first_docking_s", "second_docking_s") \
                else (1e-6 if f.name in ("inertia_scale", "stiffness_scale", "actuator_gain")
                      else -np.inf)
            object.__setattr__(self, f.name, _range(f.name, getattr(self, f.name), low))

    def draw(self, rng: np.random.Generator) -> PlantDraw:
        """One plant, from ``rng`` (its draws in a fixed order: reproducible)."""
        u = lambda r: float(rng.uniform(*r))  # noqa: E731
        return PlantDraw(
            inertia_scale=u(self.inertia_scale), stiffness_scale=u(self.stiffness_scale),
            actuator_gain=u(self.actuator_gain),
            module_masses_kg=(u(self.module_mass_kg), u(self.module_mass_kg)),
            docking_times_s=(u(self.first_docking_s), u(self.second_docking_s)),
            paddle_angle_deg=u(self.paddle_angle_deg),
            paddle_rate_deg_s=u(self.paddle_rate_deg_s))
