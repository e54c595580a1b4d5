"""Gymnasium environment: API conformance, determinism, pickling, bad input."""

from __future__ import annotations

import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import spacecraft_env
from controllers import OracleLQG, run_episode
from spacecraft_env import (
    ENV_IDS,
    REWARDS,
    ActionRepeat,
    FlexibleSpacecraftEnv,
    NominalUnits,
    ObservationAverage,
    ObservationGroups,
    ObservationProducts,
    RewardWeights,
)

IDS = sorted(ENV_IDS)


def _rollout(env, seed, n=100):
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    rewards, states = [], []
    for _ in range(n):
        obs, reward, terminated, truncated, info = env.step(
            rng.uniform(-1, 1, 3).astype(np.float32))
        out.append(obs)
        rewards.append(reward)
        states.append(info["state"])
        if terminated or truncated:
            break
    return np.array(out), np.array(rewards), np.array(states)


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_check_env_without_warnings(env_id):
    env = gym.make(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env_without_warnings(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(env, warn=True)
    env.close()


def test_render_rgb_array_passes_check_env():
    env = gym.make("FlexibleSpacecraftDocking-v2", render_mode="rgb_array").unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env)
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (400, 720, 3)
    assert frame.std() > 5  # something is drawn


def test_make_without_prior_import_in_fresh_interpreter():
    code = ("import gymnasium as gym\n"
            "env = gym.make('spacecraft_env:FlexibleSpacecraftDocking-v2')\n"
            "obs, info = env.reset(seed=0)\n"
            "print(env.spec.max_episode_steps, obs.shape, info['time'])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == ["2500", "(10,)", "0.0"]


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec(mode):
    envs = gym.make_vec("spacecraft_env:FlexibleSpacecraftDocking-v2", num_envs=2,
                        vectorization_mode=mode)
    obs, _ = envs.reset(seed=[1, 2])
    assert obs.shape == (2, 10) and not np.allclose(obs[0], obs[1])
    for _ in range(5):
        obs, reward, _term, _trunc, _info = envs.step(np.zeros((2, 3), dtype=np.float32))
    assert reward.shape == (2,) and np.all(np.isfinite(reward))
    envs.close()


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_rollout(env_id):
    a = _rollout(gym.make(env_id), seed=7)
    b = _rollout(gym.make(env_id), seed=7)
    c = _rollout(gym.make(env_id), seed=8)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0])


def test_pickled_env_reproduces_reset_and_steps():
    env = FlexibleSpacecraftEnv("solar_rotation", randomize=True)
    env.reset(seed=3)
    for _ in range(10):
        env.step(np.array([0.3, -0.2, 0.1]))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(20):
        a = np.array([0.5, 0.1, -0.4])
        o1, r1, *_ , i1 = env.step(a)
        o2, r2, *_ , i2 = clone.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2
        np.testing.assert_array_equal(i1["state"], i2["state"])
    # and a fresh reset with the same seed agrees too
    np.testing.assert_array_equal(env.reset(seed=11)[0], clone.reset(seed=11)[0])


def test_info_and_time_and_torque_scaling():
    env = FlexibleSpacecraftEnv("docking", max_torque=5.0)
    _, info = env.reset(seed=0)
    assert info["time"] == 0.0 and info["state"].dtype == np.float64
    _, _, _, _, info = env.step(np.array([2.0, -0.5, 0.0]))  # clipped to [1, -0.5, 0]
    np.testing.assert_allclose(info["torque"], [5.0, -2.5, 0.0])
    assert info["time"] == pytest.approx(0.1)
    assert info["state"].shape == (env.model.n,)


