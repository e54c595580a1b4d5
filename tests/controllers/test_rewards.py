"""The scored-window reward (controllers.rewards)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import ScoredWindowReward
from controllers.harness import SCORED_FROM_S


def test_the_window_keeps_the_rewards_from_its_start_and_nothing_before():
    raw = gym.make("FlexibleSpacecraftDocking-v2", task="slew", reward="cost")
    env = ScoredWindowReward(gym.make("FlexibleSpacecraftDocking-v2", task="slew",
                                      reward="cost"))
    raw.reset(seed=4)
    env.reset(seed=4)
    action = np.array([0.01, -0.02, 0.005], dtype=np.float32)
    for _ in range(1100):
        r_raw, (_, r, _, _, info) = raw.step(action)[1], env.step(action)
        if info["time"] < SCORED_FROM_S - 1e-9:
            assert r == 0.0
        else:
            assert r == r_raw < 0
    assert info["time"] == pytest.approx(110.0)


def test_a_crash_is_charged_whenever_it_comes():
    raw = gym.make("FlexibleSpacecraftDocking-v2", reward="cost")
    env = ScoredWindowReward(gym.make("FlexibleSpacecraftDocking-v2", reward="cost"))
    raw.reset(seed=0)
    env.reset(seed=0)
    full = np.ones(3, dtype=np.float32)            # full torque leaves the bound early
    while True:
        r_raw, (_, r, terminated, _, info) = raw.step(full)[1], env.step(full)
        if terminated:
            break
        assert r == 0.0
    assert info["time"] < SCORED_FROM_S and r == r_raw
    assert r < -env.unwrapped.termination_penalty() / 2      # the penalty is in it


@pytest.mark.parametrize("start_s", [-1.0, float("nan"), float("inf"), True, "100"])
def test_the_window_refuses_a_bad_start(start_s):
    with pytest.raises(ValueError, match="start_s must be a finite time"):
        ScoredWindowReward(gym.make("FlexibleSpacecraftDocking-v2"), start_s)
