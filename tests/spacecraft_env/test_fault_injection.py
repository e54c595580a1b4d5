"""FaultInjection: each fault does what it says, when it says, where it says; the
commanded torque stays what is reported; seeded, picklable, checked."""

from __future__ import annotations

import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from spacecraft_env import FAULT_KINDS, Fault, FaultInjection, env_id, parse_fault


def _env(*faults: Fault, **kwargs) -> FaultInjection:
    return FaultInjection(gym.make(env_id("constant"), snr_db=None, initial_attitude_deg=0.0,
                                   max_episode_steps=60, **kwargs), faults)


def _fly(env, torque, steps=20, seed=0):
    """Constant commanded torque (N m); the observations, infos and final true rates."""
    obs, info = env.reset(seed=seed)
    observations, infos = [obs], [info]
    action = (np.asarray(torque, dtype=float) / env.unwrapped.max_torque).astype(np.float32)
    for _ in range(steps):
        obs, _, _, _, info = env.step(action)
        observations.append(obs)
        infos.append(info)
    nd = env.unwrapped.model.n_dof
    return np.array(observations), infos, info["state"][nd:nd + 3]


def test_a_dead_wheel_delivers_nothing_on_its_axis_and_the_report_does_not_show_it():
    clean = _fly(_env(), [1.0, 1.0, 1.0])[2]
    without_pitch = _fly(_env(), [1.0, 0.0, 1.0])[2]
    dead = _env(Fault("loss_of_effectiveness", onset_s=0.0, axis=1, value=0.0))
    _, infos, rates = _fly(dead, [1.0, 1.0, 1.0])
    np.testing.assert_allclose(rates, without_pitch, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(infos[-1]["torque"], [1.0, 1.0, 1.0], rtol=1e-7)  # commanded
    half = _fly(_env(Fault("loss_of_effectiveness", onset_s=0.0, value=0.5)),
                [1.0, 1.0, 1.0])[2]
    np.testing.assert_allclose(half, 0.5 * clean, rtol=1e-9)


def test_a_stuck_wheel_and_a_biased_one_deliver_their_torque():
    clean = _fly(_env(), [0.2, 0.0, 0.0])[2]
    stuck = _fly(_env(Fault("stuck_actuator", onset_s=0.0, axis=0, value=0.2)),
                 [5.0, 0.0, 0.0])[2]
    np.testing.assert_allclose(stuck, clean, rtol=1e-6)       # the command is float32
    biased = _fly(_env(Fault("actuator_bias", onset_s=0.0, axis=0, value=0.2)),
                  [0.0, 0.0, 0.0])[2]
    np.testing.assert_allclose(biased, clean, rtol=1e-6)


def test_sensor_faults_strike_their_channels_during_their_window():
    faults = (Fault("sensor_dropout", onset_s=0.5, duration_s=0.5, group="rate", axis=2),
              Fault("stuck_sensor", onset_s=0.3, group="attitude", axis=0),
              Fault("sensor_bias", onset_s=1.0, group="deflection", value=0.01),
              Fault("noise_burst", onset_s=1.0, group="attitude", axis=1, value=1e-3))
    env = _env(*faults)
    obs, infos, _ = _fly(env, [1.0, 2.0, 3.0], steps=15)
    layout = env.unwrapped.observation_layout
    rate_z, att_x = layout.indices("rate")[2], layout.indices("attitude")[0]
    assert np.isnan(obs[5:10, rate_z]).all() and np.isfinite(obs[np.r_[0:5, 10:16], rate_z]).all()
    assert (obs[3:, att_x] == obs[3, att_x]).all() and obs[3, att_x] != obs[15, att_x] + 1
    clean, _, _ = _fly(_env(), [1.0, 2.0, 3.0], steps=15)
    defl = layout.indices("deflection")
    np.testing.assert_allclose(obs[10:, defl] - clean[10:, defl], 0.01, atol=1e-6)
    att_y = layout.indices("attitude")[1]
    burst = obs[10:, att_y] - clean[10:, att_y]
    assert np.abs(burst).max() > 1e-4 and (obs[:10, att_y] == clean[:10, att_y]).all()
    assert [f["kind"] for f in infos[6]["faults"]] == ["sensor_dropout", "stuck_sensor"]
    assert [f["kind"] for f in infos[12]["faults"]] == ["stuck_sensor", "sensor_bias",
                                                        "noise_burst"]


def test_injection_is_seeded_and_pickles():
    faults = (Fault("noise_burst", onset_s=0.0, group="rate", value=1e-3),
              Fault("loss_of_effectiveness", onset_s=0.5, axis=2, value=0.3))
    first, _, _ = _fly(_env(*faults), [0.5, 0.5, 0.5], seed=3)
    again, _, _ = _fly(pickle.loads(pickle.dumps(_env(*faults))), [0.5, 0.5, 0.5], seed=3)
    np.testing.assert_array_equal(first, again)
    other, _, _ = _fly(_env(*faults), [0.5, 0.5, 0.5], seed=4)
    assert not np.array_equal(first, other)


def test_the_wrapped_env_passes_the_checker():
    env = FaultInjection(gym.make(env_id("docking")),
                         [Fault("loss_of_effectiveness", onset_s=5.0, axis=0, value=0.1)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # the checker's note that it checks a wrapper is what this test asks for
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(env.unwrapped)
        check_env(env, skip_render_check=True)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"kind": "gremlin", "onset_s": 1.0}, "unknown fault kind"),
    ({"kind": "actuator_bias", "onset_s": -1.0}, "onset_s must be"),
    ({"kind": "actuator_bias", "onset_s": 1.0, "duration_s": 0.0}, "duration_s must be"),
    ({"kind": "loss_of_effectiveness", "onset_s": 1.0, "value": 1.5}, r"in \[0, 1\]"),
    ({"kind": "actuator_bias", "onset_s": 1.0, "axis": 3}, "must be 0, 1, 2 or None"),
    ({"kind": "sensor_bias", "onset_s": 1.0}, "needs a sensor group"),
    ({"kind": "stuck_actuator", "onset_s": 1.0, "group": "rate"}, "no sensor group"),
    ({"kind": "sensor_bias", "onset_s": 1.0, "group": "rate", "value": math.nan},
     "value must be finite"),
])
def test_a_bad_fault_is_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Fault(**kwargs)


def test_faults_parse_from_the_command_line_form():
    assert parse_fault("loss-of-effectiveness,onset=120,axis=0,value=0.1") == Fault(
        "loss_of_effectiveness", onset_s=120.0, axis=0, value=0.1)
    assert parse_fault("sensor_bias, onset=120, group=rate, axis=1, value=1.7e-4, "
                       "duration=20").duration_s == 20.0
    with pytest.raises(ValueError, match="onset=S is required"):
        parse_fault("sensor_dropout,group=rate")
    with pytest.raises(ValueError, match="expected key=value pairs"):
        parse_fault("sensor_dropout,onset=3,when=4")
    with pytest.raises(ValueError, match="axis must be a number"):
        parse_fault("actuator_bias,onset=3,axis=x")
    assert set(FAULT_KINDS) >= {"stuck_sensor", "noise_burst"}


def test_a_fault_on_a_group_the_env_does_not_observe_is_refused():
    env = gym.make(env_id("constant"), outputs=("attitude", "rate"))
    with pytest.raises(ValueError, match="does not observe"):
        FaultInjection(env, [Fault("sensor_dropout", onset_s=1.0, group="deflection")])
    with pytest.raises(TypeError, match="flexible-spacecraft"):
        FaultInjection(gym.make("Pendulum-v1"), [])