def test_noise_follows_snr_and_none_is_noiseless():
    quiet = FlexibleSpacecraftEnv("constant", snr_db=None, outputs=("attitude",))
    obs, info = quiet.reset(seed=0)
    np.testing.assert_allclose(obs, info["state"][:3].astype(np.float32))
    env = FlexibleSpacecraftEnv("constant", snr_db=40.0, outputs=("attitude",))
    samples = np.array([env.reset(seed=s)[0] - env.state[:3] for s in range(400)])
    expected = np.deg2rad(1.0) * 10 ** (-40 / 20)
    assert samples.std() == pytest.approx(expected, rel=0.1)


def test_reset_options_and_slew_observation():
    env = FlexibleSpacecraftEnv("constant", outputs=("attitude_error", "reference"),
                                snr_db=None)
    obs, _ = env.reset(seed=0, options={"initial_attitude": [0.01, 0.0, -0.02],
                                        "reference_attitude": [0.05, 0.0, 0.0]})
    np.testing.assert_allclose(obs, np.float32([-0.04, 0, -0.02, 0.05, 0, 0]), atol=1e-7)
    slew = FlexibleSpacecraftEnv("constant", task="slew")
    _, info = slew.reset(seed=1)
    assert np.any(info["reference"] != 0) and np.all(info["state"][:3] == 0)


def test_reward_is_negative_quadratic_cost():
    env = FlexibleSpacecraftEnv("constant", snr_db=None)
    env.reset(seed=0, options={"initial_attitude": [np.deg2rad(2.0), 0.0, 0.0]})
    _, reward, *_ = env.step(np.zeros(3))
    assert reward == pytest.approx(-4.0, rel=1e-9)  # (2 deg / 1 deg)^2, all else zero
    env.reset(seed=0, options={"initial_attitude": [0.0, 0.0, 0.0]})
    _, reward, _, _, info = env.step(np.array([1.0, 0.0, 0.0]))
    # from rest, 10 N m on roll for one step: 0.3 per (N m)^2 of torque, and the
    # outputs of the state it produced, x_1 = B_d u (each in units of its nominal level)
    y = env.model.C @ info["state"]
    levels = env.model.output_layout.scales()
    weights = np.r_[np.ones(6), np.full(y.size - 6, 0.1)]
    assert np.allclose(info["state"], env.model.discrete(0.0)[1] @ [10.0, 0, 0], rtol=1e-12)
    assert reward == pytest.approx(-(0.3 * 100 + weights @ (y / levels) ** 2), rel=1e-9)


def test_terminates_when_attitude_leaves_small_angle_range():
    env = FlexibleSpacecraftEnv("constant", max_attitude_deg=5.0, initial_attitude_deg=1.0)
    env.reset(seed=0, options={"initial_attitude": [np.deg2rad(4.9), 0, 0],
                               "initial_rate": [np.deg2rad(1.0), 0, 0]})
    terminated = False
    for _ in range(10):
        *_, terminated, truncated, _ = env.step(np.zeros(3))
        assert not truncated
        if terminated:
            break
    assert terminated


def test_time_limit_truncates():
    env = gym.make("FlexibleSpacecraft-v2", max_episode_steps=5)
    env.reset(seed=0)
    for _ in range(5):
        *_, terminated, truncated, _ = env.step(np.zeros(3, dtype=np.float32))
    assert truncated and not terminated


def test_randomized_scenario_drawn_from_env_seed():
    env = FlexibleSpacecraftEnv("docking", randomize=True)
    env.reset(seed=4)
    first = env.scenario
    env.reset(seed=4)
    assert env.scenario == first
    env.reset(seed=5)
    assert env.scenario != first


