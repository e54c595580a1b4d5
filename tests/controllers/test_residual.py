"""ResidualControl: an agent's action added to a controller's."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import (
    AdaptiveLQG,
    Controller,
    FixedLQG,
    ResidualControl,
    episode_metrics,
    fast_identifier,
    run_episode,
)

ID = "FlexibleSpacecraftDocking-v2"


class _Constant(Controller):
    """An 'agent' that always sends the same action."""

    def __init__(self, action) -> None:
        self.action = np.asarray(action, dtype=np.float32)

    def act(self, obs, info=None):
        return self.action


def test_zero_residual_flies_the_base_controller_exactly():
    # the adaptive LQG inside the wrapper, with a silent agent, is the adaptive
    # LQG alone: same torques, same identifier, bit for bit
    alone_env = gym.make(ID)
    alone = AdaptiveLQG(alone_env.unwrapped, identifier=fast_identifier(alone_env))
    ref = run_episode(alone_env, alone, seed=3, max_steps=700)
    env = gym.make(ID)
    wrapped = ResidualControl(env, AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env)))
    got = run_episode(wrapped, _Constant(np.zeros(3)), seed=3, max_steps=700)
    np.testing.assert_array_equal(got.torque, ref.torque)
    np.testing.assert_array_equal(got.states, ref.states)
    assert alone.stats["redesigns"] > 0
    assert wrapped.controller.stats["redesigns"] == alone.stats["redesigns"]


def test_residual_is_scaled_added_and_saturated():
    env = gym.make(ID)
    wrapped = ResidualControl(env, FixedLQG(env.unwrapped), scale=0.5)
    wrapped.reset(seed=0)
    for action in ([1.0, -1.0, 0.2], [3.0, 0.0, -0.4]):     # 3.0 is clipped to 1
        _, _, _, _, info = wrapped.step(np.asarray(action, dtype=np.float32))
        base = info["base_action"].astype(float)
        expected = np.clip(base + 0.5 * np.clip(action, -1, 1), -1, 1)
        np.testing.assert_allclose(info["torque"], expected * env.unwrapped.max_torque,
                                   rtol=1e-6)
        np.testing.assert_allclose(info["residual_action"], expected - base, atol=1e-6)


def test_identifier_learns_from_the_applied_torque_not_the_base_action():
    env = gym.make(ID)
    ctrl = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env))
    sent: list[np.ndarray] = []
    update = ctrl.identifier.update
    wrapped = ResidualControl(env, ctrl)
    wrapped.reset(seed=1)

    def recording(u, y):
        sent.append(np.array(u, dtype=float))
        return update(u, y)

    ctrl.identifier.update = recording
    applied = []
    rng = np.random.default_rng(0)
    for _ in range(30):
        _, _, _, _, info = wrapped.step(rng.uniform(-1, 1, 3).astype(np.float32))
        applied.append(info["torque"].copy())
    # sample k reaches the identifier at step k + 1, with the torque applied at k
    assert len(sent) == 29
    np.testing.assert_array_equal(np.array(sent), np.array(applied[:-1]))
    base = np.array([info["base_action"]]) * env.unwrapped.max_torque
    assert not np.allclose(applied[-1], base)


def test_residual_env_passes_both_checkers_pickles_and_is_seeded():
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ID)
    wrapped = ResidualControl(env, FixedLQG(env.unwrapped))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(wrapped, warn=True)
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(wrapped, skip_render_check=True)

    def rollout(w):
        w.reset(seed=5)
        out = [w.step(np.array([0.3, -0.2, 0.1], dtype=np.float32))[0] for _ in range(50)]
        w.reset()                       # unseeded: the controller seed comes from seed 5
        out += [w.step(np.zeros(3, dtype=np.float32))[0] for _ in range(50)]
        return np.array(out)

    e1, e2 = gym.make(ID), gym.make(ID)
    first = rollout(ResidualControl(e1, AdaptiveLQG(e1.unwrapped, identifier=fast_identifier(e1))))
    second = rollout(ResidualControl(e2, AdaptiveLQG(e2.unwrapped, identifier=fast_identifier(e2))))
    np.testing.assert_array_equal(first, second)
    clone = pickle.loads(pickle.dumps(wrapped))
    a = np.array([0.2, -0.1, 0.05], dtype=np.float32)
    np.testing.assert_array_equal(wrapped.step(a)[0], clone.step(a)[0])


def test_residual_rejects_bad_input():
    env = gym.make(ID)
    with pytest.raises(TypeError, match="Controller"):
        ResidualControl(env, controller="lqg")
    with pytest.raises(ValueError, match="scale"):
        ResidualControl(env, FixedLQG(env.unwrapped), scale=0.0)
    wrapped = ResidualControl(env, FixedLQG(env.unwrapped))
    with pytest.raises(gym.error.ResetNeeded):
        wrapped.step(np.zeros(3, dtype=np.float32))
    wrapped.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        wrapped.step(np.zeros(2, dtype=np.float32))
    with pytest.raises(ValueError, match="finite"):
        wrapped.step(np.array([np.nan, 0, 0], dtype=np.float32))


def test_default_base_is_the_adaptive_lqg_and_it_scores_like_it():
    env = gym.make(ID)
    wrapped = ResidualControl(env)
    assert isinstance(wrapped.controller, AdaptiveLQG)
    traj = run_episode(wrapped, _Constant(np.zeros(3)), seed=2, max_steps=300)
    assert episode_metrics(traj, env.unwrapped.model)["stable"]


def test_residual_observations_append_the_error_the_torque_and_the_bases_state():
    from controllers import ResidualObservations, ScheduledLQG

    env = gym.make("FlexibleSpacecraftFamily-v2", task="slew")
    base = ScheduledLQG(env.unwrapped)
    wrapped = ResidualObservations(ResidualControl(env, base, scale=0.05))
    n = env.unwrapped.model.n
    assert wrapped.observation_space.shape == (env.observation_space.shape[0] + 6 + n,)
    obs, info = wrapped.reset(seed=4)
    assert wrapped.observation_space.contains(obs)
    att = env.unwrapped.observation_layout.indices("attitude")
    for _ in range(30):
        obs, _, _, _, info = wrapped.step(np.array([0.5, -0.5, 0.0], dtype=np.float32))
    plain = obs[:env.observation_space.shape[0]]
    extra = obs[env.observation_space.shape[0]:]
    np.testing.assert_allclose(extra[:3], plain[att] - info["reference"], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(extra[3:6], info["torque"] / env.unwrapped.max_torque,
                               rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(extra[6:], base.kf.x, rtol=1e-5, atol=1e-9)
    assert np.any(extra[6:] != 0)
    # the same seed, the same observations
    again, _ = wrapped.reset(seed=4)
    other = gym.make("FlexibleSpacecraftFamily-v2", task="slew")
    first, _ = ResidualObservations(ResidualControl(
        other, ScheduledLQG(other.unwrapped), scale=0.05)).reset(seed=4)
    np.testing.assert_allclose(again, first)
    with pytest.raises(TypeError, match="ResidualControl"):
        ResidualObservations(env)


def test_base_relative_reward_subtracts_the_base_flown_on_the_same_episode():
    from controllers import BaseRelativeReward

    def make():
        env = gym.make(ID, reward="cost")
        return ResidualControl(env, FixedLQG(env.unwrapped), scale=0.5)

    relative = BaseRelativeReward(make())
    relative.reset(seed=4)
    # a silent residual flies its base on the same draw and noise: nothing to gain
    for _ in range(30):
        _, r, _, _, info = relative.step(np.zeros(3, dtype=np.float32))
        assert r == 0.0 and info["base_reward"] < 0.0
    # an active one: its own reward minus what the base alone earns, step by step
    own, base = make(), make()
    own.reset(seed=4)
    base.reset(seed=4)
    relative.reset(seed=4)
    for k in range(30):
        action = np.array([0.4, -0.3, 0.2 * (k % 3)], dtype=np.float32)
        r_own = own.step(action)[1]
        r_base = base.step(np.zeros(3, dtype=np.float32))[1]
        _, r, _, _, info = relative.step(action)
        assert info["base_reward"] == r_base
        assert r == pytest.approx(r_own - r_base, rel=1e-12, abs=1e-15)
    assert r != 0.0                             # the pushes changed the cost
    # the twin flew its own simulator: the agent's env ran 30 steps, not 60
    assert relative.unwrapped.time == pytest.approx(3.0)
    clone = pickle.loads(pickle.dumps(relative))
    a = np.array([0.1, 0.0, -0.1], dtype=np.float32)
    assert clone.step(a)[1] == relative.step(a)[1]
    with pytest.raises(ValueError, match="ResidualControl"):
        BaseRelativeReward(gym.make(ID))


def test_base_relative_reward_passes_both_checkers():
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    from gymnasium.utils.env_checker import check_env

    from controllers import BaseRelativeReward

    env = gym.make(ID, reward="cost")
    wrapped = BaseRelativeReward(ResidualControl(env, FixedLQG(env.unwrapped)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(wrapped, warn=True)
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(wrapped, skip_render_check=True)
