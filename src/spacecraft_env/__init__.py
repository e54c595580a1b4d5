"""Time-varying flexible spacecraft (ETS-VIII) truth model and Gymnasium environments.

Importing the package registers three environments (250 s episodes,
``max_episode_steps=2500`` at dt = 0.1 s):

* ``FlexibleSpacecraft-v0``: constant (LTI) plant,
* ``FlexibleSpacecraftDocking-v0``: two modules dock at t = 100 s and 180 s,
* ``FlexibleSpacecraftSolarRotation-v0``: paddles turn at 0.2 deg/s.

``gymnasium.make("spacecraft_env:FlexibleSpacecraftDocking-v0")`` works
without a prior import.
"""

from __future__ import annotations

import gymnasium as gym

from spacecraft_env.dynamics import (
    OUTPUT_GROUPS,
    FlexibleSpacecraftModel,
    StateSpaceMatrices,
)
from spacecraft_env.env import OBSERVATION_GROUPS, FlexibleSpacecraftEnv, RewardWeights
from spacecraft_env.parameters import (
    ANTENNA_FREQUENCIES_HZ,
    PADDLE_FREQUENCIES_HZ,
    AppendageParameters,
    DockingModule,
    SpacecraftParameters,
    ets8_parameters,
)
from spacecraft_env.scenarios import (
    SCENARIOS,
    CombinedScenario,
    Configuration,
    ConstantScenario,
    DockingScenario,
    Scenario,
    SolarRotationScenario,
    make_scenario,
)

__all__ = [
    "ANTENNA_FREQUENCIES_HZ",
    "ENV_IDS",
    "OBSERVATION_GROUPS",
    "OUTPUT_GROUPS",
    "PADDLE_FREQUENCIES_HZ",
    "SCENARIOS",
    "AppendageParameters",
    "CombinedScenario",
    "Configuration",
    "ConstantScenario",
    "DockingModule",
    "DockingScenario",
    "FlexibleSpacecraftEnv",
    "FlexibleSpacecraftModel",
    "RewardWeights",
    "Scenario",
    "SolarRotationScenario",
    "SpacecraftParameters",
    "StateSpaceMatrices",
    "ets8_parameters",
    "make_scenario",
    "register_envs",
]

__version__ = "0.1.0"

#: Registered environment ids and their scenarios.
ENV_IDS: dict[str, str] = {
    "FlexibleSpacecraft-v0": "constant",
    "FlexibleSpacecraftDocking-v0": "docking",
    "FlexibleSpacecraftSolarRotation-v0": "solar_rotation",
}


def register_envs() -> None:
    """Register the environments with Gymnasium (idempotent)."""
    for env_id, scenario in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point="spacecraft_env.env:FlexibleSpacecraftEnv",
                max_episode_steps=2500,
                kwargs={"scenario": scenario},
            )


register_envs()