@pytest.mark.parametrize(
    ("action", "error"),
    [
        (np.zeros(2), ValueError),
        (np.zeros((1, 3)), ValueError),
        (np.array([0.0, np.nan, 0.0]), ValueError),
        (np.array([np.inf, 0.0, 0.0]), ValueError),
        (np.array(["a", "b", "c"]), TypeError),
        (np.array([True, False, True]), TypeError),
        (None, TypeError),
    ],
)
def test_bad_actions_raise_and_change_nothing(action, error):
    env = FlexibleSpacecraftEnv("docking")
    env.reset(seed=0)
    before = env.state, env.time
    with pytest.raises(error):
        env.step(action)
    np.testing.assert_array_equal(env.state, before[0])
    assert env.time == before[1]


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"scenario": "orbit"}, ValueError),
        ({"outputs": ("attitude", "gps")}, ValueError),
        ({"outputs": ("rate", "rate")}, ValueError),
        ({"snr_db": float("nan")}, ValueError),
        ({"max_torque": 0.0}, ValueError),
        ({"n_modes": 0}, ValueError),
        ({"task": "dance"}, ValueError),
        ({"render_mode": "ascii"}, ValueError),
        ({"disturbance_torque": [1.0, 2.0]}, ValueError),
        ({"reward_weights": {"attitude": 1.0}}, TypeError),
    ],
)
def test_bad_constructor_arguments(kwargs, error):
    with pytest.raises(error):
        FlexibleSpacecraftEnv(**kwargs)


def test_bad_reset_options():
    env = FlexibleSpacecraftEnv("constant")
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(seed=0, options={"attitude": [0, 0, 0]})
    with pytest.raises(ValueError):
        env.reset(seed=0, options={"initial_attitude": [0.0, 0.0]})
    with pytest.raises(ValueError):
        env.reset(seed=0, options={"reference_attitude": [1.0, 0.0, 0.0]})  # > 20 deg


def test_public_api_exports():
    for name in spacecraft_env.__all__:
        assert hasattr(spacecraft_env, name)


def test_actuator_delay_and_rate_limit_shape_the_applied_torque():
    env = FlexibleSpacecraftEnv("constant", snr_db=None, actuator_delay_steps=2,
                                torque_rate_limit=5.0)                   # 0.5 N m per step
    env.reset(seed=0)
    applied = [env.step(np.ones(3, dtype=np.float32))[4]["torque"][0] for _ in range(5)]
    np.testing.assert_allclose(applied, [0.0, 0.0, 0.5, 1.0, 1.5])
    env.reset(seed=0)                                                     # the queue empties
    assert env.step(np.ones(3, dtype=np.float32))[4]["torque"][0] == 0.0
    with pytest.raises(ValueError, match="actuator_delay_steps"):
        FlexibleSpacecraftEnv(actuator_delay_steps=-1)
    with pytest.raises(ValueError, match="torque_rate_limit"):
        FlexibleSpacecraftEnv(torque_rate_limit=0.0)


def test_paddle_rotation_id_turns_the_paddles_from_90_to_180_deg():
    env = gym.make("FlexibleSpacecraftPaddleRotation-v2")
    _, info = env.reset(seed=0)
    assert np.rad2deg(info["paddle_angle"]) == pytest.approx(90.0)
    model = env.unwrapped.model
    assert np.rad2deg(model.configuration(250.0).paddle_angle) == pytest.approx(180.0)
    drawn = model.scenario.randomized(np.random.default_rng(0))
    assert type(drawn) is type(model.scenario) and drawn.initial_angle_deg == 90.0


@pytest.mark.parametrize("env_name", IDS)
@pytest.mark.parametrize("task", ["regulation", "slew"])
@pytest.mark.parametrize("reward", REWARDS)
def test_crashing_does_not_pay(env_name, task, reward):
    """Full torque until the bound is left < zero torque < LQG, on every id, task and
    reward form."""
    def score(policy):
        env = gym.make(env_name, task=task, reward=reward)
        if policy == "lqg":
            traj = run_episode(env, OracleLQG(env.unwrapped), seed=0)
            return float(traj.rewards.sum()), traj.terminated
        env.reset(seed=0)
        action = np.ones(3, dtype=np.float32) if policy == "crash" else np.zeros(3, np.float32)
        total, done, terminated = 0.0, False, False
        while not done:
            _, r, terminated, truncated, _ = env.step(action)
            total += r
            done = terminated or truncated
        return total, terminated

    crash, crashed = score("crash")
    zero, _ = score("zero")
    lqg, lqg_crashed = score("lqg")
    assert crashed and not lqg_crashed
    assert crash < zero < lqg


