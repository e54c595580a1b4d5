"""The identifiers the adaptive loop flies: the default for each environment,
the fast option, and what each refuses."""

from __future__ import annotations

import gymnasium as gym
import pytest

from controllers import (
    AdaptiveLQG,
    closed_loop_identifier,
    fast_identifier,
    scheduled_identifier,
    structured_identifier,
)
from identifiers import (
    CLOSED_LOOP_SETTINGS,
    STRUCTURED_CLOSED_LOOP_SETTINGS,
    RigidFlexibleIdentifier,
    ScheduledPhysicalIdentifier,
    StructuredRPBSID,
)
from spacecraft_env import ENV_IDS


@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_the_adaptive_lqg_flies_the_scheduled_fit_on_every_registered_env(env_id):
    env = gym.make(f"spacecraft_env:{env_id}")
    ctrl = AdaptiveLQG(env)
    ident = ctrl.identifier
    assert isinstance(ident, ScheduledPhysicalIdentifier)
    model = env.unwrapped.model
    assert ident.dt == model.dt
    # the env's appendages, as its model describes them, and its sensors
    assert tuple(ident.turning) == model.appendage_turns
    assert tuple(ident.sensor_appendage) == model.sensor_appendage
    assert ident.layout == env.unwrapped.observation_layout.sensors()
    # the warm-up's excitation is the amplitude this identifier asks for
    assert ctrl.excitation.warmup_amplitude == ident.warmup_amplitude == 0.5


def test_without_deflection_sensors_the_loop_flies_the_fast_identifier():
    env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2",
                   outputs=("attitude", "rate", "attitude_error", "reference"))
    ident = closed_loop_identifier(env)
    assert isinstance(ident, RigidFlexibleIdentifier)
    assert ident.layout.names == ("attitude", "rate")
    with pytest.raises(ValueError, match="deflection"):
        scheduled_identifier(env)


def test_a_model_that_does_not_describe_its_appendages_gets_the_fast_identifier():
    env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2")
    del env.unwrapped.model.drive_axis
    assert isinstance(closed_loop_identifier(env), RigidFlexibleIdentifier)
    with pytest.raises(ValueError, match="drive_axis"):
        scheduled_identifier(env)


def test_the_fast_identifier_has_the_closed_loop_settings_and_takes_overrides():
    env = gym.make("spacecraft_env:FlexibleSpacecraftPaddleRotation-v2")
    ident = fast_identifier(env)
    assert isinstance(ident, RigidFlexibleIdentifier)
    assert ident.warmup == CLOSED_LOOP_SETTINGS["warmup"]
    assert ident.rigid_drift == CLOSED_LOOP_SETTINGS["rigid_drift"] == 0.0
    assert ident.n == env.unwrapped.model.n
    assert fast_identifier(env, warmup=200).warmup == 200
    held = scheduled_identifier(env, accumulate=False)
    assert held.accumulate is False


def test_the_structured_identifier_has_its_closed_loop_settings_and_takes_overrides():
    env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2")
    ident = structured_identifier(env)
    assert isinstance(ident, StructuredRPBSID)
    assert ident.warmup == STRUCTURED_CLOSED_LOOP_SETTINGS["warmup"] == 300
    assert ident.process_torque == STRUCTURED_CLOSED_LOOP_SETTINGS["process_torque"]
    assert ident.detect_changes is STRUCTURED_CLOSED_LOOP_SETTINGS["detect_changes"] is False
    assert ident.flexible == "classical"          # the env observes the tip deflections
    assert ident.dt == env.unwrapped.model.dt
    # the open-loop constructor's defaults differ: the settings are what the loop gets
    assert StructuredRPBSID().warmup != ident.warmup
    assert structured_identifier(env, warmup=200, flexible="improved").flexible == "improved"
    # the loop's warm-up excitation lasts the identifier's warm-up
    assert AdaptiveLQG(env, identifier=ident).excitation.warmup_steps == 300


@pytest.mark.parametrize("build", [closed_loop_identifier, fast_identifier,
                                   scheduled_identifier, structured_identifier])
def test_an_env_that_is_not_the_spacecraft_is_refused(build):
    with pytest.raises(TypeError, match="flexible-spacecraft environment"):
        build(gym.make("Pendulum-v1"))
