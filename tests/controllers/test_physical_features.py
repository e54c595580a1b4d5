"""RL bridge: the physical-parameter features (identified and privileged)."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import FixedLQG, PhysicalFeatures, PrivilegedFeatures, ResidualControl
from controllers.features import PHYSICAL_FEATURE_NAMES, physical_feature_names

N_OBS = 13                       # attitude, rate, four deflections, reference (slew task)
N_FEAT = len(PHYSICAL_FEATURE_NAMES)
GAIN_DIAG = slice(0, 3)
LOG_FREQ = slice(7, 9)


def _checked(env):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(env, warn=True)
        # Gymnasium's checker flags any wrapper as such; only that notice is allowed
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(env, skip_render_check=True)


@pytest.mark.parametrize("wrapper", [PhysicalFeatures, PrivilegedFeatures])
def test_both_wrappers_pass_both_env_checkers(wrapper):
    env = wrapper(gym.make("FlexibleSpacecraftFamily-v2", task="slew"))
    assert env.observation_space.shape == (N_OBS + N_FEAT,)
    _checked(env)


def test_names_describe_every_channel():
    assert len(physical_feature_names(3)) == 7 + 3 * 3 + 4
    assert PHYSICAL_FEATURE_NAMES[-4:] == ("paddle_sin", "paddle_cos", "changed", "ready")


PADDLE = slice(N_FEAT - 4, N_FEAT - 2)


def test_the_paddle_angle_tells_apart_plants_the_rest_of_the_vector_cannot():
    """At 90 and 270 deg the gain and the modes are the same, the modal input coupling's
    sign is not (a fixed LQG is stable at one, unstable at the other): both wrappers
    report the drive's angle, from the first step."""
    vectors = {}
    for angle in (90.0, 270.0):
        plant = {"paddle_angle_deg": angle, "paddle_rate_deg_s": 0.0,
                 "module_masses_kg": [0.0, 0.0]}
        for wrapper in (PrivilegedFeatures, PhysicalFeatures):
            env = wrapper(gym.make("FlexibleSpacecraftFamily-v2", task="slew"))
            obs, _ = env.reset(seed=0, options={"plant": plant})
            vectors[wrapper, angle] = obs[N_OBS:]
            np.testing.assert_allclose(obs[N_OBS:][PADDLE],
                                       [np.sin(np.radians(angle)), np.cos(np.radians(angle))],
                                       atol=1e-6)
    same = slice(0, N_FEAT - 4)
    np.testing.assert_allclose(vectors[PrivilegedFeatures, 90.0][same],
                               vectors[PrivilegedFeatures, 270.0][same], atol=1e-5)
    assert abs(vectors[PrivilegedFeatures, 90.0][PADDLE][0]
               - vectors[PrivilegedFeatures, 270.0][PADDLE][0]) > 1.9


def test_privileged_is_zero_at_the_nominal_plant_and_follows_a_draw():
    env = PrivilegedFeatures(gym.make("FlexibleSpacecraft-v2", task="slew"))
    obs, _ = env.reset(seed=0)
    feats = obs[N_OBS:]
    np.testing.assert_allclose(feats[GAIN_DIAG], 0.0, atol=1e-6)   # the frame's origin
    np.testing.assert_allclose(feats[LOG_FREQ], 0.0, atol=1e-6)
    assert feats[-1] == 1.0 and feats[6] == 0.0                      # known exactly
    family = PrivilegedFeatures(gym.make("FlexibleSpacecraftFamily-v2", task="slew"))
    plant = {"inertia_scale": 1.0, "stiffness_scale": 1.21, "actuator_gain": 0.8,
             "module_masses_kg": [0.0, 0.0], "paddle_angle_deg": 0.0,
             "paddle_rate_deg_s": 0.0}
    obs, _ = family.reset(seed=0, options={"plant": plant})
    feats = obs[N_OBS:]
    # no docking and the paddles at 0 deg: only the efficiency and the stiffness differ
    np.testing.assert_allclose(feats[GAIN_DIAG], np.log(0.8), atol=1e-5)
    assert 0.0 < feats[7] < np.log(1.1) + 1e-3       # a sqrt(1.21) = 1.1 stiffer appendage


def test_privileged_change_flag_marks_a_docking_for_twenty_seconds():
    env = PrivilegedFeatures(gym.make("FlexibleSpacecraftFamily-v2", task="slew"), every=1)
    plant = {"module_masses_kg": [600.0, 0.0], "docking_times_s": [50.0, 200.0],
             "paddle_angle_deg": 0.0, "paddle_rate_deg_s": 0.0}
    env.reset(seed=0, options={"plant": plant})
    flags = []
    for _ in range(1000):
        obs, *_ = env.step(np.zeros(3, dtype=np.float32))
        flags.append(obs[-2])
    t = 0.1 * np.arange(1, 1001)
    changed = t[np.asarray(flags) > 0]
    assert changed.min() == pytest.approx(50.0, abs=0.2)
    assert changed.max() == pytest.approx(70.0, abs=0.2)
    # refreshed every 10 steps (the default), the agent's decisions see the same vector
    sparse = PrivilegedFeatures(gym.make("FlexibleSpacecraftFamily-v2", task="slew"))
    dense = PrivilegedFeatures(gym.make("FlexibleSpacecraftFamily-v2", task="slew"), every=1)
    for wrapper in (sparse, dense):
        wrapper.reset(seed=0, options={"plant": plant})
    for k in range(1, 701):
        a = np.zeros(3, dtype=np.float32)
        (obs_s, *_), (obs_d, *_) = sparse.step(a), dense.step(a)
        if k % 10 == 0:
            np.testing.assert_array_equal(obs_s[N_OBS:], obs_d[N_OBS:])


