"""Time-varying on-orbit scenarios: functions of time only.

A scenario maps time t (s) to a :class:`Configuration`: the paddle rotation
angle and the modules docked so far. The truth model turns a configuration
into ``M(t)``, ``(A, B, C)``; because configurations are hashable, the model
caches its matrices on them, which makes piecewise-constant scenarios
(docking) cost one matrix exponential per segment.

Scenarios
---------
``constant``
    LTI plant (for checks against closed forms).
``docking``
    Paper Case 1: two 600 kg, 2.35 x 2.45 x 3 m cuboids dock on the yaw axis
    at t = 100 s and t = 180 s (hub mass 2400 -> 3000 -> 3600 kg), the
    system mass centre unchanged.
``solar_rotation``
    Paper Case 2: both paddles turn about pitch at 0.2 deg/s.
``paddle_rotation``
    The paddles turn from 90 deg to 180 deg in one 250 s episode (0.36
    deg/s). A geostationary satellite's paddles track the sun through 360 deg
    a day, so a controller designed with the paddles at 0 deg meets every
    angle; past about 96 deg the paddle mode's coupling to the body changes
    sign relative to that design (it goes with cos and sin of the angle) and a
    fixed design that damps the mode actively destabilizes it. The episode is
    that part of the day, compressed.
``docking_solar_rotation``
    Both at once.

Every scenario also has :meth:`Scenario.randomized`, which draws a concrete
variant (docking times and masses, rotation rate) from a seeded
``np.random.Generator`` for domain randomization.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from spacecraft_env.limits import check_parameter
from spacecraft_env.parameters import DockingModule

__all__ = [
    "SCENARIOS",
    "CombinedScenario",
    "Configuration",
    "ConstantScenario",
    "DockingScenario",
    "PaddleRotationScenario",
    "Scenario",
    "SolarRotationScenario",
    "make_scenario",
]


@dataclass(frozen=True)
class Configuration:
    """Instantaneous configuration of the spacecraft.

    Attributes
    ----------
    paddle_angle : float
        Rotation of the solar paddles about pitch, rad (``theta`` in
        ``T_s(t)``).
    modules : tuple of DockingModule
        Modules docked so far.
    mass_centre_shift : bool
        Take the inertia and coupling about the mass centre the docked
        modules move (True), or keep the paper's assumption that docking
        leaves it where it was (False).
    """

    paddle_angle: float = 0.0
    modules: tuple = ()
    mass_centre_shift: bool = False


class Scenario(ABC):
    """A time-varying scenario: configuration as a function of time only."""

    #: Registry name.
    name: str = "scenario"
    #: True if the configuration is piecewise constant in time.
    piecewise_constant: bool = True

    @abstractmethod
    def configuration(self, t: float) -> Configuration:
        """Configuration at time ``t`` (s).

        Returns
        -------
        Configuration
            The paddle angle and the modules docked at ``t``.
        """

    def paddle_angle(self, t: float) -> float:
        """Paddle angle (rad) at time ``t`` (s): ``configuration(t).paddle_angle``,
        without building the configuration where a subclass can.

        Returns
        -------
        float
            The angle, rad.
        """
        return self.configuration(t).paddle_angle

    def event_times(self) -> tuple[float, ...]:
        """Instants (s) at which the dynamics jump (docking events).

        Between two of them only the paddle angle may change; the truth
        model relies on it to interpolate a block of steps from one
        configuration (a block holding an event is evaluated step by step).

        Returns
        -------
        tuple of float
            The instants, s, increasing (empty without dockings).
        """
        return ()

    def randomized(self, rng: np.random.Generator) -> Scenario:
        """A concrete random variant drawn from ``rng`` (default: self).

        Returns
        -------
        Scenario
            The variant (``self`` for a scenario that draws nothing).
        """
        return self

    def parameters(self) -> dict:
        """The concrete values of this scenario (JSON-ready; the env reports
        them in ``reset``'s info, so a randomized draw is on record).

        Returns
        -------
        dict
            The scenario's name and values.
        """
        return {"name": self.name}


@dataclass(frozen=True)
class ConstantScenario(Scenario):
    """No change: the LTI plant at a fixed paddle angle.

    Parameters
    ----------
    paddle_angle_deg : float
        Fixed paddle rotation, deg.
    """

    paddle_angle_deg: float = 0.0
    name = "constant"

    def __post_init__(self) -> None:
        object.__setattr__(self, "paddle_angle_deg", check_parameter(
            "paddle_angle", self.paddle_angle_deg, "paddle_angle_deg"))

    def configuration(self, t: float) -> Configuration:
        return Configuration(paddle_angle=self.paddle_angle(t))

    def paddle_angle(self, t: float) -> float:
        return float(np.deg2rad(self.paddle_angle_deg))

    def parameters(self) -> dict:
        return {"name": self.name, "paddle_angle_deg": float(self.paddle_angle_deg)}


def _default_modules() -> tuple[DockingModule, ...]:
    return (
        DockingModule(time=100.0, position=(0.0, 0.0, 3.0)),
        DockingModule(time=180.0, position=(0.0, 0.0, -3.0)),
    )


@dataclass(frozen=True)
class DockingScenario(Scenario):
    """Modules dock with the hub at given instants (paper Case 1).

    Parameters
    ----------
    modules : tuple of DockingModule
        Default: the paper's two 600 kg cuboids at +-3 m on the yaw axis,
        docking at t = 100 s and 180 s.
    mass_range : (float, float)
        Module mass range (kg) for :meth:`randomized`.
    first_window, second_window : (float, float)
        Docking-time windows (s) for :meth:`randomized`; the second module
        docks at least 20 s after the first.
    offset_range : float
        Largest off-axis offset (m) for :meth:`randomized`: each module's
        x and y are drawn from +-offset_range around its nominal position
        (from the system mass centre, the paper's convention), so the draw
        also changes the products of inertia, i.e. the axes' coupling.
    mass_centre_shift : bool
        False (default, the paper): module positions are taken from a
        system mass centre that docking does not move. True: positions are
        from the undocked spacecraft's mass centre, and the inertia and
        the appendages' coupling are taken about the mass centre of
        spacecraft plus modules (parallel-axis theorem; the root lever arm
        of every appendage moves with it).
    """

    modules: tuple = field(default_factory=_default_modules)
    mass_range: tuple = (400.0, 800.0)
    first_window: tuple = (60.0, 140.0)
    second_window: tuple = (140.0, 220.0)
    offset_range: float = 1.0
    mass_centre_shift: bool = False
    name = "docking"

    def __post_init__(self) -> None:
        mods = tuple(self.modules)
        if not all(isinstance(m, DockingModule) for m in mods):
            raise TypeError("modules must be DockingModule instances")
        object.__setattr__(self, "modules", tuple(sorted(mods, key=lambda m: m.time)))
        for name in ("mass_range", "first_window", "second_window"):
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo <= hi):
                raise ValueError(f"{name} must be (low, high) with 0 <= low <= high")
        if not (np.isfinite(self.offset_range) and self.offset_range >= 0):
            raise ValueError(f"offset_range must be >= 0 m, got {self.offset_range}")

    def configuration(self, t: float) -> Configuration:
        return Configuration(modules=tuple(m for m in self.modules if t >= m.time),
                             mass_centre_shift=self.mass_centre_shift)

    def paddle_angle(self, t: float) -> float:
        return Configuration.paddle_angle       # docking never turns the paddles

    def event_times(self) -> tuple[float, ...]:
        return tuple(m.time for m in self.modules)

    def parameters(self) -> dict:
        return {"name": self.name,
                "times_s": [m.time for m in self.modules],
                "masses_kg": [m.mass for m in self.modules],
                "positions_m": [list(m.position) for m in self.modules],
                "angular_momenta_Nms": [None if m.angular_momentum is None
                                        else list(m.angular_momentum) for m in self.modules],
                "mass_centre_shift": self.mass_centre_shift}

    def randomized(self, rng: np.random.Generator) -> DockingScenario:
        """Draw docking times, module masses and off-axis offsets (two modules, +-z).

        Returns
        -------
        DockingScenario
            The drawn scenario.
        """
        t1 = rng.uniform(*self.first_window)
        t2 = max(rng.uniform(*self.second_window), t1 + 20.0)
        m1, m2 = rng.uniform(*self.mass_range, size=2)
        offsets = rng.uniform(-self.offset_range, self.offset_range, size=(2, 2))
        base = self.modules if len(self.modules) >= 2 else _default_modules()
        return dataclasses.replace(self, modules=tuple(
            DockingModule(mass=mass, dimensions=mod.dimensions, time=t,
                          angular_momentum=mod.angular_momentum,
                          position=tuple(np.asarray(mod.position) + np.append(off, 0.0)))
            for mod, mass, t, off in zip(base[:2], (m1, m2), (t1, t2), offsets, strict=True)))


@dataclass(frozen=True)
class SolarRotationScenario(Scenario):
    """Both solar paddles rotate about pitch at a constant rate (paper Case 2).

    Parameters
    ----------
    rate_deg_s : float
        Rotation rate, deg/s (paper: 0.2).
    initial_angle_deg : float
        Paddle angle at t = 0, deg.
    rate_range : (float, float)
        Rate range (deg/s) for :meth:`randomized`.
    """

    rate_deg_s: float = 0.2
    initial_angle_deg: float = 0.0
    rate_range: tuple = (0.1, 0.4)
    name = "solar_rotation"
    piecewise_constant = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate_deg_s", check_parameter(
            "rotation_rate", self.rate_deg_s, "rate_deg_s"))
        object.__setattr__(self, "initial_angle_deg", check_parameter(
            "paddle_angle", self.initial_angle_deg, "initial_angle_deg"))
        lo, hi = self.rate_range
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ValueError("rate_range must be (low, high) with low <= high")

    def configuration(self, t: float) -> Configuration:
        return Configuration(paddle_angle=self.paddle_angle(t))

    def paddle_angle(self, t: float) -> float:
        return math.radians(self.initial_angle_deg + self.rate_deg_s * t)

    def parameters(self) -> dict:
        return {"name": self.name, "rate_deg_s": float(self.rate_deg_s),
                "initial_angle_deg": float(self.initial_angle_deg)}

    def randomized(self, rng: np.random.Generator) -> SolarRotationScenario:
        """Draw the rotation rate uniformly from ``rate_range``.

        Returns
        -------
        SolarRotationScenario
            The drawn scenario.
        """
        return dataclasses.replace(self, rate_deg_s=float(rng.uniform(*self.rate_range)))


@dataclass(frozen=True)
class PaddleRotationScenario(SolarRotationScenario):
    """The paddles turn through the angles where a nominal design fails.

    Same physics as :class:`SolarRotationScenario`; the defaults start the
    paddles at 90 deg and turn them at 0.36 deg/s, so one 250 s episode
    covers 90-180 deg (the nominal design, made at 0 deg, is unstable from
    about 96 deg on). Give ``initial_angle_deg`` for any other start.

    Parameters
    ----------
    rate_deg_s : float
        Rotation rate, deg/s.
    initial_angle_deg : float
        Paddle angle at t = 0, deg.
    rate_range : (float, float)
        Rate range (deg/s) for :meth:`randomized`.
    """

    rate_deg_s: float = 0.36
    initial_angle_deg: float = 90.0
    rate_range: tuple = (0.2, 0.5)
    name = "paddle_rotation"


@dataclass(frozen=True)
class CombinedScenario(Scenario):
    """Docking and paddle rotation at the same time.

    Parameters
    ----------
    docking : DockingScenario
        The docking events (modules, times, ``mass_centre_shift``); default:
        the paper's Case 1.
    rotation : SolarRotationScenario
        The paddle rotation (rate, deg/s, and initial angle, deg); default:
        the paper's Case 2, 0.2 deg/s from 0 deg.
    """

    docking: DockingScenario = field(default_factory=DockingScenario)
    rotation: SolarRotationScenario = field(default_factory=SolarRotationScenario)
    name = "docking_solar_rotation"
    piecewise_constant = False

    def configuration(self, t: float) -> Configuration:
        docked = self.docking.configuration(t)
        return Configuration(paddle_angle=self.rotation.paddle_angle(t),
                             modules=docked.modules,
                             mass_centre_shift=docked.mass_centre_shift)

    def paddle_angle(self, t: float) -> float:
        return self.rotation.paddle_angle(t)

    def event_times(self) -> tuple[float, ...]:
        return self.docking.event_times()

    def parameters(self) -> dict:
        return {"name": self.name, "docking": self.docking.parameters(),
                "rotation": self.rotation.parameters()}

    def randomized(self, rng: np.random.Generator) -> CombinedScenario:
        return CombinedScenario(self.docking.randomized(rng), self.rotation.randomized(rng))


#: Scenario names accepted by :func:`make_scenario` and the environments.
SCENARIOS: dict[str, type[Scenario]] = {
    "constant": ConstantScenario,
    "docking": DockingScenario,
    "solar_rotation": SolarRotationScenario,
    "paddle_rotation": PaddleRotationScenario,
    "docking_solar_rotation": CombinedScenario,
}


def make_scenario(scenario: str | Scenario) -> Scenario:
    """Return a scenario instance from its name (or pass one through).

    Parameters
    ----------
    scenario : str or Scenario
        A key of :data:`SCENARIOS` (``"constant"``, ``"docking"``,
        ``"solar_rotation"``, ``"paddle_rotation"``,
        ``"docking_solar_rotation"``), built with its defaults, or a
        :class:`Scenario` instance.

    Returns
    -------
    Scenario
        A new instance for a name; ``scenario`` itself for an instance.

    Raises
    ------
    ValueError
        For an unknown name; the message lists the valid ones.
    TypeError
        For anything that is neither a name nor a :class:`Scenario`.
    """
    if isinstance(scenario, Scenario):
        return scenario
    if not isinstance(scenario, str):
        raise TypeError(f"scenario must be a name or a Scenario, got {type(scenario).__name__}")
    try:
        return SCENARIOS[scenario]()
    except KeyError:
        raise ValueError(
            f"unknown scenario {scenario!r}; expected one of {sorted(SCENARIOS)}"
        ) from None
