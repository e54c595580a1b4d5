"""Identification in proportion to need: a spacecraft held at rest is not shaken."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from controllers import (
    AdaptiveLQG,
    MotionNeed,
    RobustLQG,
    adaptive_start,
    run_episode,
    same_start_ceiling,
)
from spacecraft_env import env_id


def _at_rest(**kwargs):
    return gym.make(env_id("constant"), task="regulation", initial_attitude_deg=0.0, **kwargs)


def test_noise_alone_is_no_need_and_motion_is():
    env = _at_rest(max_episode_steps=3000)
    need = MotionNeed(env)
    obs, info = env.reset(seed=4)
    for _ in range(2500):                     # 2500 samples of the sensors' noise alone
        assert not need(obs, info["reference"])
        obs, _, _, _, info = env.step(np.zeros(3, dtype=np.float32))
    # a torque moves it: the rate is beyond the noise within a few samples, then latched
    for _ in range(20):
        obs, _, _, _, info = env.step(np.full(3, 0.3, dtype=np.float32))
    assert need(obs, info["reference"])
    assert need(np.zeros_like(obs), info["reference"])
    need.reset()
    assert not need.needed
    # a missing sample shows nothing
    assert not need(np.full_like(obs, np.nan), info["reference"])
    env.close()


def test_without_noise_any_motion_is_a_need_and_rest_is_none():
    env = _at_rest(snr_db=None, max_episode_steps=50)
    need = MotionNeed(env)
    obs, info = env.reset(seed=0)
    assert not need(obs, info["reference"])
    obs, *_ = env.step(np.full(3, 1e-6, dtype=np.float32))
    assert need(obs, info["reference"])
    with pytest.raises(ValueError, match="sigmas must be a finite number > 0"):
        MotionNeed(env, sigmas=0.0)
    env.close()


def test_a_slew_or_an_attitude_to_correct_is_a_need_at_the_first_sample():
    for task in ("slew", "regulation"):
        env = gym.make(env_id("constant"), task=task, max_episode_steps=10)
        obs, info = env.reset(seed=1)
        assert MotionNeed(env)(obs, info["reference"]), task
        env.close()


def test_held_at_rest_the_loop_flies_its_robust_fallback_and_excites_nothing():
    """Past the identifier's first fit: the loop's torques are the robust design's (its
    fallback, the same filter told the same torques), no excitation, every step's cause
    "at rest"; the same start flies the same torques."""
    env = _at_rest(max_episode_steps=450)
    loop = AdaptiveLQG(env)
    traj = run_episode(env, loop, seed=3)
    robust = run_episode(env, RobustLQG(env), seed=3)
    np.testing.assert_allclose(traj.torque, robust.torque, rtol=1e-9, atol=1e-15)
    stats = traj.controller_stats
    assert stats["excited_steps"] == 0 and not traj.excitation.any()
    assert stats["fallback_steps"] == 450
    assert set(stats["fallback_by_after_60s"]) <= {"at rest"}
    assert loop.identifier.model is not None          # it identified all the same
    _, steps = adaptive_start(env)
    start = run_episode(env, same_start_ceiling(env), seed=3)
    np.testing.assert_array_equal(start.torque[:steps], traj.torque[:steps])
    env.close()


def test_identifying_whatever_the_motion_is_the_option_need_sigmas_none():
    env = _at_rest(max_episode_steps=60)
    traj = run_episode(env, AdaptiveLQG(env, need_sigmas=None), seed=3)
    assert traj.controller_stats["excited_steps"] == 60
    assert np.abs(traj.excitation).max() == pytest.approx(0.5)
    env.close()