def test_randomized_docking_records_its_draw_in_reset_info():
    env = gym.make("FlexibleSpacecraftDocking-v2", randomize=True)
    _, first = env.reset(seed=3)
    _, second = env.reset()
    draws = [first["scenario"], second["scenario"]]
    assert draws[0]["name"] == "docking" and draws[0] != draws[1]
    for draw in draws:
        assert all(400 <= m <= 800 for m in draw["masses_kg"])
        assert 60 <= draw["times_s"][0] <= 140 and draw["times_s"][1] >= draw["times_s"][0] + 20
        offsets = np.array(draw["positions_m"])[:, :2]
        assert np.all(np.abs(offsets) <= 1.0) and np.abs(offsets).max() > 0.05
    # the draw is what the plant flies: off-axis modules couple the axes after docking
    model = env.unwrapped.model
    after = model.inertia(draws[1]["times_s"][1] + 1.0)
    assert abs(after[0, 2]) + abs(after[1, 2]) > abs(model.inertia(0.0)[1, 2]) + 1.0
    _, again = gym.make("FlexibleSpacecraftDocking-v2", randomize=True).reset(seed=3)
    assert again["scenario"] == draws[0]


def test_the_slew_task_observes_its_reference_by_default():
    slew = gym.make("FlexibleSpacecraftDocking-v2", task="slew")
    obs, info = slew.reset(seed=2)
    assert slew.unwrapped.outputs[-1] == "reference"
    np.testing.assert_allclose(obs[-3:], info["reference"], rtol=1e-6)
    assert np.abs(obs[-3:]).max() > 0
    regulation = gym.make("FlexibleSpacecraftDocking-v2")
    assert regulation.unwrapped.outputs == ("attitude", "rate", "deflection")


def _rewards_beside_the_cost(form, weights, steps):
    """(cost reward, ``form`` reward) of each step of one random-torque docking run, both
    envs fed the same actions, up to ``steps`` or the first termination."""
    envs = [gym.make("FlexibleSpacecraftDocking-v2", reward=f, reward_weights=weights)
            for f in ("cost", form)]
    for env in envs:
        env.reset(seed=4)
    rng = np.random.default_rng(0)
    pairs = []
    for _ in range(steps):
        action = rng.uniform(-1, 1, 3).astype(np.float32)
        (_, r_cost, term, *_), (_, r_form, term_f, *_) = (env.step(action) for env in envs)
        assert term == term_f
        if term:
            break
        pairs.append((r_cost, r_form))
    return pairs


def test_bounded_reward_is_one_minus_the_saturated_cost():
    """Both reward forms see the same stage cost: bounded = 1 - min(cost / saturation, 1)."""
    seen = []
    for r_cost, r_bounded in _rewards_beside_the_cost("bounded", RewardWeights(saturation=20.0),
                                                      2500):
        assert r_bounded == pytest.approx(1.0 - min(-r_cost / 20.0, 1.0), abs=1e-12)
        seen.append(r_bounded)
    # the run covers both the graded range and saturation
    assert min(seen) == 0.0 and 0.1 < max(seen) < 1.0


