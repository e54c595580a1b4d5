"""Controllers: Riccati closed forms, validation, closed-loop behaviour, interface."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from controllers import (
    LQR,
    PD,
    AdaptiveLQR,
    LQRWeights,
    OracleLQR,
    PolicyController,
    RiccatiTracker,
    check_weights,
    dlqr,
    episode_metrics,
    run_episode,
)
from spacecraft_env import FlexibleSpacecraftEnv


def test_scalar_riccati_closed_form():
    """x+ = a x + b u: P = q + a^2 P r / (r + b^2 P), positive root."""
    a, b, q, r = 1.2, 0.5, 2.0, 0.3
    gain, p = dlqr(np.array([[a]]), np.array([[b]]), np.array([[q]]), np.array([[r]]))
    # b^2 P^2 + (r - a^2 r - q b^2) P - q r = 0
    c1, c0 = r - a * a * r - q * b * b, -q * r
    p_exact = (-c1 + np.sqrt(c1 * c1 - 4 * b * b * c0)) / (2 * b * b)
    assert p[0, 0] == pytest.approx(p_exact, rel=1e-12)
    assert gain[0, 0] == pytest.approx(a * b * p_exact / (r + b * b * p_exact), rel=1e-12)


def test_double_integrator_lqr_matches_python_control():
    import control

    dt = 0.1
    a = np.array([[1.0, dt], [0.0, 1.0]])
    b = np.array([[dt**2 / 2], [dt]])
    q, r = np.diag([1.0, 0.1]), np.array([[0.01]])
    gain, _ = dlqr(a, b, q, r)
    ref, _, _ = control.dlqr(a, b, q, r)
    np.testing.assert_allclose(gain, ref, rtol=1e-9)
    assert np.abs(np.linalg.eigvals(a - b @ gain)).max() < 1


def test_riccati_tracker_converges_to_exact_solution():
    rng = np.random.default_rng(0)
    a = np.diag([1.0, 0.95, 0.9]) + 0.05 * rng.normal(size=(3, 3))
    b = rng.normal(size=(3, 1))
    q, r = np.eye(3), np.array([[1.0]])
    tracker = RiccatiTracker(q, r, iterations=50, tol=1e-13)
    tracker.design(a, b)
    a2 = a + 1e-3 * rng.normal(size=(3, 3))          # slowly varying model
    for _ in range(20):
        gain = tracker.design(a2, b)
    np.testing.assert_allclose(gain, dlqr(a2, b, q, r)[0], rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize(
    ("q", "r", "match"),
    [
        (np.array([[1.0, 2.0], [0.0, 1.0]]), np.eye(1), "symmetric"),
        (np.diag([1.0, -1.0]), np.eye(1), "positive semidefinite"),
        (np.eye(2), np.zeros((1, 1)), "positive definite"),
        (np.eye(2), np.ones((1, 2)), "square"),
        (np.eye(3), np.eye(1), r"shape \(2, 2\)"),
    ],
)
def test_invalid_weights_raise(q, r, match):
    with pytest.raises(ValueError, match=match):
        check_weights(q, r, 2, 1)


def test_invalid_lqr_weights_dataclass():
    with pytest.raises(ValueError):
        LQRWeights(torque=0.0)
    with pytest.raises(ValueError):
        LQRWeights(attitude=-1.0)


@pytest.mark.parametrize("make", [PD, LQR, OracleLQR])
def test_baselines_regulate_the_constant_plant(make):
    env = gym.make("FlexibleSpacecraft-v0", max_episode_steps=1500)
    traj = run_episode(env, make(env), seed=0)
    m = episode_metrics(traj, env.unwrapped.model)
    assert m["stable"]
    final = np.abs(traj.states[-1, :3] - traj.reference[-1]).max()
    initial = np.abs(traj.states[0, :3]).max()
    assert final < 0.05 * initial


def test_oracle_equals_fixed_lqr_on_lti_plant_with_true_state():
    """On the constant plant the oracle's re-design reproduces the t = 0 gain."""
    env = FlexibleSpacecraftEnv("constant")
    oracle = OracleLQR(env)
    fixed = LQR(env)
    obs, info = env.reset(seed=0)
    oracle.reset()
    oracle.act(obs, info)
    np.testing.assert_allclose(oracle._tracker.design(fixed.a, fixed.b), fixed.gain,
                               rtol=1e-6, atol=1e-9)


