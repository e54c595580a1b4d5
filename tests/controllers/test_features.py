"""RL bridge: the identified-model features wrapper."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import IdentifiedModelFeatures, OracleModelFeatures
from identifiers import MomentRefitRPBSID
from spacecraft_conventions import STANDARD_OUTPUTS


def _wrapped(**kwargs):
    env = gym.make("FlexibleSpacecraftDocking-v2")
    ident = MomentRefitRPBSID(22, 15, 0.999, warmup=100, regularization=0.001,
                              input_scale=np.ones(3), output_scale=STANDARD_OUTPUTS.scales())
    return IdentifiedModelFeatures(env, identifier=ident, **kwargs)


def test_features_pass_both_env_checkers_without_warnings():
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    from gymnasium.utils.env_checker import check_env

    env = _wrapped()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(env, warn=True)
        # Gymnasium's checker flags any wrapper as such ("is different from the
        # unwrapped version"); only that notice is allowed, all else errors.
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(env, skip_render_check=True)


def test_features_layout_and_warmup_flag():
    env = _wrapped(n_modes=3)
    assert env.observation_space.shape == (10 + 22 + 6 + 6 + 10 + 1,)
    obs, _ = env.reset(seed=0)
    assert obs[-1] == 0.0 and np.all(obs[10:] == 0)
    rng = np.random.default_rng(0)
    for _ in range(150):
        obs, *_ = env.step(rng.uniform(-0.3, 0.3, 3).astype(np.float32))
    assert obs[-1] == 1.0
    assert env.observation_space.contains(obs)
    freqs = obs[10 + 22 + 6:10 + 22 + 6 + 3]
    assert np.all(freqs >= 0) and np.any(freqs > 0)
    gain = obs[10 + 22:10 + 22 + 6]            # J^-1 times the nominal mean inertia
    assert np.all(gain[[0, 3, 5]] > 0.1)


def test_features_pickle_and_vector_envs():
    env = _wrapped()
    env.reset(seed=1)
    for _ in range(120):
        env.step(np.full(3, 0.1, dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    a = np.array([0.2, -0.1, 0.05], dtype=np.float32)
    np.testing.assert_array_equal(env.step(a)[0], clone.step(a)[0])
    vec = gym.make_vec("spacecraft_env:FlexibleSpacecraftDocking-v2", num_envs=2,
                       vectorization_mode="sync", wrappers=[IdentifiedModelFeatures])
    obs, _ = vec.reset(seed=[0, 1])
    assert obs.shape == (2, 10 + 22 + 6 + 8 + 10 + 1)
    vec.close()
    sb3_vec = pytest.importorskip("stable_baselines3.common.vec_env")
    venv = sb3_vec.DummyVecEnv([lambda: _wrapped(), lambda: _wrapped()])
    assert venv.reset().shape == (2, 57)


def test_features_reject_env_without_sensors():
    env = gym.make("FlexibleSpacecraft-v2", outputs=("reference",))
    with pytest.raises(ValueError, match="sensor group"):
        IdentifiedModelFeatures(env)


def test_oracle_features_follow_the_true_plant_through_docking():
    from gymnasium.utils.env_checker import check_env

    env = OracleModelFeatures(gym.make("FlexibleSpacecraftDocking-v2"), n_modes=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    model = env.unwrapped.model
    j0 = np.mean(np.diag(model.inertia(0.0)))
    np.testing.assert_allclose(obs[10:16], np.linalg.inv(model.inertia(0.0))[np.triu_indices(3)]
                               * j0, rtol=1e-6)
    np.testing.assert_allclose(obs[16:18], model.modal(0.0)[0][:2], rtol=1e-6)
    for _ in range(1900):                      # past both dockings (100 s, 180 s)
        obs, *_ = env.step(np.zeros(3, dtype=np.float32))
    # heavier: the yaw-axis entries of J^-1 fall (modules dock on the yaw axis)
    after = np.linalg.inv(model.inertia(190.0))[np.triu_indices(3)] * j0
    np.testing.assert_allclose(obs[10:16], after, rtol=1e-6)
    assert obs[10] < 0.9 * np.linalg.inv(model.inertia(0.0))[0, 0] * j0


@pytest.mark.parametrize("keep", [False, True])
def test_keep_identifier_carries_the_model_over_episode_resets(keep):
    env = IdentifiedModelFeatures(gym.make("FlexibleSpacecraftDocking-v2"), keep_identifier=keep)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(520):                 # past the default identifier's 500-sample warm-up
        obs, *_ = env.step(rng.uniform(-0.3, 0.3, 3).astype(np.float32))
    assert obs[-1] == 1.0
    gain = obs[10 + 22:10 + 22 + 6].copy()
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)
    if keep:       # a model from the first step on: the flag and the learnt gain
        assert obs[-1] == 1.0
        np.testing.assert_array_equal(obs[10 + 22:10 + 22 + 6], gain)
        np.testing.assert_array_equal(obs[10:10 + 22], 0.0)      # the state starts afresh
    else:
        assert obs[-1] == 0.0 and np.all(obs[10:] == 0)


def test_features_without_the_state_estimate():
    env = _wrapped(n_modes=3, include_state=False)
    assert env.observation_space.shape == (10 + 6 + 6 + 10 + 1,)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(150):
        obs, *_ = env.step(rng.uniform(-0.3, 0.3, 3).astype(np.float32))
    assert obs[-1] == 1.0 and env.observation_space.contains(obs)
    assert np.all(obs[10:16][[0, 3, 5]] > 0.1)      # the gain comes first now
