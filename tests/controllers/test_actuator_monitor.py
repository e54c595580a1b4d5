"""The actuator monitor: a wheel that does not deliver its command is declared, dated and
valued from the momentum balance; an axis whose wheel does not answer is reported lost;
nothing is declared with healthy wheels."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

from controllers import PD, ActuatorMonitor, AdaptiveLQG, FaultWarning, episode_metrics, run_episode
from controllers.actuator_monitor import CONFIRM_S, SMALLEST_TORQUE
from spacecraft_env import FaultInjection, env_id, parse_fault


def _at_rest(faults=(), steps=600):
    env = gym.make(env_id("constant"), task="regulation", initial_attitude_deg=0.0,
                   max_episode_steps=steps)
    return FaultInjection(env, [parse_fault(f) for f in faults]) if faults else env


def _fly(env, action, monitor, seed=0, steps=None):
    """Steps ``env`` with a normalized ``action`` (constant, or a function of the step),
    the monitor reading each observation and the step's info (the commanded torque)."""
    obs, info = env.reset(seed=seed)
    monitor.reset()
    for k in range(steps or env.spec.max_episode_steps):
        monitor(obs, info)
        now = action(k) if callable(action) else action
        obs, _, terminated, truncated, info = env.step(np.asarray(now, dtype=np.float32))
        if terminated or truncated:
            break
    return monitor


def test_healthy_wheels_at_rest_and_in_a_slew_declare_nothing():
    env = _at_rest()
    with warnings.catch_warnings():
        warnings.simplefilter("error", FaultWarning)
        monitor = _fly(env, np.zeros(3), ActuatorMonitor(env))
        assert monitor.faults == [] and not monitor.declared.any()
        # the balance closes to within the gyro's noise, below the declared size
        assert np.abs(monitor.torque_error).max() < SMALLEST_TORQUE
        slew = gym.make(env_id("paddle_rotation"), task="slew", max_episode_steps=1200)
        traj = run_episode(slew, PD(slew), seed=1)
        monitor = ActuatorMonitor(slew)
        monitor(traj.observations[0])
        for obs, torque in zip(traj.observations[1:], traj.torque, strict=True):
            monitor(obs, {"torque": torque})
        assert monitor.faults == []


@pytest.mark.parametrize("inertia_scale, gain", [(1.5, 0.7), (0.7, 0.7), (0.7, 1.3), (1.5, 1.3)])
def test_the_plant_familys_healthy_extremes_declare_nothing(inertia_scale, gain):
    """The family's corners (hub inertia 0.7-1.5x, wheels delivering 0.7-1.3 of their
    command) with both 800 kg modules docked, a sustained torque commanded on every axis
    (1 N m on pitch, one way then the other): the gain from command to momentum is down
    to 0.33x the nominal one on pitch, and healthy."""
    from spacecraft_env import PlantDraw

    env = gym.make(env_id("family"), task="regulation", initial_attitude_deg=0.0,
                   max_episode_steps=600)
    env.reset(seed=0)
    command = np.array([0.3, 1.0, -0.5]) / env.unwrapped.max_torque
    plant = PlantDraw(inertia_scale=inertia_scale, actuator_gain=gain,
                      module_masses_kg=(800.0, 800.0), docking_times_s=(1.0, 2.0))
    monitor = ActuatorMonitor(env)
    obs, info = env.reset(seed=0, options={"plant": plant})
    with warnings.catch_warnings():
        warnings.simplefilter("error", FaultWarning)
        for k in range(600):
            monitor(obs, info)
            obs, *_, info = env.step((command if k < 300 else -command).astype(np.float32))
    assert monitor.faults == []
    # the balance does see the plant off its nominal gain, by up to 0.66 N m of 1 N m
    assert np.abs(monitor.torque_error).max() > 0.2


def test_a_wheel_at_ten_percent_under_a_sustained_command_is_declared():
    """The same sustained command on the nominal plant, the pitch wheel at 10 %: beyond
    any healthy plant of the family (gain 0.1), declared."""
    env = _at_rest(["loss_of_effectiveness,onset=0,axis=1,value=0.1"])
    command = np.array([0.3, 1.0, -0.5]) / env.unwrapped.max_torque
    with pytest.warns(FaultWarning, match="actuator torque on axis 1"):
        monitor = _fly(env, lambda k: command if k < 300 else -command, ActuatorMonitor(env))
    assert [(f["kind"], f["axis"]) for f in monitor.faults][:1] == [("actuator torque", 1)]


def test_a_wheel_bias_is_declared_dated_and_valued():
    """0.5 N m added on pitch from 20 s, nothing commanded: the balance misses 0.5 N m."""
    env = _at_rest(["actuator_bias,onset=20,axis=1,value=0.5"])
    with pytest.warns(FaultWarning, match="actuator torque on axis 1 \\(pitch\\)"):
        monitor = _fly(env, np.zeros(3), ActuatorMonitor(env))
    (fault,) = monitor.faults
    assert fault["kind"] == "actuator torque" and fault["axis"] == 1
    # longer than a one-off step stays in the window, and within 20 s of the onset
    assert 20.0 + CONFIRM_S < fault["detected_s"] <= 40.0
    assert abs(fault["onset_s"] - 20.0) <= 4.0
    assert monitor.torque_error[1] == pytest.approx(0.5, rel=0.05)
    assert monitor.declared.tolist() == [False, True, False]