def test_log_reward_resolves_precision_where_the_bounded_one_cannot():
    """log = 1 - log(1 + cost / precision) / log(1 + saturation / precision), from the same
    stage cost; 0.01 deg and 0.1 deg errors pay visibly different rewards."""
    weights = RewardWeights(saturation=20.0, precision=1e-3)
    seen = []
    for r_cost, r_log in _rewards_beside_the_cost("log", weights, 600):
        want = max(1.0 - np.log1p(-r_cost / 1e-3) / np.log1p(20.0 / 1e-3), 0.0)
        assert r_log == pytest.approx(want, abs=1e-12)
        seen.append(r_log)
    assert 0.0 <= min(seen) and max(seen) <= 1.0
    # at the default weights: a 0.01 deg and a 0.1 deg error on every axis, at rest
    env = FlexibleSpacecraftEnv("constant", reward="log", snr_db=None)
    rewards = {}
    for err_deg in (0.01, 0.1):
        env.reset(seed=0, options={"initial_attitude": np.full(3, np.deg2rad(err_deg)),
                                   "reference_attitude": np.zeros(3)})
        rewards[err_deg] = env.step(np.zeros(3, dtype=np.float32))[1]
    assert rewards[0.01] - rewards[0.1] > 0.1
    bounded = FlexibleSpacecraftEnv("constant", reward="bounded", snr_db=None)
    gaps = []
    for err_deg in (0.01, 0.1):
        bounded.reset(seed=0, options={"initial_attitude": np.full(3, np.deg2rad(err_deg)),
                                       "reference_attitude": np.zeros(3)})
        gaps.append(bounded.step(np.zeros(3, dtype=np.float32))[1])
    assert gaps[0] - gaps[1] < 1e-3


@pytest.mark.parametrize("bad", [{"reward": "sparse"}, {"reward": None}])
def test_unknown_reward_form_raises(bad):
    with pytest.raises(ValueError, match="reward must be one of"):
        FlexibleSpacecraftEnv("docking", **bad)


def test_saturation_must_be_positive():
    with pytest.raises(ValueError, match="saturation"):
        RewardWeights(saturation=0.0)
    with pytest.raises(ValueError, match="precision"):
        RewardWeights(precision=0.0)


def test_action_repeat_sums_the_rewards_of_the_held_steps():
    inner = gym.make("FlexibleSpacecraftSolarRotation-v2", task="slew")
    wrapped = ActionRepeat(gym.make("FlexibleSpacecraftSolarRotation-v2", task="slew"), 7)
    inner.reset(seed=2)
    wrapped.reset(seed=2)
    action = np.array([0.3, -0.2, 0.1], dtype=np.float32)
    for _ in range(3):
        steps = [inner.step(action) for _ in range(7)]
        obs_w, r_w, *_, info = wrapped.step(action)
        assert r_w == pytest.approx(sum(step[1] for step in steps), rel=1e-12)
        assert info["repeated_steps"] == 7
        assert info["time"] == pytest.approx(inner.unwrapped.time)
        np.testing.assert_array_equal(obs_w, steps[-1][0])      # the last step's (noisy) obs
    np.testing.assert_array_equal(wrapped.unwrapped.state, inner.unwrapped.state)


def test_action_repeat_stops_at_the_end_of_the_episode():
    env = ActionRepeat(gym.make("FlexibleSpacecraftDocking-v2"), 1000)
    env.reset(seed=0)
    _, _, terminated, truncated, info = env.step(np.ones(3, dtype=np.float32))
    assert terminated and not truncated            # full torque leaves the bound first
    assert 1 <= info["repeated_steps"] < 1000
    assert info["repeated_steps"] == env.unwrapped._k
    # and at the time limit: 2500 steps are 3 actions of 1000 (the last one cut short)
    env = ActionRepeat(gym.make("FlexibleSpacecraftDocking-v2"), 1000)
    env.reset(seed=0)
    held = [env.step(np.zeros(3, dtype=np.float32))[4]["repeated_steps"] for _ in range(3)]
    assert held == [1000, 1000, 500]


def test_action_repeat_is_recorded_in_the_spec():
    """Like Gymnasium's own wrappers: ``gym.make(env.spec)`` rebuilds it, repeat included."""
    env = ActionRepeat(gym.make("FlexibleSpacecraftDocking-v2"), 5)
    again = gym.make(env.spec)
    assert isinstance(again, ActionRepeat) and again.repeat == 5
    assert pickle.loads(pickle.dumps(env)).repeat == 5


