"""The registered environment ids, defined once, and their registration.

Importing :mod:`spacecraft_env` registers them, so
``gymnasium.make("spacecraft_env:FlexibleSpacecraftDocking-v2")`` works
without a prior import.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import gymnasium as gym

__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS", "env_id", "register_envs"]

#: Registered environment id -> scenario name.
ENV_IDS: Mapping[str, str] = MappingProxyType({
    "FlexibleSpacecraft-v2": "constant",
    "FlexibleSpacecraftDocking-v2": "docking",
    "FlexibleSpacecraftSolarRotation-v2": "solar_rotation",
    "FlexibleSpacecraftPaddleRotation-v2": "paddle_rotation",
    "FlexibleSpacecraftFamily-v2": "family",
})

#: Episode length of every registered id: 250 s at dt = 0.1 s.
MAX_EPISODE_STEPS = 2500


def env_id(scenario: str) -> str:
    """The registered id (with the ``spacecraft_env:`` module prefix) of a scenario.

    Parameters
    ----------
    scenario : str
        A scenario name of :data:`ENV_IDS`'s values (``"constant"``,
        ``"docking"``, ``"solar_rotation"``, ``"paddle_rotation"``, ``"family"``).

    Returns
    -------
    str
        ``"spacecraft_env:<id>"``, e.g. ``"spacecraft_env:FlexibleSpacecraftDocking-v2"``
        for ``"docking"``, which ``gymnasium.make`` accepts.

    Raises
    ------
    ValueError
        For a scenario that has no registered id (the message lists those that do).
    """
    for name, registered in ENV_IDS.items():
        if registered == scenario:
            return f"spacecraft_env:{name}"
    raise ValueError(f"no registered environment for scenario {scenario!r}; registered: "
                     f"{sorted(ENV_IDS.values())}")


def register_envs() -> None:
    """Register the environments with Gymnasium (idempotent)."""
    for name, scenario in ENV_IDS.items():
        if name not in gym.registry:
            gym.register(
                id=name,
                entry_point="spacecraft_env.env:FlexibleSpacecraftEnv",
                max_episode_steps=MAX_EPISODE_STEPS,
                kwargs={"scenario": scenario},
            )