def _multisine_episode(env, steps, seed=0):
    """Open-loop random-phase multisine (0.01-0.5 Hz, 1 N m RMS per axis) through ``env``."""
    rng = np.random.default_rng(seed)
    freqs = np.linspace(0.01, 0.5, 25)
    phases = rng.uniform(0, 2 * np.pi, (3, freqs.size))
    scale = 0.1 / np.sqrt(freqs.size / 2)
    obs, _ = env.reset(seed=seed)
    for k in range(steps):
        a = scale * np.sin(2 * np.pi * freqs * 0.1 * k + phases).sum(axis=1)
        obs, *_ = env.step(a.astype(np.float32))
    return obs


def test_identified_gain_and_modes_agree_with_the_privileged_ones():
    """Constant plant drawn off-nominal: the identified vector converges to the truth."""
    plant = {"inertia_scale": 1.3, "stiffness_scale": 1.0, "actuator_gain": 0.9,
             "module_masses_kg": [0.0, 0.0], "paddle_angle_deg": 0.0,
             "paddle_rate_deg_s": 0.0}

    class Fixed(gym.Wrapper):
        def reset(self, *, seed=None, options=None):
            return self.env.reset(seed=seed, options={"plant": plant})

    ident = PhysicalFeatures(Fixed(gym.make("FlexibleSpacecraftFamily-v2", task="slew")))
    truth = PrivilegedFeatures(Fixed(gym.make("FlexibleSpacecraftFamily-v2", task="slew")))
    got = _multisine_episode(ident, 1500)[N_OBS:]
    want = _multisine_episode(truth, 1500)[N_OBS:]
    assert got[-1] == 1.0
    # the rigid-body gain of each axis within 5 % (log ratio), its uncertainty reported
    np.testing.assert_allclose(got[GAIN_DIAG], want[GAIN_DIAG], atol=0.05)
    assert 0.0 < got[6] < 0.2          # relative std over all nine entries
    # the nominal would be 0: truth and estimate are well away from it (the hub's own
    # inertia is scaled, not the appendages')
    assert want[0] < -0.15 and got[0] < -0.15
    np.testing.assert_allclose(got[LOG_FREQ], want[LOG_FREQ], atol=0.03)


def test_identified_features_are_zero_before_warm_up_and_restart_every_episode():
    """Every channel but the drive's paddle angle is 0 until the identifier has warmed up."""
    estimated = np.ones(N_FEAT, dtype=bool)
    estimated[PADDLE] = False
    env = PhysicalFeatures(gym.make("FlexibleSpacecraftFamily-v2", task="slew"))
    obs, info = env.reset(seed=0)
    assert np.all(obs[N_OBS:][estimated] == 0.0)
    np.testing.assert_allclose(obs[N_OBS:][PADDLE][1], np.cos(info["paddle_angle"]), atol=1e-6)
    obs = _multisine_episode(env, 450)
    assert obs[-1] == 0.0 and np.all(obs[N_OBS:][estimated] == 0.0)      # the 50 s warm-up
    obs = _multisine_episode(env, 600)
    assert obs[-1] == 1.0
    obs, _ = env.reset(seed=1)
    assert np.all(obs[N_OBS:][estimated] == 0.0) and env.identifier.n_samples == 0


def test_identifier_sees_the_whole_torque_outside_a_residual_controller():
    inner = gym.make("FlexibleSpacecraftFamily-v2", task="slew")
    env = PhysicalFeatures(ResidualControl(inner, FixedLQG(inner.unwrapped)))
    env.reset(seed=0)
    seen = []
    original = env.identifier.update

    def spy(u, y):
        seen.append(np.array(u))
        return original(u, y)

    env.identifier.update = spy
    _, _, _, _, info = env.step(np.zeros(3, dtype=np.float32))
    # a zero residual: the torque fed is the fixed LQG's, in N m
    np.testing.assert_array_equal(seen[0], info["torque"])
    assert np.abs(seen[0]).max() > 0


def test_physical_features_pickle_and_reject_bad_input():
    env = PhysicalFeatures(gym.make("FlexibleSpacecraftFamily-v2", task="slew"))
    _multisine_episode(env, 550)
    clone = pickle.loads(pickle.dumps(env))
    a = np.array([0.02, -0.01, 0.0], dtype=np.float32)
    np.testing.assert_array_equal(env.step(a)[0], clone.step(a)[0])
    with pytest.raises(ValueError, match="n_modes"):
        PhysicalFeatures(gym.make("FlexibleSpacecraft-v2"), n_modes=0)
    with pytest.raises(ValueError, match="every"):
        PhysicalFeatures(gym.make("FlexibleSpacecraft-v2"), every=0)
    with pytest.raises(ValueError, match="'attitude' and 'rate'"):
        PhysicalFeatures(gym.make("FlexibleSpacecraft-v2", outputs=("attitude", "deflection")))
    with pytest.raises(gym.error.ResetNeeded):
        PhysicalFeatures(gym.make("FlexibleSpacecraft-v2")).step(np.zeros(3, np.float32))