@pytest.mark.parametrize("repeat", [0, -1, 1.5, True, "10"])
def test_action_repeat_rejects_bad_repeat(repeat):
    with pytest.raises(ValueError, match="repeat must be an integer >= 1"):
        ActionRepeat(gym.make("FlexibleSpacecraftDocking-v2"), repeat)


def test_nominal_units_divide_each_channel_by_its_groups_level():
    """1 in the wrapped observation is 1 deg of attitude error, 0.1 deg/s of rate."""
    outputs = ("attitude_error", "rate")
    raw = gym.make("FlexibleSpacecraftFamily-v2", task="slew", outputs=outputs)
    env = NominalUnits(gym.make("FlexibleSpacecraftFamily-v2", task="slew", outputs=outputs))
    obs_raw, _ = raw.reset(seed=3)
    obs, _ = env.reset(seed=3)
    level = np.array([np.deg2rad(1.0)] * 3 + [np.deg2rad(0.1)] * 3)
    np.testing.assert_allclose(obs, obs_raw / level, rtol=1e-6)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    # the space's bounds in the same units: +-2 pi rad of error is +-360 nominal degrees
    np.testing.assert_allclose(env.observation_space.high[:3], 360.0, rtol=1e-6)
    action = np.array([0.2, -0.1, 0.05], dtype=np.float32)
    step_raw, step = raw.step(action), env.step(action)
    np.testing.assert_allclose(step[0], step_raw[0] / level, rtol=1e-6)
    assert step[1] == step_raw[1]                              # the reward is untouched
    assert pickle.loads(pickle.dumps(env)).scales.tolist() == env.scales.tolist()


def test_nominal_units_take_levels_that_replace_a_groups_nominal_one():
    """``levels={"deflection": 0.1}``: the deflections in 10 cm units, the rest nominal."""
    outputs = ("attitude_error", "rate", "deflection")
    raw = gym.make("FlexibleSpacecraftFamily-v2", task="slew", outputs=outputs)
    env = NominalUnits(gym.make("FlexibleSpacecraftFamily-v2", task="slew", outputs=outputs),
                       levels={"deflection": 0.1})
    obs_raw, _ = raw.reset(seed=3)
    obs, _ = env.reset(seed=3)
    n_defl = obs.size - 6
    level = np.array([np.deg2rad(1.0)] * 3 + [np.deg2rad(0.1)] * 3 + [0.1] * n_defl)
    np.testing.assert_allclose(obs, obs_raw / level, rtol=1e-6)
    assert pickle.loads(pickle.dumps(env)).scales.tolist() == env.scales.tolist()
    for level in (np.float32(0.1), np.int64(1), 1):       # any real number, NumPy's too
        assert NominalUnits(raw, levels={"deflection": level}).scales[-1] == float(level)
    for levels, message in (({"torque": 1.0}, "not a group"), ({"rate": 0.0}, "finite positive"),
                            ({"rate": np.inf}, "finite positive"),
                            ({"rate": True}, "finite positive"),
                            ({"rate": np.True_}, "finite positive"),
                            ({"rate": "0.1"}, "finite positive")):
        with pytest.raises(ValueError, match=message):
            NominalUnits(raw, levels=levels)


def test_nominal_units_refuse_an_observation_shorter_than_the_envs_own():
    fewer = ObservationGroups(gym.make("FlexibleSpacecraftFamily-v2"), ("rate",))
    with pytest.raises(ValueError, match="NominalUnits needs the environment's own"):
        NominalUnits(fewer)


