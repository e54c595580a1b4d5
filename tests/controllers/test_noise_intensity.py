"""ProcessNoiseBank: the filter intensity chosen from the innovations, against the known
truth of simulated plants."""

import pickle

import gymnasium as gym
import numpy as np
import pytest

from controllers import AdaptiveLQG, OracleLQG, run_episode, stage_costs
from controllers.noise_intensity import LAG_NATS, NOISE_LEVELS, ProcessNoiseBank
from spacecraft_env import env_id

DT = 0.1
A = np.array([[1.0, DT], [0.0, 1.0]])          # a double integrator, one axis
B = np.array([[DT**2 / 2], [DT]])
C = np.eye(1, 2)
SENSOR = 1e-4                                   # position noise


def _fly(bank, torque_std, steps, seed, a_true=A, break_at=None):
    """Chosen indices, per step, on a plant driven by white torque ``torque_std``."""
    rng = np.random.default_rng(seed)
    x, chosen = np.array([1e-3, 0.0]), []
    for k in range(steps):
        a_plant = a_true if break_at is None or k < break_at else 0.995 * a_true
        y = C @ x + SENSOR * rng.standard_normal(1)
        bank.step(A, B, C, np.array([SENSOR**2]), y, np.zeros(1))
        chosen.append(bank.chosen)
        x = a_plant @ x + B[:, 0] * torque_std * rng.standard_normal()
    return np.array(chosen)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_quiet_plant_is_filtered_as_quiet(seed):
    bank = ProcessNoiseBank(DT, memory_s=20.0)
    chosen = _fly(bank, 0.0, 3000, seed)
    assert NOISE_LEVELS[np.bincount(chosen[1500:]).argmax()] == 0.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_disturbed_plant_gets_its_intensity(seed):
    """White torque of 0.01 N m (a grid level): the quieter filters are rejected, the
    choice is that level or its neighbour for most of the late samples."""
    bank = ProcessNoiseBank(DT, memory_s=20.0)
    chosen = _fly(bank, 0.01, 4000, seed)
    late = np.array(NOISE_LEVELS)[chosen[2000:]]
    assert np.mean((late >= 2e-3) & (late <= 0.05)) > 0.9


def test_a_model_that_stops_fitting_moves_the_choice_up_at_once():
    bank = ProcessNoiseBank(DT, memory_s=20.0)
    chosen = _fly(bank, 0.0, 3000, 0, break_at=2500)
    assert NOISE_LEVELS[chosen[2499]] == 0.0
    assert chosen[2500:2600].min() < len(NOISE_LEVELS) - 1


def test_no_score_falls_further_behind_than_the_floor():
    bank = ProcessNoiseBank(DT, memory_s=1000.0)
    _fly(bank, 0.05, 500, 0)
    assert bank.scores.max() - bank.scores.min() <= LAG_NATS + 1e-9


def test_seeded_runs_repeat_and_the_bank_pickles():
    first, second = ProcessNoiseBank(DT), ProcessNoiseBank(DT)
    np.testing.assert_array_equal(_fly(first, 0.0, 300, 4), _fly(second, 0.0, 300, 4))
    np.testing.assert_array_equal(first.scores, second.scores)
    clone = pickle.loads(pickle.dumps(first))
    y = np.array([1e-4])
    np.testing.assert_array_equal(clone.step(A, B, C, np.array([1e-8]), y, np.zeros(1)),
                                  first.step(A, B, C, np.array([1e-8]), y, np.zeros(1)))


def test_a_sample_with_a_missing_output_is_not_scored():
    bank = ProcessNoiseBank(DT)
    _fly(bank, 0.0, 50, 0)
    before = bank.scores.copy()
    x = bank.step(A, B, C, np.array([1e-8]), np.array([np.nan]), np.zeros(1))
    assert np.isfinite(x).all()
    np.testing.assert_array_equal(bank.scores, before)


@pytest.mark.parametrize("kwargs, match", [
    ({"levels": (0.01, 0.05)}, "decreasing"), ({"levels": ()}, "decreasing"),
    ({"levels": (0.05, -1.0)}, ">= 0"), ({"memory_s": 0.0}, "memory_s"),
    ({"initial_covariance": -1.0}, "initial_covariance"),
])
def test_bad_settings_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ProcessNoiseBank(DT, **kwargs)
    with pytest.raises(ValueError, match="dt"):
        ProcessNoiseBank(0.0)


# ---------------------------------------------------------------- in the loop and the oracle

@pytest.mark.parametrize("make", [AdaptiveLQG, OracleLQG])
@pytest.mark.parametrize("value", [-0.01, float("nan"), float("inf")])
def test_a_noise_intensity_that_is_no_torque_is_refused(make, value):
    env = gym.make(env_id("constant"))
    with pytest.raises(ValueError, match="noise_intensity"):
        make(env, noise_intensity=value)


def test_the_tight_oracle_is_quieter_than_the_oracle_on_a_quiet_plant():
    """The oracle LQG whose filter assumes the plant's true disturbance (none) costs less
    than the one assuming 0.05 N m once its filter has converged (the same law, the
    true model: only the filter differs)."""
    env = gym.make(env_id("constant"), task="regulation", max_episode_steps=4000)
    model = env.unwrapped.model
    late = {}
    for name, ctrl in (("tight", OracleLQG(env, noise_intensity=0.0)),
                       ("loose", OracleLQG(env))):
        traj = run_episode(env, ctrl, seed=3)
        late[name] = stage_costs(traj, model)[:, :4].sum(axis=1)[traj.time >= 300].mean()
    assert late["tight"] < 0.5 * late["loose"]


def test_the_loop_reports_the_intensity_its_filter_flies():
    env = gym.make(env_id("constant"), task="regulation", max_episode_steps=700)
    loop = AdaptiveLQG(env)
    traj = run_episode(env, loop, seed=0)
    assert traj.controller_stats["noise_intensity_Nm"] in NOISE_LEVELS
    assert AdaptiveLQG(env, noise_intensity=0.05).noise_bank is None
