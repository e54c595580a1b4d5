"""The gyro-bias monitor: a bias estimated from the star tracker, declared, dated and
compensated; nothing declared without one."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

from controllers import PD, AdaptiveLQG, FaultWarning, GyroBiasMonitor, run_episode
from controllers.gyro_bias import SMALLEST_BIAS
from spacecraft_env import FaultInjection, env_id, parse_fault

BIAS = np.deg2rad(0.01)          # 36 deg/h


def _gyro_bias(onset_s: float, axis: int = 1) -> object:
    return parse_fault(f"sensor_bias,onset={onset_s},group=rate,axis={axis},value={BIAS}")


def _monitor_over(env, traj):
    monitor = GyroBiasMonitor(env)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FaultWarning)
        for obs in traj.observations:
            monitor(obs)
    return monitor


@pytest.mark.parametrize("snr_db", [40.0, 20.0, None])
def test_nothing_is_declared_without_a_bias(snr_db):
    """A PD slew (rates up to its manoeuvre's) at three noise levels, three seeds."""
    env = gym.make(env_id("paddle_rotation"), task="slew", snr_db=snr_db,
                   max_episode_steps=1500)
    for seed in range(3):
        monitor = _monitor_over(env, run_episode(env, PD(env), seed=seed))
        assert monitor.faults == [] and not monitor.compensated.any()
        # converged to its steady state: the estimate's noise
        assert np.abs(monitor.bias).max() < max(5 * monitor.bias_std, SMALLEST_BIAS)
    env.close()


def test_a_bias_is_declared_dated_and_subtracted():
    env = FaultInjection(gym.make(env_id("constant"), max_episode_steps=900),
                         [_gyro_bias(40.0)])
    traj = run_episode(env, PD(env), seed=5)
    monitor = GyroBiasMonitor(env)
    with pytest.warns(FaultWarning, match="gyro bias on axis 1"):
        corrected = [monitor(obs) for obs in traj.observations]
    (fault,) = monitor.faults
    assert fault["kind"] == "gyro bias" and fault["axis"] == 1
    assert 40.0 <= fault["detected_s"] <= 50.0          # within 10 s of the onset
    # the step dated by the hinge of the attitude less the gyro's integral, and the
    # estimate run again from there: the bias at once, not a quarter of it
    assert abs(fault["onset_s"] - 40.0) <= 1.5
    assert fault["value"] == pytest.approx(BIAS, rel=0.2)
    assert monitor.compensated.tolist() == [False, True, False]
    # converged: the bias is gone from the corrected gyro, the other axes untouched
    assert monitor.bias[1] == pytest.approx(BIAS, rel=0.1)
    rate = env.unwrapped.observation_layout.indices("rate")
    late = np.array(corrected[-200:])[:, rate] - traj.observations[-200:][:, rate]
    np.testing.assert_allclose(late[:, 1], -monitor.bias[1], rtol=0.2)
    assert not late[:, [0, 2]].any()
    env.close()


def test_a_stuck_star_tracker_is_not_read_as_a_gyro_bias():
    """The attitude sensor frozen for 60 s while a PD slews: the held readings are skipped
    (not an innovation the bias would absorb)."""
    stuck = parse_fault("stuck_sensor,onset=20,duration=60,group=attitude")
    env = FaultInjection(gym.make(env_id("paddle_rotation"), task="slew",
                                  max_episode_steps=1200), [stuck])
    for seed in range(2):
        monitor = _monitor_over(env, run_episode(env, PD(env), seed=seed))
        assert monitor.faults == []
    env.close()


def test_a_missing_sample_only_predicts_and_bad_input_raises():
    env = gym.make(env_id("constant"), max_episode_steps=20)
    monitor = GyroBiasMonitor(env)
    obs, _ = env.reset(seed=0)
    monitor(obs)
    out = monitor(np.full_like(obs, np.nan))
    assert np.isfinite(monitor.bias).all() and np.isnan(out).all()
    with pytest.raises(ValueError, match="bias_walk must be a finite rate > 0"):
        GyroBiasMonitor(env, bias_walk=-1.0)
    env.close()


def test_the_loop_reports_a_gyro_bias_and_flies_as_before_without_one():
    env = FaultInjection(gym.make(env_id("paddle_rotation"), max_episode_steps=600),
                         [_gyro_bias(20.0, axis=0)])
    with pytest.warns(FaultWarning, match="gyro bias on axis 0"):
        traj = run_episode(env, AdaptiveLQG(env), seed=2)
    (fault,) = traj.controller_stats["faults"]
    assert fault["axis"] == 0 and fault["detected_s"] - 20.0 <= 10.0
    clean = gym.make(env_id("paddle_rotation"), max_episode_steps=450)
    on = run_episode(clean, AdaptiveLQG(clean), seed=2)
    off = run_episode(clean, AdaptiveLQG(clean, monitor_gyro=False), seed=2)
    assert on.controller_stats["faults"] == []
    np.testing.assert_array_equal(on.torque, off.torque)
    env.close()
    clean.close()


def test_a_declared_gyro_bias_restarts_the_integrals_settling():
    """The attitude walked while the bias went uncompensated: its walk back must not
    charge the integrals, so on the declaration both laws (the identified design's and
    the fallback's) wait ``settle_s`` in the band again, their integrals kept."""
    env = gym.make(env_id("paddle_rotation"))
    ctrl = AdaptiveLQG(env)
    laws = (ctrl.law, ctrl.fallback.law)
    error = np.full(3, 1e-4)
    for law in laws:
        law.z = np.array([1.0, 2.0, 3.0])
        law._in_band_steps = 10 * law._settle_steps     # long settled: integrating
        law.integrate(error, saturated=False)
        assert law.z[0] > 1.0
    kept = [law.z.copy() for law in laws]
    ctrl.gyro_monitor.faults.append({"kind": "gyro bias", "axis": 0, "onset_s": 1.0,
                                     "detected_s": 7.0, "value": 1e-4})
    ctrl._collect_faults()
    for law, z in zip(laws, kept, strict=True):
        np.testing.assert_array_equal(law.z, z)
        for _ in range(law._settle_steps - 1):
            law.integrate(error, saturated=False)
        np.testing.assert_array_equal(law.z, z)          # still settling
        law.integrate(error, saturated=False)
        assert law.z[0] > z[0]                           # settled again: integrating
    # an actuator report does not restart them
    ctrl.law._in_band_steps = 10 * ctrl.law._settle_steps
    ctrl.actuator_monitor.faults.append({"kind": "actuator torque", "axis": 1,
                                         "onset_s": 1.0, "detected_s": 9.0, "value": 0.1})
    ctrl._collect_faults()
    assert ctrl.law._in_band_steps == 10 * ctrl.law._settle_steps
    env.close()


def test_a_declared_gyro_bias_corrects_what_the_identifier_recorded(monkeypatch):
    """On the declaration the loop hands its identifier the bias on that gyro's output
    from the dated onset."""
    env = FaultInjection(gym.make(env_id("paddle_rotation"), max_episode_steps=600),
                         [_gyro_bias(20.0, axis=0)])
    ctrl = AdaptiveLQG(env)
    calls = []
    correct = type(ctrl.identifier).correct_outputs

    def recorded(ident, offset, since):
        calls.append((offset, since))
        correct(ident, offset, since)

    monkeypatch.setattr(type(ctrl.identifier), "correct_outputs", recorded)
    with pytest.warns(FaultWarning, match="gyro bias on axis 0"):
        run_episode(env, ctrl, seed=2)
    ((offset, since),) = calls
    (fault,) = ctrl.stats["faults"]
    rate = ctrl.identifier.layout.indices("rate")
    assert offset[rate[0]] == fault["value"] and np.count_nonzero(offset) == 1
    assert since == round(fault["onset_s"] / env.unwrapped.model.dt)
    assert abs(fault["onset_s"] - 20.0) <= 1.5
    env.close()


def test_an_identifiers_record_takes_a_late_correction():
    """Before its first fit the scheduled identifier records every sample: a correction
    since sample 50 shifts the outputs of samples 50-99 (in its normalized units) and no
    other; a bad offset is refused."""
    from identifiers import ScheduledPhysicalIdentifier

    ident = ScheduledPhysicalIdentifier(dt=0.1)
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=(100, 3)), rng.normal(size=(100, 10))
    for k in range(100):
        ident.update(u[k], y[k])
    before = [item[1].copy() for item in ident._record]
    offset = np.zeros(10)
    offset[3] = 1e-3
    ident.correct_outputs(offset, 50)
    after = np.array([item[1] for item in ident._record])
    np.testing.assert_array_equal(after[:50], before[:50])
    np.testing.assert_allclose(after[50:], np.array(before[50:]) - offset / ident._sy)
    with pytest.raises(ValueError, match="one per output"):
        ident.correct_outputs(np.zeros(5), 0)
    with pytest.raises(ValueError, match="since must be"):
        ident.correct_outputs(offset, -1)