def test_nominal_units_and_groups_pass_appended_channels_unchanged():
    """A feature wrapper's appended vector (already normalized) follows the groups as
    it is; the layout's channels are scaled and selected as without it."""
    from controllers import PrivilegedFeatures

    outputs = ("attitude", "rate", "deflection", "attitude_error")
    plain = ObservationGroups(NominalUnits(gym.make("FlexibleSpacecraftFamily-v2",
                                                    task="slew", outputs=outputs)),
                              ("attitude_error", "rate"))
    features = PrivilegedFeatures(gym.make("FlexibleSpacecraftFamily-v2", task="slew",
                                           outputs=outputs))
    env = ObservationGroups(NominalUnits(features), ("attitude_error", "rate"))
    d = features.n_features
    assert env.observation_space.shape == (6 + d,)
    action = np.array([0.2, -0.1, 0.05], dtype=np.float32)
    for obs, (expected, vector) in zip(
            (env.reset(seed=3)[0], env.step(action)[0]),
            ((plain.reset(seed=3)[0], features._feats), (plain.step(action)[0],
                                                         features._feats)), strict=True):
        np.testing.assert_allclose(obs[:6], expected, rtol=1e-6)
        np.testing.assert_array_equal(obs[6:], vector.astype(np.float32))
        assert env.observation_space.contains(obs)
    assert np.abs(obs[6:]).max() > 0.01                  # the vector is there, not zeros


def test_observation_average_is_the_mean_of_the_last_window_samples():
    raw = gym.make("FlexibleSpacecraftDocking-v2", task="slew")
    env = ObservationAverage(gym.make("FlexibleSpacecraftDocking-v2", task="slew"), 4)
    for episode in range(2):                     # the average restarts at each reset
        seen = [raw.reset(seed=episode)[0]]
        obs, _ = env.reset(seed=episode)
        np.testing.assert_allclose(obs, seen[0], rtol=1e-6)
        action = np.array([0.1, -0.2, 0.05], dtype=np.float32)
        for _ in range(6):
            seen.append(raw.step(action)[0])
            obs = env.step(action)[0]
            np.testing.assert_allclose(obs, np.mean(seen[-4:], axis=0), rtol=1e-5, atol=1e-9)
            assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    # the sensor noise's spread falls as sqrt(window): rate channels of a quiet plant
    quiet = [ObservationAverage(gym.make("FlexibleSpacecraft-v2"), w) for w in (1, 16)]
    spread = []
    for env_w in quiet:
        env_w.reset(seed=0)
        rates = [env_w.step(np.zeros(3, dtype=np.float32))[0][3:6] for _ in range(400)]
        spread.append(np.std(np.diff(np.array(rates[50:]), axis=0)))
    assert spread[1] < spread[0] / 3


@pytest.mark.parametrize("window", [0, -1, 1.5, True, "10"])
def test_observation_average_rejects_a_bad_window(window):
    with pytest.raises(ValueError, match="window must be an integer >= 1"):
        ObservationAverage(gym.make("FlexibleSpacecraftDocking-v2"), window)


def test_observation_groups_pass_on_the_named_groups_in_the_order_named():
    outputs = ("attitude", "rate", "deflection", "attitude_error")
    raw = gym.make("FlexibleSpacecraftFamily-v2", task="slew", outputs=outputs)
    env = ObservationGroups(gym.make("FlexibleSpacecraftFamily-v2", task="slew",
                                     outputs=outputs), ("attitude_error", "rate"))
    obs_raw, _ = raw.reset(seed=3)
    obs, _ = env.reset(seed=3)
    rows = [10, 11, 12, 3, 4, 5]
    assert obs.shape == (6,) and obs.dtype == obs_raw.dtype
    np.testing.assert_array_equal(obs, obs_raw[rows])
    np.testing.assert_array_equal(env.observation_space.high, raw.observation_space.high[rows])
    action = np.array([0.2, -0.1, 0.05], dtype=np.float32)
    step_raw, step = raw.step(action), env.step(action)
    np.testing.assert_array_equal(step[0], step_raw[0][rows])
    assert step[1] == step_raw[1] and env.observation_space.contains(step[0])
    assert pickle.loads(pickle.dumps(env)).rows.tolist() == rows
    # over NominalUnits (which keeps the layout): the same channels in nominal units
    nominal = ObservationGroups(NominalUnits(gym.make("FlexibleSpacecraftFamily-v2",
                                                      task="slew", outputs=outputs)),
                                ("attitude_error",))
    np.testing.assert_allclose(nominal.reset(seed=3)[0], obs_raw[10:13] / np.deg2rad(1.0),
                               rtol=1e-6)