def test_slew_reaches_reference_without_steady_state_error():
    env = gym.make("FlexibleSpacecraft-v0", task="slew", snr_db=None)
    traj = run_episode(env, OracleLQR(env.unwrapped), seed=3)
    err = np.rad2deg(np.abs(traj.states[-1, :3] - traj.reference[-1]))
    assert np.abs(np.rad2deg(traj.reference[-1])).max() > 1.0   # a real slew
    assert err.max() < 0.01


def test_settling_time_metric_on_synthetic_trajectory():
    from controllers.harness import Trajectory
    from spacecraft_env import FlexibleSpacecraftModel

    model = FlexibleSpacecraftModel()
    n_steps = 100
    states = np.zeros((n_steps + 1, model.n))
    states[1:51, 0] = np.deg2rad(1.0)        # error of 1 deg until t = 5.0 s
    traj = Trajectory(time=np.arange(1, n_steps + 1) * 0.1, observations=np.zeros((101, 10)),
                      actions=np.zeros((100, 3)), torque=np.zeros((100, 3)), states=states,
                      reference=np.zeros((101, 3)), rewards=np.zeros(100), terminated=False,
                      events=(2.0,))
    m = episode_metrics(traj, model)
    assert m["settling_s"] == [pytest.approx(3.1)]
    assert m["attitude_peak_deg"] == pytest.approx(1.0)


def test_adaptive_lqr_runs_and_counts_its_safeguards():
    env = gym.make("FlexibleSpacecraftDocking-v0")
    ctrl = AdaptiveLQR(env.unwrapped)
    traj = run_episode(env, ctrl, seed=0, max_steps=650)
    stats = traj.controller_stats
    assert stats["steps"] == 650
    assert stats["fallback_steps"] >= ctrl.identifier.warmup - 1   # PD until warmed up
    assert stats["redesigns"] + stats["rejected_unstable"] + stats["failed_redesigns"] > 0
    assert np.all(np.isfinite(traj.actions))


def test_nan_observation_reaches_the_identifier_which_skips_and_counts_it():
    env = FlexibleSpacecraftEnv("docking")
    ctrl = AdaptiveLQR(env)
    obs, info = env.reset(seed=0)
    ctrl.reset(0)
    for _ in range(5):
        action = ctrl.act(obs, info)
        obs, _, _, _, info = env.step(action)
    samples, skipped = ctrl.identifier.n_samples, ctrl.identifier.n_skipped
    pd_action = ctrl.fallback._last.copy()
    bad = obs.copy()
    bad[1] = np.nan
    action = ctrl.act(bad, info)
    assert np.all(np.isfinite(action))
    np.testing.assert_array_equal(ctrl.fallback._last, pd_action)   # PD holds its action
    assert ctrl.identifier.n_samples == samples + 1      # the sample is not lost ...
    assert ctrl.identifier.n_skipped == skipped + 1      # ... it is skipped and counted
    assert ctrl.stats["nonfinite_observations"] == 1


def test_wrong_observation_shape_raises():
    env = FlexibleSpacecraftEnv("constant")
    with pytest.raises(ValueError, match="observation must have shape"):
        PD(env).act(np.zeros(4))
    with pytest.raises(ValueError):
        PD(FlexibleSpacecraftEnv("constant", outputs=("deflection",)))


def test_sb3_style_predict_and_policy_wrapper():
    env = FlexibleSpacecraftEnv("constant")
    pd = PD(env)
    obs, _ = env.reset(seed=0)
    action, state = pd.predict(obs, deterministic=True)
    assert action.shape == (3,) and state is None
    batch, _ = pd.predict(np.stack([obs, obs]), episode_start=np.array([True, False]))
    assert batch.shape == (2, 3)
    wrapped = PolicyController(pd, name="pd-as-policy")
    np.testing.assert_allclose(wrapped.act(obs), pd.act(obs))
    with pytest.raises(TypeError):
        PolicyController(object())
