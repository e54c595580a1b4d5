"""Time-varying flexible spacecraft (ETS-VIII) truth model and Gymnasium environments.

Importing the package registers five environments (250 s episodes,
``max_episode_steps=2500`` at dt = 0.1 s):

* ``FlexibleSpacecraft-v2``: constant (LTI) plant,
* ``FlexibleSpacecraftDocking-v2``: two modules dock at t = 100 s and 180 s,
* ``FlexibleSpacecraftSolarRotation-v2``: paddles turn at 0.2 deg/s from 0 deg,
* ``FlexibleSpacecraftPaddleRotation-v2``: paddles turn from 90 to 180 deg,
  where a design made at 0 deg goes unstable;
* ``FlexibleSpacecraftFamily-v2``: the adaptation task, a new plant every
  episode (inertia, modal stiffness, actuator efficiency, docking, paddle
  angle and rate: :mod:`spacecraft_env.family`).

``gymnasium.make("spacecraft_env:FlexibleSpacecraftDocking-v2")`` works
without a prior import.
"""

from __future__ import annotations

from spacecraft_conventions import __version__
from spacecraft_env.dynamics import DRIVE_AXIS, FlexibleSpacecraftModel, StateSpaceMatrices
from spacecraft_env.env import DEFAULT_SNR_DB, REWARDS, FlexibleSpacecraftEnv, RewardWeights
from spacecraft_env.family import PlantDraw, TaskFamily
from spacecraft_env.faults import (
    ACTUATOR_FAULTS,
    FAULT_KINDS,
    SENSOR_FAULTS,
    Fault,
    FaultInjection,
    parse_fault,
)
from spacecraft_env.limits import PARAMETER_LIMITS, Limit, check_parameter
from spacecraft_env.parameters import (
    ANTENNA_FREQUENCIES_HZ,
    PADDLE_FREQUENCIES_HZ,
    AppendageParameters,
    DockingModule,
    SpacecraftParameters,
    ets8_parameters,
)
from spacecraft_env.registration import ENV_IDS, MAX_EPISODE_STEPS, env_id, register_envs
from spacecraft_env.scenarios import (
    SCENARIOS,
    CombinedScenario,
    Configuration,
    ConstantScenario,
    DockingScenario,
    PaddleRotationScenario,
    Scenario,
    SolarRotationScenario,
    make_scenario,
)
from spacecraft_env.wrappers import (
    ActionRepeat,
    NominalUnits,
    ObservationAverage,
    ObservationGroups,
    ObservationProducts,
)

__all__ = [
    "ACTUATOR_FAULTS",
    "ANTENNA_FREQUENCIES_HZ",
    "DEFAULT_SNR_DB",
    "DRIVE_AXIS",
    "ENV_IDS",
    "FAULT_KINDS",
    "MAX_EPISODE_STEPS",
    "PADDLE_FREQUENCIES_HZ",
    "PARAMETER_LIMITS",
    "REWARDS",
    "SCENARIOS",
    "SENSOR_FAULTS",
    "ActionRepeat",
    "AppendageParameters",
    "CombinedScenario",
    "Configuration",
    "ConstantScenario",
    "DockingModule",
    "DockingScenario",
    "Fault",
    "FaultInjection",
    "FlexibleSpacecraftEnv",
    "FlexibleSpacecraftModel",
    "Limit",
    "NominalUnits",
    "ObservationAverage",
    "ObservationGroups",
    "ObservationProducts",
    "PaddleRotationScenario",
    "PlantDraw",
    "RewardWeights",
    "Scenario",
    "SolarRotationScenario",
    "SpacecraftParameters",
    "StateSpaceMatrices",
    "TaskFamily",
    "__version__",
    "check_parameter",
    "env_id",
    "ets8_parameters",
    "make_scenario",
    "parse_fault",
    "register_envs",
]

register_envs()