def test_a_wheel_that_does_not_answer_is_reported_lost():
    """Pitch commanded ever harder one way (0 to -4 N m over 40 s), its wheel stuck at
    0.5 N m the other way: declared, then the axis reported lost (the delivered torque
    does not follow the command; no other actuator torques pitch)."""
    env = _at_rest(["stuck_actuator,onset=5,axis=1,value=0.5"], steps=400)
    with pytest.warns(FaultWarning, match="no\\s+controller can hold pitch"):
        monitor = _fly(env, lambda k: [0.0, -0.4 * k / 400, 0.0], ActuatorMonitor(env))
    kinds = [(f["kind"], f["axis"]) for f in monitor.faults]
    assert kinds == [("actuator torque", 1), ("axis lost", 1)]
    # the balance sees the whole miss: 0.5 N m delivered against about -3.8 commanded
    assert monitor.torque_error[1] == pytest.approx(0.5 + 3.8, rel=0.1)


def test_the_monitor_pickles_mid_episode_and_resumes_identically():
    env = _at_rest(["actuator_bias,onset=5,axis=2,value=0.3"], steps=300)
    obs, info = env.reset(seed=3)
    monitor, samples = ActuatorMonitor(env), []
    for _ in range(300):
        samples.append((obs, info))
        obs, _, _, _, info = env.step(np.zeros(3, dtype=np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FaultWarning)
        for o, i in samples[:100]:
            monitor(o, i)
        copy = pickle.loads(pickle.dumps(monitor))
        for o, i in samples[100:]:
            monitor(o, i)
            copy(o, i)
    assert copy.faults == monitor.faults and len(monitor.faults) == 1
    np.testing.assert_array_equal(copy.torque_error, monitor.torque_error)


def test_a_one_off_step_of_momentum_is_not_a_wheel_fault():
    """A gyro bias's jump (0.01 deg/s on roll at 10 s: 5 N m s of apparent momentum)
    passes through the balance undeclared."""
    env = _at_rest(["sensor_bias,onset=10,group=rate,axis=0,value=1.745e-4"], steps=400)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FaultWarning)
        monitor = _fly(env, np.zeros(3), ActuatorMonitor(env))
    assert monitor.faults == []
    assert monitor.torque_error[0] == pytest.approx(0.0, abs=SMALLEST_TORQUE)


def test_the_adaptive_loop_carries_the_monitor_and_can_leave_it_out():
    env = _at_rest(steps=10)
    assert isinstance(AdaptiveLQG(env).actuator_monitor, ActuatorMonitor)
    assert AdaptiveLQG(env, monitor_actuators=False).actuator_monitor is None


class _MonitoredPD(PD):
    """A PD law carrying the actuator monitor, its reports in ``stats["faults"]``."""

    def __init__(self, env):
        super().__init__(env)
        self.monitor = ActuatorMonitor(env)
        self.stats = {"faults": self.monitor.faults}

    def reset(self, seed=None):
        super().reset(seed)
        self.monitor.reset()
        self.stats = {"faults": self.monitor.faults}

    def act(self, obs, info=None):
        self.monitor(obs, info)
        return super().act(obs, info)


def test_the_verdict_says_why_when_an_axis_is_lost():
    """A stuck pitch wheel: the PD cannot hold pitch; the verdict names the lost axis
    (checked against the true closed loop: the attitude leaves its bound), and the same
    law on the healthy plant gets no reason."""
    faulted = _at_rest(["stuck_actuator,onset=5,axis=1,value=0.5"], steps=900)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FaultWarning)
        traj = run_episode(faulted, _MonitoredPD(faulted), seed=0)
    metrics = episode_metrics(traj, faulted.unwrapped.model)
    assert metrics["verdict"] != "stable"
    assert metrics["verdict_reason"].startswith("pitch lost: its wheel does not answer")
    healthy = _at_rest(steps=900)
    clean = episode_metrics(run_episode(healthy, _MonitoredPD(healthy), seed=0),
                            healthy.unwrapped.model)
    assert clean["verdict"] == "stable" and clean["verdict_reason"] is None


def test_the_loop_without_infos_monitors_its_own_torque():
    """Flown through SB3's ``predict`` (no ``info``: the torque the env applied is not
    reported), the loop's monitor balances the momentum against the torque it commanded
    itself: a healthy slew declares nothing. (The loop on the fast identifier, the one
    flown as an SB3 policy: the scheduled fit needs the drive's angle from ``info``.)"""
    from controllers import fast_identifier

    env = gym.make(env_id("paddle_rotation"), task="slew", max_episode_steps=400)
    ctrl = AdaptiveLQG(env, identifier=fast_identifier(env))
    obs, _ = env.reset(seed=0)
    ctrl.reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FaultWarning)
        for _ in range(400):
            obs, *_ = env.step(ctrl.act(obs))
    assert ctrl.stats["faults"] == []
    env.close()