@pytest.mark.parametrize("groups", [(), ("rate", "rate"), ("reference",), ["speed"]])
def test_observation_groups_refuse_groups_the_env_does_not_observe(groups):
    with pytest.raises(ValueError, match="groups must be distinct names from the env's layout"):
        ObservationGroups(gym.make("FlexibleSpacecraftDocking-v2"), groups)


def test_observation_groups_refuse_an_observation_shorter_than_the_envs_own():
    fewer = ObservationGroups(gym.make("FlexibleSpacecraftFamily-v2"), ("rate",))
    with pytest.raises(ValueError, match="ObservationGroups needs the environment's own"):
        ObservationGroups(fewer, ("rate",))


def test_observation_products_are_the_state_times_each_scheduling_channel():
    raw = gym.make("FlexibleSpacecraftDocking-v2", task="slew")
    env = ObservationProducts(gym.make("FlexibleSpacecraftDocking-v2", task="slew"), 3, (6, 8))
    obs_raw, _ = raw.reset(seed=2)
    obs, _ = env.reset(seed=2)
    action = np.array([0.3, -0.2, 0.1], dtype=np.float32)
    for _ in range(2):
        x, s = obs_raw[:3].astype(float), obs_raw[[6, 8]].astype(float)
        expected = [x[0], x[1], x[2], x[0] * s[0], x[0] * s[1], x[1] * s[0], x[1] * s[1],
                    x[2] * s[0], x[2] * s[1]]
        np.testing.assert_allclose(obs, expected, rtol=1e-6, atol=1e-12)
        assert obs.dtype == np.float32 and env.observation_space.contains(obs)
        obs_raw, obs = raw.step(action)[0], env.step(action)[0]
    assert obs.shape == (9,) and env.observation_space.shape == (9,)
    copy = pickle.loads(pickle.dumps(env))
    assert copy.state == 3 and copy.schedule.tolist() == [6, 8]


@pytest.mark.parametrize(("state", "schedule", "match"), [
    (0, (6,), "state must be an integer >= 1"),
    (10, (6,), "state must be below"),
    (3, (), "schedule must be distinct"),
    (3, (6, 6), "schedule must be distinct"),
    (3, (2,), "schedule must be distinct"),
    (3, (10,), "schedule must be distinct"),
])
def test_observation_products_refuse_bad_channels(state, schedule, match):
    with pytest.raises(ValueError, match=match):
        ObservationProducts(gym.make("FlexibleSpacecraftDocking-v2"), state, schedule)


def test_observation_products_bounds_are_never_nan():
    """An unbounded channel times one fixed at 0 has an unbounded (not NaN) bound."""
    class Fixed(gym.Env):
        observation_space = gym.spaces.Box(np.array([-np.inf, 0.0, -2.0], dtype=np.float32),
                                           np.array([np.inf, 0.0, 2.0], dtype=np.float32))
        action_space = gym.spaces.Box(-1.0, 1.0, (1,))

    space = ObservationProducts(Fixed(), 1, (1, 2)).observation_space
    assert not np.isnan(space.low).any() and not np.isnan(space.high).any()
    assert np.all(np.isinf(space.high)) and np.all(np.isinf(space.low))


def test_a_mistyped_keyword_names_the_closest_one():
    with pytest.raises(TypeError, match=r"'snr' \(did you mean 'snr_db'\?\)"):
        gym.make("spacecraft_env:FlexibleSpacecraft-v2", snr=40)
    with pytest.raises(ValueError, match=r"unknown scenario 'dock'.*'family'"):
        gym.make("spacecraft_env:FlexibleSpacecraft-v2", scenario="dock")
