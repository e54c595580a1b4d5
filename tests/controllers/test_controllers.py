"""Controllers: Riccati closed forms, validation, closed-loop behaviour, interface."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

from controllers import (
    PD,
    AdaptiveLQG,
    BinaryExcitation,
    FixedLQG,
    GainAcceptance,
    LQRWeights,
    OracleLQG,
    OracleLQR,
    PolicyController,
    RiccatiTracker,
    RobustLQG,
    ScheduledLQG,
    check_weights,
    dlqr,
    episode_metrics,
    equilibrium_map,
    equilibrium_state,
    fast_identifier,
    input_disk_margin,
    run_episode,
    spectral_radius,
)
from controllers.base import episode_seed
from spacecraft_env import ENV_IDS, ConstantScenario, FlexibleSpacecraftEnv


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


def _lqr_problem(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """A 3-state, 1-input model near the unit circle and unit weights."""
    a = np.diag([1.0, 0.95, 0.9]) + 0.05 * rng.normal(size=(3, 3))
    b = rng.normal(size=(3, 1))
    return a, b, np.eye(3), np.array([[1.0]])


def test_riccati_tracker_converges_to_exact_solution():
    rng = np.random.default_rng(0)
    a, b, q, r = _lqr_problem(rng)
    tracker = RiccatiTracker(q, r, iterations=50, tol=1e-13)
    tracker.design(a, b)
    a2 = a + 1e-3 * rng.normal(size=(3, 3))          # slowly varying model
    for _ in range(20):
        gain = tracker.design(a2, b)
    np.testing.assert_allclose(gain, dlqr(a2, b, q, r)[0], rtol=1e-8, atol=1e-12)


def test_riccati_tracker_hands_back_a_converged_design_for_an_unchanged_model():
    a, b, q, r = _lqr_problem(np.random.default_rng(1))
    tracker = RiccatiTracker(q, r, iterations=4, tol=1e-9)
    gain = tracker.design(a, b)                     # the cold start: exact, so converged
    again = tracker.design(a.copy(), b.copy())      # equal values, other arrays
    assert again is gain and tracker.n_reused == 1 and not again.flags.writeable
    moved = tracker.design(a + 1e-3, b)             # a new model: iterated, not reused
    assert moved is not gain and tracker.n_reused == 1
    for _ in range(200):                            # iterate until converged, then kept
        latest = tracker.design(a + 1e-3, b)
    assert tracker.n_reused > 100
    np.testing.assert_allclose(latest, dlqr(a + 1e-3, b, q, r)[0], rtol=1e-7)
    tracker.q = 2 * q                               # another weight: designed again
    assert tracker.design(a + 1e-3, b) is not latest


def test_doubling_solves_the_dare_as_scipy_does_and_certifies_stability():
    from scipy.linalg import solve_discrete_are

    from controllers.riccati import doubling_dare

    rng = np.random.default_rng(3)
    dt = 0.1
    for trial in range(10):
        # a double integrator per axis (two poles at 1) plus random lightly damped modes,
        # integral-augmented as the adaptive law's model is: closed-loop poles near 1
        n_modes = 2 + trial % 4
        w = rng.uniform(0.3, 3.0, n_modes)
        blocks = [np.array([[1.0, dt], [0.0, 1.0]])]
        for wi in w:
            c_, s_ = np.cos(wi * dt), np.sin(wi * dt)
            blocks.append(0.998 * np.array([[c_, s_], [-s_, c_]]))
        a = np.zeros((2 * len(blocks) + 1, 2 * len(blocks) + 1))
        for i, blk in enumerate(blocks):
            a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = blk
        a[-1, -1] = 1.0
        a[-1, 0] = dt                                       # the integral of the angle
        b = rng.normal(size=(a.shape[0], 2))
        b[-1] = 0.0
        q = np.diag(rng.uniform(0.0, 1.0, a.shape[0]))
        q[0, 0] = q[-1, -1] = 1.0
        r = np.diag(rng.uniform(0.1, 1.0, 2))
        p = doubling_dare(a, b, q, r)
        ref = solve_discrete_are(a, b, q, r)
        np.testing.assert_allclose(p, ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())
        assert np.allclose(p, p.T, rtol=0, atol=1e-12 * np.abs(p).max())
    # an unstable mode the input cannot reach: no stabilizing solution, None (not a guess)
    a = np.diag([1.05, 0.5])
    b = np.array([[0.0], [1.0]])
    assert doubling_dare(a, b, np.eye(2), np.eye(1)) is None
    tracker = RiccatiTracker(np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match="stabilizing"):
        tracker.design(a, b)


def test_riccati_tracker_solves_each_new_model_exactly_and_keeps_it():
    a, b, q, r = _lqr_problem(np.random.default_rng(4))
    tracker = RiccatiTracker(q, r)                  # default: exact for every new model
    gain = tracker.design(a, b)
    np.testing.assert_allclose(gain, dlqr(a, b, q, r)[0], rtol=1e-9, atol=1e-12)
    assert tracker.design(a.copy(), b) is gain and tracker.n_reused == 1
    moved = tracker.design(a + 1e-3, b)             # one step: the new model's exact gain
    np.testing.assert_allclose(moved, dlqr(a + 1e-3, b, q, r)[0], rtol=1e-9, atol=1e-12)
    assert tracker.n_exact == 2
    for bad in (0, -1, 2.5, True, "4"):
        with pytest.raises(ValueError, match="iterations must be None"):
            RiccatiTracker(q, r, iterations=bad)
    # refused where it is given, not at the first design (which would count it as a
    # failed design and fly the fallback without a word)
    env = gym.make("spacecraft_env:FlexibleSpacecraft-v2")
    with pytest.raises(ValueError, match="iterations must be None"):
        AdaptiveLQG(env.unwrapped, iterations=0)
    assert AdaptiveLQG(env.unwrapped, iterations=4).law.iterations == 4


def test_spectral_radius_matches_numpy_and_refuses_non_finite_matrices():
    rng = np.random.default_rng(2)
    for n in (1, 2, 5, 17):
        a = rng.normal(size=(n, n))
        assert spectral_radius(a) == pytest.approx(np.abs(np.linalg.eigvals(a)).max(),
                                                   rel=1e-12)
    assert spectral_radius(np.array([[0.0, -1.0], [1.0, 0.0]])) == pytest.approx(1.0)
    with pytest.raises(np.linalg.LinAlgError, match="infs or NaNs"):
        spectral_radius(np.array([[np.nan]]))
    with pytest.raises(np.linalg.LinAlgError, match="square"):
        spectral_radius(np.ones((2, 3)))


def test_equilibrium_map_is_the_equilibrium_state_per_unit_reference():
    a = np.eye(4)
    a[:2, 2:] = 0.1 * np.eye(2)                     # two double integrators
    c_att = np.hstack([np.eye(2), np.zeros((2, 2))])
    ref = np.array([0.02, -0.01])
    np.testing.assert_allclose(equilibrium_map(a, c_att) @ ref,
                               equilibrium_state(a, c_att, ref), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(equilibrium_state(a, c_att, ref), [0.02, -0.01, 0, 0],
                               atol=1e-15)


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


@pytest.mark.parametrize("make", [PD, FixedLQG, RobustLQG, ScheduledLQG, OracleLQG, OracleLQR])
def test_baselines_regulate_the_constant_plant(make):
    env = gym.make("FlexibleSpacecraft-v2", max_episode_steps=1500)
    traj = run_episode(env, make(env), seed=0)
    m = episode_metrics(traj, env.unwrapped.model)
    assert m["stable"]
    final = np.abs(traj.states[-1, :3] - traj.reference[-1]).max()
    initial = np.abs(traj.states[0, :3]).max()
    assert final < 0.05 * initial


def test_oracle_equals_fixed_lqg_on_the_nominal_plant():
    """On the constant nominal plant the oracle's re-design reproduces the fixed gain."""
    env = FlexibleSpacecraftEnv("constant")
    oracle = OracleLQG(env)
    fixed = FixedLQG(env)
    obs, info = env.reset(seed=0)
    oracle.reset()
    fixed.reset()
    np.testing.assert_allclose(oracle.act(obs, info), fixed.act(obs, info), rtol=1e-6,
                               atol=1e-7)
    sys_ = env.model.discrete(0.0)
    np.testing.assert_allclose(oracle.law.design(sys_.A, sys_.B, fixed._c, fixed._c_att),
                               fixed.gain, rtol=1e-6, atol=1e-9)


def test_slew_reaches_reference_without_steady_state_error():
    env = gym.make("FlexibleSpacecraft-v2", task="slew", snr_db=None)
    traj = run_episode(env, OracleLQR(env.unwrapped), seed=3)
    err = np.rad2deg(np.abs(traj.states[-1, :3] - traj.reference[-1]))
    assert np.abs(np.rad2deg(traj.reference[-1])).max() > 1.0   # a real slew
    assert err.max() < 0.01


def _synthetic(error_deg, deflection_m=None, events=(), dt=0.1):
    from controllers.harness import Trajectory
    from spacecraft_env import FlexibleSpacecraftModel

    model = FlexibleSpacecraftModel()
    n_steps = len(error_deg)
    states = np.zeros((n_steps + 1, model.n))
    states[1:, 0] = np.deg2rad(error_deg)
    if deflection_m is not None:   # the first deflection sensor reads the first modal coordinate
        row = model.C[model.output_layout.slice("deflection")][0]
        states[1:] += np.outer(deflection_m, row) / (row @ row)
    traj = Trajectory(time=np.arange(1, n_steps + 1) * dt,
                      observations=np.zeros((n_steps + 1, 10)), actions=np.zeros((n_steps, 3)),
                      torque=np.zeros((n_steps, 3)), states=states,
                      reference=np.zeros((n_steps + 1, 3)), rewards=np.zeros(n_steps),
                      terminated=False, events=tuple(events))
    return traj, model


def test_settling_time_counts_only_a_loop_that_had_settled():
    err = np.zeros(300)
    err[100:150] = 1.0                                  # 1 deg from t = 10.1 s to 15.0 s
    traj, model = _synthetic(err, events=(10.0,))
    m = episode_metrics(traj, model)
    assert m["settling_s"] == [pytest.approx(5.1)]
    assert m["settled_before_event"] == [True]
    assert m["attitude_peak_deg"] == pytest.approx(1.0)
    err[40:100] = 0.2                                   # not settled before the event
    traj, model = _synthetic(err, events=(10.0,))
    m = episode_metrics(traj, model)
    assert m["settling_s"] == [None] and m["settled_before_event"] == [False]


def test_stability_verdict_sees_a_slowly_growing_envelope():
    """Rho = 1.00135 per step (the fixed LQG at 180 deg): small at the end, but growing."""
    t = np.arange(1, 2501) * 0.1
    growing = 1e-3 * np.exp(0.0135 * t) * np.sin(2 * np.pi * 0.08 * t)   # metres
    traj, model = _synthetic(np.zeros(2500), deflection_m=growing)
    m = episode_metrics(traj, model)
    assert np.abs(growing[-250:]).max() < 0.05       # a final-error check would call it stable
    assert m["envelope_growth_per_100s"] == pytest.approx(np.exp(1.35), rel=0.1)
    assert m["verdict"] == "growing" and not m["stable"]
    decaying = 1e-2 * np.exp(-0.02 * t) * np.sin(2 * np.pi * 0.08 * t)
    m = episode_metrics(*_synthetic(np.zeros(2500), deflection_m=decaying))
    assert m["verdict"] == "stable" and m["envelope_growth_per_100s"] < 1


def test_stability_verdict_sees_a_slow_but_significant_growth():
    """1.12x per 100 s (the fixed LQG at 90 deg: radius 1.00014) is below GROWTH_LIMIT
    but a trend, which a stationary or decaying envelope is not."""
    from controllers.harness import GROWTH_LIMIT, GROWTH_T, SLOW_GROWTH_LIMIT

    t = np.arange(1, 2501) * 0.1
    rate = np.log(1.12) / 100.0
    ring = np.sin(2 * np.pi * 0.08 * t)
    m = episode_metrics(*_synthetic(np.zeros(2500), deflection_m=0.05 * np.exp(rate * t) * ring))
    assert SLOW_GROWTH_LIMIT < m["envelope_growth_per_100s"] < GROWTH_LIMIT
    assert m["envelope_growth_t"] > GROWTH_T and m["verdict"] == "growing"
    # the same growth below the envelope floor (sensor noise wanders there) is not judged
    m = episode_metrics(*_synthetic(np.zeros(2500), deflection_m=1e-4 * np.exp(rate * t) * ring))
    assert m["verdict"] == "stable"
    # a stationary envelope with a random wander: no significant trend
    wander = 0.2 * (1 + 0.3 * np.random.default_rng(0).standard_normal(250).repeat(10))
    m = episode_metrics(*_synthetic(np.zeros(2500), deflection_m=wander * 0.01 * ring))
    assert abs(m["envelope_growth_t"]) < GROWTH_T and m["verdict"] == "stable"


def test_stability_verdict_flags_a_saturated_limit_cycle():
    traj, model = _synthetic(0.05 * np.sin(np.arange(2500) * 0.3))
    traj.actions[:] = np.sign(np.sin(np.arange(2500) * 0.3))[:, None]
    m = episode_metrics(traj, model)
    assert m["verdict"] == "saturated" and not m["stable"]


def test_adaptive_lqg_runs_and_counts_its_safeguards():
    env = gym.make("FlexibleSpacecraftDocking-v2")
    ctrl = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env))
    traj = run_episode(env, ctrl, seed=0, max_steps=650)
    stats = traj.controller_stats
    assert stats["steps"] == 650
    assert stats["fallback_steps"] >= ctrl.identifier.warmup - 1   # not identified until warm
    assert stats["redesigns"] + stats["rejected"] + stats["failed_designs"] > 0
    assert np.all(np.isfinite(traj.actions))
    assert stats["excitation_rms_Nm"] > 0


class _RecordedPD(PD):
    """A PD that records every action it returned."""

    def reset(self, seed=None):
        super().reset(seed)
        self.actions: list[np.ndarray] = []

    def act(self, obs, info=None):
        action = super().act(obs, info)
        self.actions.append(np.array(action, dtype=float))
        return action


def test_the_warmup_controller_flies_until_the_identifier_has_a_model():
    """A gentle PD flies the identifier's warm-up (the robust design's faster loop left
    the start's manoeuvre ringing in the modes), then never again: the robust design
    covers the rejections after that (a PD without integral must not fly on when no
    identified gain passes: see the integral test below)."""
    env = gym.make("FlexibleSpacecraftDocking-v2", task="slew")
    warm = _RecordedPD(env.unwrapped)
    ctrl = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env), warmup_controller=warm)
    handed = []
    transfer = ctrl._transfer_integral
    ctrl._transfer_integral = lambda to_identified: (handed.append(to_identified),
                                                     transfer(to_identified))
    traj = run_episode(env, ctrl, seed=0, max_steps=700)
    assert ctrl._warm and ctrl.stats["redesigns"] > 0
    first = len(warm.actions)                # the first step with a model
    assert ctrl.identifier.warmup - 1 <= first <= ctrl.identifier.warmup + 1
    pd_torque = np.array(warm.actions[:first - 1]) * ctrl.max_torque
    np.testing.assert_allclose(traj.torque[:first - 1], pd_torque + traj.excitation[:first - 1],
                               rtol=0, atol=1e-5)          # float32 actions
    # the robust design, whose filter and integral ran on all along, flies from the
    # model's arrival until the first gain passes the acceptance test; its integral is
    # handed over then, as at every later switch
    assert handed and handed[0] is True and ctrl.stats["fallback_steps"] > first
    # one controller for both roles: the robust design flies the warm-up
    robust = RobustLQG(env.unwrapped)
    both = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env), fallback=robust,
                       warmup_controller=robust,
                       excitation=BinaryExcitation(0.0, 0.0))
    alone = RobustLQG(env.unwrapped)
    a = run_episode(env, both, seed=0, max_steps=100).actions
    np.testing.assert_allclose(a, run_episode(env, alone, seed=0, max_steps=100).actions,
                               rtol=0, atol=1e-12)


def test_disk_margin_of_a_scalar_observer_loop_closed_form():
    """x+ = a x + u, y = x, predictor gain k, u = -g xhat:
    L(z) = g k / ((z - (a - k - g)) (z - a)); alpha = min |1 + L|."""
    a, k, g, dt = 0.5, 0.4, 0.3, 0.1
    w = np.geomspace(1e-2, 30.0, 200)
    z = np.exp(1j * w * dt)
    expected = np.min(np.abs(1 + g * k / ((z - (a - k - g)) * (z - a))))
    got = input_disk_margin(np.array([[a]]), np.array([[1.0]]), np.array([[1.0]]),
                            np.array([[k]]), np.array([[g]]), np.array([0]), dt, w)
    assert got == pytest.approx(expected, rel=1e-12)


def test_disk_margin_with_the_integral_closed_form():
    """Same loop with the integral z+ = z + dt x and u = -g xhat - h z."""
    a, k, g, h, dt = 0.9, 0.5, 0.2, 0.05, 0.1
    w = np.geomspace(1e-2, 30.0, 200)
    z = np.exp(1j * w * dt)
    plant_y, plant_z = 1 / (z - a), dt / ((z - 1) * (z - a))
    a_c = a - k - g
    loop = g / (z - a_c) * (k * plant_y - h * plant_z) + h * plant_z
    expected = np.min(np.abs(1 + loop))
    got = input_disk_margin(np.array([[a]]), np.array([[1.0]]), np.array([[1.0]]),
                            np.array([[k]]), np.array([[g, h]]), np.array([0]), dt, w)
    assert got == pytest.approx(expected, rel=1e-12)
    with pytest.raises(ValueError, match="min_disk_margin"):
        GainAcceptance(min_disk_margin=1.0)
    assert GainAcceptance(min_disk_margin=0.4).check_margin(0.39) == "margin"
    assert GainAcceptance(min_disk_margin=0.4).check_margin(0.41) is None


def test_disk_margin_skips_a_frequency_at_an_undamped_pole():
    """An undamped mode puts a model pole on the unit circle at the frequency the
    margin is evaluated at (the pole angles are on its grid): no error, a finite
    margin from the other frequencies."""
    dt, w0 = 0.1, 0.5
    a = np.array([[np.cos(w0 * dt), np.sin(w0 * dt)], [-np.sin(w0 * dt), np.cos(w0 * dt)]])
    b, c, k = np.array([[0.0], [0.1]]), np.array([[1.0, 0.0]]), np.array([[0.5], [0.2]])
    margin = input_disk_margin(a, b, c, k, np.array([[0.1, 0.2]]), np.array([0]), dt)
    assert 0.0 < margin < np.inf


def test_adaptive_lqg_reads_attitude_and_rate_states_from_the_sensors():
    env = gym.make("FlexibleSpacecraftDocking-v2")
    ctrl = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env))
    traj = run_episode(env, ctrl, seed=0, max_steps=560)
    y = traj.observations[-1][ctrl._meas_obs].astype(float)
    x = ctrl.identifier.filtered_state(y)
    c = ctrl.identifier.model.C
    measured = ctrl._measured_rigid(x, y, c)
    rows = np.concatenate([ctrl._att_rows, ctrl._rate_rows])
    # the model reproduces the measured attitude and rate exactly; the filter alone does not
    np.testing.assert_allclose(c[rows] @ measured, y[rows], rtol=0, atol=1e-12)
    assert np.max(np.abs(c[rows] @ x - y[rows])) > 1e-9
    np.testing.assert_array_equal(measured[6:], x[6:])          # flexible states untouched
    with pytest.raises(ValueError, match="rigid_state"):
        AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env), rigid_state="sensors")


def test_adaptive_lqg_rejects_gains_whose_loop_margin_is_too_small():
    env = gym.make("FlexibleSpacecraftDocking-v2")
    # the prediction test off: only the margin can reject the identified gains
    strict = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env), acceptance=GainAcceptance(
        max_prediction_error=np.inf, min_disk_margin=0.999))
    traj = run_episode(env, strict, seed=0, max_steps=560)
    assert traj.controller_stats["rejected_by"].get("margin", 0) > 0
    assert traj.controller_stats["redesigns"] == 0


def test_the_dual_excitation_runs_only_in_its_window_after_the_warm_up_or_a_change(
        monkeypatch):
    """With a tolerance no estimate meets, the excitation wants to run for good: it runs
    for ``excitation_window_s`` after the identifier's first model, then stops; a change
    the identifier reports opens the window again; ``inf`` keeps the old behaviour."""
    from identifiers.modal.rigid_flexible import RigidFlexibleIdentifier

    reported: list = []          # the changes the identifier reports (the loop counts them)
    monkeypatch.setattr(RigidFlexibleIdentifier, "events", property(lambda self: reported))

    def run(window, steps=420, event_at=None, more=0):
        reported.clear()
        env = FlexibleSpacecraftEnv("docking")
        ctrl = AdaptiveLQG(env, identifier=fast_identifier(env), uncertainty_tolerance=1e-9,
                           excitation_window_s=window)
        obs, info = env.reset(seed=0)
        ctrl.reset(0)
        excitation, warm_at = [], None
        for k in range(steps + more):
            if k == event_at:
                reported.append("a change")
            action = ctrl.act(obs, info)
            if warm_at is None and ctrl._warm:
                warm_at = k
            excitation.append(np.abs(ctrl.last_excitation).max())
            obs, _, _, _, info = env.step(action)
        return np.array(excitation), warm_at

    bounded, warm_at = run(5.0)
    assert warm_at is not None and warm_at < 330
    window = slice(warm_at + 10, warm_at + 50)           # inside the 5 s (50 steps)
    after = slice(warm_at + 60, 420)                     # the amplitude is set every 10 steps
    assert bounded[window].max() > 0 and bounded[after].max() == 0
    unbounded, _ = run(np.inf)
    assert unbounded[after].max() > 0
    reopened, _ = run(5.0, event_at=420, more=40)
    assert reopened[after].max() == 0 and reopened[430:460].max() > 0
    for bad in (-1.0, np.nan):
        with pytest.raises(ValueError, match="excitation_window_s"):
            AdaptiveLQG(FlexibleSpacecraftEnv("docking"), excitation_window_s=bad)


@pytest.mark.parametrize(("acceptance", "cause"), [
    ({"max_prediction_error": np.inf, "min_disk_margin": 0.999}, "margin"),
    ({"max_prediction_error": 1e-9}, "prediction"),
])
def test_every_fallback_step_after_60s_has_its_cause(acceptance, cause):
    """With one acceptance test made impossible, every step the fallback flies from 60 s
    is put down to that test; the causes sum to the fallback's share and are reported by
    the episode metrics and pooled over seeds."""
    from controllers import controller_shares, fallback_causes
    from controllers.acceptance import REJECTION_REASONS
    from controllers.adaptive import FALLBACK_CAUSES

    env = gym.make("FlexibleSpacecraftDocking-v2")
    ctrl = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env),
                       acceptance=GainAcceptance(**acceptance))
    traj = run_episode(env, ctrl, seed=0, max_steps=700)
    stats = traj.controller_stats
    assert stats["steps_after_60s"] == 100 and stats["redesigns"] == 0
    assert stats["fallback_by_after_60s"] == {cause: 100}
    shares = controller_shares(stats)
    assert shares["fallback_causes_after_60s"] == {cause: 1.0}
    assert shares["fallback_share_after_60s"] == 1.0
    assert cause in REJECTION_REASONS and set(REJECTION_REASONS) <= set(FALLBACK_CAUSES)
    pooled = fallback_causes([shares, {"fallback_causes_after_60s": {}}])
    assert pooled == {cause: 0.5}


def test_the_fallback_causes_of_a_default_loop_add_up():
    """On a default loop that flies its design and its fallback, every fallback step
    from 60 s has exactly one cause among :data:`FALLBACK_CAUSES`."""
    from controllers.adaptive import FALLBACK_CAUSES

    env = gym.make("FlexibleSpacecraftPaddleRotation-v2", snr_db=None)
    ctrl = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # the fallback warning, on clean data
        traj = run_episode(env, ctrl, seed=0, max_steps=800)
    stats = traj.controller_stats
    by = stats["fallback_by_after_60s"]
    assert stats["fallback_steps_after_60s"] > 0
    assert sum(by.values()) == stats["fallback_steps_after_60s"]
    assert set(by) <= set(FALLBACK_CAUSES)


def test_nan_observation_reaches_the_identifier_which_skips_and_counts_it():
    env = FlexibleSpacecraftEnv("docking")
    ctrl = AdaptiveLQG(env, identifier=fast_identifier(env))
    obs, info = env.reset(seed=0)
    ctrl.reset(0)
    for _ in range(5):
        action = ctrl.act(obs, info)
        obs, _, _, _, info = env.step(action)
    samples, skipped = ctrl.identifier.n_samples, ctrl.identifier.n_skipped
    held = ctrl.fallback._last.copy()
    bad = obs.copy()
    bad[1] = np.nan
    action = ctrl.act(bad, info)
    assert np.all(np.isfinite(action))
    np.testing.assert_array_equal(ctrl.fallback._last, held)   # the fallback holds its action
    # a sample reaches the identifier at the next step, with the torque applied after it
    obs, _, _, _, info = env.step(action)
    ctrl.act(obs, info)
    assert ctrl.identifier.n_samples == samples + 2      # the sample is not lost ...
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


def test_the_integral_runs_only_after_the_error_has_settled_in_its_band():
    """settle_s: the integral waits until every attitude error has stayed inside the
    band that long; leaving the band restarts the wait; a held (saturated) call counts
    the time but does not integrate; 0 integrates at once (the published LQI)."""
    from controllers.lqg import INTEGRAL_BAND, INTEGRAL_SETTLE_S, LQGLaw, LQRWeights

    inside = np.full(3, 0.5 * INTEGRAL_BAND)
    law = LQGLaw(np.eye(3), LQRWeights(), dt=0.1, settle_s=1.0)
    for _ in range(9):                               # 0.9 s in the band: not yet
        law.integrate(inside, saturated=False)
    assert np.all(law.z == 0)
    law.integrate(inside, saturated=False)           # 1.0 s: integrates this step
    np.testing.assert_allclose(law.z, 0.1 * inside)
    law.integrate(3 * inside, saturated=False)       # out of the band: the wait restarts
    for _ in range(9):
        law.integrate(inside, saturated=True)        # held calls count the time
    np.testing.assert_allclose(law.z, 0.1 * inside)
    law.integrate(inside, saturated=False)
    np.testing.assert_allclose(law.z, 0.2 * inside)
    law.reset()
    assert np.all(law.z == 0)
    law.integrate(inside, saturated=False)           # the wait restarts with the episode
    assert np.all(law.z == 0)
    at_once = LQGLaw(np.eye(3), LQRWeights(), dt=0.1, settle_s=0.0)
    at_once.integrate(inside, saturated=False)
    np.testing.assert_allclose(at_once.z, 0.1 * inside)
    default = LQGLaw(np.eye(3), LQRWeights(), dt=0.1)
    assert default.settle_s == INTEGRAL_SETTLE_S == 50.0
    for _ in range(499):                             # 49.9 s in the band: not yet
        default.integrate(inside, saturated=False)
    assert np.all(default.z == 0)
    default.integrate(inside, saturated=False)       # 50 s, counted in steps, not a float sum
    np.testing.assert_allclose(default.z, 0.1 * inside)
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="settle_s"):
            LQGLaw(np.eye(3), LQRWeights(), dt=0.1, settle_s=bad)
        with pytest.raises(ValueError, match="settle_s"):
            default.settle_s = bad                   # checked when set, too
    assert default.settle_s == INTEGRAL_SETTLE_S


def test_set_integral_settle_reaches_the_adaptive_loop_and_its_fallback():
    """A saved residual agent flies its base as trained: ``set_integral_settle`` sets
    every LQG law of a controller (the adaptive LQG's own and its robust fallback's)
    and leaves a controller without one alone."""
    from controllers import PD, set_integral_settle
    from controllers.lqg import INTEGRAL_SETTLE_S

    env = gym.make("FlexibleSpacecraftDocking-v2")
    adaptive = AdaptiveLQG(env, identifier=fast_identifier(env))
    assert adaptive.law.settle_s == adaptive.fallback.law.settle_s == INTEGRAL_SETTLE_S
    assert set_integral_settle(adaptive, 0.0) is adaptive
    assert adaptive.law.settle_s == adaptive.fallback.law.settle_s == 0.0
    pd = PD(env)
    assert set_integral_settle(pd, 10.0) is pd and not hasattr(pd, "law")
    for bad in (-1.0, float("inf")):
        with pytest.raises(ValueError, match="settle_s"):
            set_integral_settle(adaptive, bad)


@pytest.mark.parametrize("make", [FixedLQG, RobustLQG, OracleLQG, AdaptiveLQG])
def test_integral_action_leaves_no_steady_state_error_under_a_constant_torque(make):
    """0.01 N m on every axis: PD keeps d / kp (about 0.01 deg); integral action removes it."""
    def steady_error(ctrl_factory):
        env = gym.make("FlexibleSpacecraft-v2", snr_db=None, disturbance_torque=0.01,
                       max_episode_steps=4000)
        traj = run_episode(env, ctrl_factory(env.unwrapped), seed=0)
        return np.abs(np.rad2deg(traj.states[-500:, :3] - traj.reference[-500:]).mean(axis=0))

    def quiet(env):    # the adaptive loop without its excitation, so the mean is the offset
        if make is AdaptiveLQG:
            return AdaptiveLQG(env, identifier=fast_identifier(env),
                               excitation=BinaryExcitation(0.0, 0.0))
        return make(env)

    assert steady_error(PD).max() > 5e-3
    assert steady_error(quiet).max() < 2e-4


def test_fixed_lqg_is_judged_unstable_past_96_deg_and_the_oracle_stable():
    env = gym.make("FlexibleSpacecraft-v2", max_episode_steps=2500,
                   scenario=ConstantScenario(paddle_angle_deg=180.0))
    fixed = episode_metrics(run_episode(env, FixedLQG(env.unwrapped), seed=0),
                            env.unwrapped.model)
    oracle = episode_metrics(run_episode(env, OracleLQG(env.unwrapped), seed=0),
                             env.unwrapped.model)
    assert fixed["verdict"] == "growing" and fixed["envelope_growth_per_100s"] > 2
    assert oracle["verdict"] == "stable"


# through predict the default identifier gets no drive angle and says so (its own test)
@pytest.mark.filterwarnings("ignore::controllers.adaptive.ScheduleWarning")
@pytest.mark.parametrize("make", [PD, FixedLQG, RobustLQG, AdaptiveLQG])
def test_predict_reads_an_observed_reference_as_act_reads_info(make):
    """SB3's evaluate_policy calls predict(obs): with the reference observed it must
    act as act(obs, info) does; without it, it cannot know the slew target."""
    env = FlexibleSpacecraftEnv("docking", task="slew",
                                outputs=("attitude", "rate", "deflection", "reference"))
    with_info, from_obs = make(env), make(env)
    obs, info = env.reset(seed=4)
    with_info.reset(0)
    from_obs.reset(0)
    for _ in range(300):
        action = with_info.act(obs, info)
        predicted, _ = from_obs.predict(obs, deterministic=True)
        # the observed reference is float32: equal to rounding, not bit for bit
        np.testing.assert_allclose(predicted, action, rtol=0, atol=1e-4)
        obs, _, _, _, info = env.step(action)
    blind_env = FlexibleSpacecraftEnv("docking", task="slew",
                                      outputs=("attitude", "rate", "deflection"))
    blind = make(blind_env)
    obs, info = blind_env.reset(seed=4)
    blind.reset(0)
    assert np.abs(blind.predict(obs)[0] - make(blind_env).act(obs, info)).max() > 0.1


def test_evaluate_policy_on_two_envs_equals_each_env_alone():
    """SB3's evaluate_policy through predict: one identifier per env, nothing interleaved."""
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    kwargs = {"scenario": "docking", "task": "slew", "max_episode_steps": 800,
              "outputs": ("attitude", "rate", "deflection", "reference")}
    vec = DummyVecEnv([lambda: Monitor(gym.make("FlexibleSpacecraft-v2", **kwargs))
                       for _ in range(2)])
    vec.seed(100)
    ctrl = AdaptiveLQG(vec.envs[0].unwrapped, identifier=fast_identifier(vec.envs[0]))
    returns, _ = evaluate_policy(ctrl, vec, n_eval_episodes=2, return_episode_rewards=True)
    copies = ctrl._batch
    assert len(copies) == 2 and copies[0].identifier is not copies[1].identifier
    # each identifier saw its own env's samples, none of the other's: 799 of 800, the
    # last one waits for the torque applied after it (reported at the next step)
    assert [c.identifier.n_samples for c in copies] == [799, 799]

    alone = []
    for i in range(2):
        env = gym.make("FlexibleSpacecraft-v2", **kwargs)
        solo = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env))
        obs, info = env.reset(seed=100 + i)
        solo.reset(seed=episode_seed(obs))     # an episode through predict: seeded by its start
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(solo.act(obs, info))
            total += reward
            done = terminated or truncated
        alone.append(total)
        assert solo.stats["redesigns"] + solo.stats["rejected"] > 0   # the identified loop ran
    # the reference is read from the float32 observation instead of info
    np.testing.assert_allclose(sorted(returns), sorted(alone), rtol=1e-4)


@pytest.mark.parametrize("outputs", [None, ("attitude", "rate", "attitude_error", "reference")],
                         ids=["default", "no-deflection-task-groups"])
@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_batched_evaluate_policy_equals_per_env_evaluation_to_1e9(env_id, outputs):
    """One controller state per env, each episode seeded by its first observation: env i
    of a batch of two scores exactly what ``make_vec_env(n_envs=1, seed=i)`` scores alone,
    on every registered id and observation layout (the adaptive loop's excitation is
    random, so a seed tied to the batch position made env 1 differ by 0.5 %)."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy

    kwargs = {"task": "slew", "max_episode_steps": 400}
    if outputs is not None:
        kwargs["outputs"] = outputs

    def evaluate(n_envs, seed):
        vec = make_vec_env(f"spacecraft_env:{env_id}", n_envs=n_envs, seed=seed,
                           env_kwargs=kwargs)
        env = gym.make(f"spacecraft_env:{env_id}", **kwargs)
        ctrl = AdaptiveLQG(env, identifier=fast_identifier(env))
        returns, _ = evaluate_policy(ctrl, vec, n_eval_episodes=n_envs,
                                     return_episode_rewards=True)
        return returns

    batched = evaluate(2, 0)
    per_env = [evaluate(1, i)[0] for i in range(2)]
    np.testing.assert_allclose(batched, per_env, rtol=1e-9, atol=0)


def test_a_loop_that_never_flies_its_identified_design_says_so():
    # AdaptiveLQG(env, identifier=ImprovedRPBSID(22)) flew the fallback on 100 % of its
    # steps without a word; the default identifier's loop flies and stays silent

    from controllers import FallbackWarning
    from identifiers import ImprovedRPBSID

    env = gym.make("FlexibleSpacecraftPaddleRotation-v2")
    for identifier, expected in ((ImprovedRPBSID(22), 1), (None, 0)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            ctrl = AdaptiveLQG(env, identifier=identifier)
            run_episode(env, ctrl, seed=0, max_steps=1300)
        said = [w for w in caught if issubclass(w.category, FallbackWarning)]
        assert len(said) == expected, [str(w.message) for w in said]
        if expected:
            assert "rejections by reason: prediction" in str(said[0].message)
            # attributed to the code that called act (the harness), not to the
            # BLAS-limiting decorator act runs in
            assert said[0].filename.endswith("harness.py"), said[0].filename


def test_a_scheduled_loop_without_the_drive_angle_says_so():
    """The default identifier follows the paddle drive through info["paddle_angle"]; a
    step without it (act without info, SB3's predict) leaves the model at its last
    angle, so the loop warns once, attributed to its caller. With info, or with an
    identifier that is not scheduled, nothing is said."""
    from controllers import ScheduleWarning, fast_identifier

    env = FlexibleSpacecraftEnv("paddle_rotation", task="slew")
    for make, with_info, expected in (
            (lambda: AdaptiveLQG(env), False, 1),
            (lambda: AdaptiveLQG(env), True, 0),
            (lambda: AdaptiveLQG(env, identifier=fast_identifier(env)), False, 0)):
        ctrl = make()
        obs, info = env.reset(seed=0)
        ctrl.reset(0)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(20):
                action = ctrl.act(obs, info if with_info else None)
                obs, _, _, _, info = env.step(action)
        said = [w for w in caught if issubclass(w.category, ScheduleWarning)]
        assert len(said) == expected, [str(w.message) for w in said]
        if expected:
            assert "paddle_angle" in str(said[0].message)
            assert said[0].filename == __file__, said[0].filename
            # the angle it keeps is the last one given: 0, where the drive has turned
            assert ctrl.identifier.angle == 0.0 != info["paddle_angle"]


def test_the_oracles_and_the_gain_error_know_the_familys_actuator_efficiency():
    """The task family draws an actuator efficiency a (torque received per torque
    commanded; info["torque"] is the commanded one): the plant's input matrix is a B.
    The true-model identifier, the oracles' designs and the harness's true rigid-body
    gain all use a J^-1, so the same-law oracle's identified gain has no error."""
    from controllers import TrueModelIdentifier

    env = gym.make("FlexibleSpacecraftFamily-v2", task="slew")
    for seed in range(20):                      # a draw clearly off 1
        env.reset(seed=seed)
        a = env.unwrapped.actuator_gain
        if abs(a - 1.0) > 0.15:
            break
    assert a == env.unwrapped.plant.actuator_gain and abs(a - 1.0) > 0.15
    # the plant integrates a times the commanded torque
    base = env.unwrapped
    x0, t0 = base.state, base.time
    _, _, _, _, info = env.step(np.array([0.3, -0.2, 0.1], dtype=np.float32))
    true = base.model.discrete(t0)
    np.testing.assert_allclose(info["state"], true.A @ x0 + a * true.B @ info["torque"],
                               rtol=1e-9, atol=1e-15)
    ident = TrueModelIdentifier(env)
    np.testing.assert_allclose(ident.model.B, a * base.model.discrete(0.0).B, rtol=1e-12)
    np.testing.assert_allclose(ident.rigid_gain.gain,
                               a * np.linalg.inv(base.model.inertia(0.0)), rtol=1e-12)
    same_law = AdaptiveLQG(env, identifier=TrueModelIdentifier(env))
    traj = run_episode(env, same_law, seed=seed, max_steps=100, freq_every=10)
    # (the gain read back from the discrete model's B is exact to 1e-4; without the
    # efficiency the error would be |a - 1| > 0.15)
    assert np.nanmax(traj.gain_error) < 1e-3
    # the oracle designs and filters on a B: the model its filter steps with
    oracle = OracleLQG(env)
    obs, info = env.reset(seed=seed)
    oracle.reset(seed)
    oracle.act(obs, info)
    np.testing.assert_allclose(oracle._pending[1], a * base.model.discrete(0.0).B,
                               rtol=1e-12)
    assert FlexibleSpacecraftEnv("constant").actuator_gain == 1.0


def test_a_scheduled_identifier_gets_each_samples_drive_angle():
    """AdaptiveLQG hands a scheduled identifier the encoder reading taken with each
    sample (``info["paddle_angle"]`` of the step that produced it), not the newer one."""
    from identifiers import ScheduledPhysicalIdentifier
    from spacecraft_env import DRIVE_AXIS

    env = FlexibleSpacecraftEnv("paddle_rotation")
    model = env.model
    ident = ScheduledPhysicalIdentifier(env.observation_layout.sensors(),
                                        turning=model.appendage_turns,
                                        sensor_appendage=model.sensor_appendage,
                                        drive_axis=DRIVE_AXIS, warmup=1000)
    ctrl = AdaptiveLQG(env, identifier=ident)
    obs, info = env.reset(seed=0)
    ctrl.reset(0)
    angles = []
    for _ in range(30):
        angles.append(info["paddle_angle"])
        obs, _, _, _, info = env.step(ctrl.act(obs, info))
    recorded = [sample[2] for sample in ident._record]
    np.testing.assert_array_equal(recorded, angles[:-1])
    assert np.ptp(recorded) > 0                      # the paddles turned meanwhile
    # the identifier's rotation about DRIVE_AXIS is the env's paddle rotation
    from identifiers.physical.scheduled_model import drive_rotation
    from spacecraft_env.dynamics import rotation_pitch

    np.testing.assert_allclose(drive_rotation(DRIVE_AXIS, 1.3), rotation_pitch(1.3), atol=1e-15)


def test_a_kept_value_holds_while_its_inputs_are_equal_and_never_goes_stale():
    from spacecraft_conventions import KeptWhileEqual

    kept: KeptWhileEqual = KeptWhileEqual()
    calls = []
    a, frozen = np.arange(4.0), np.ones(2)
    frozen.flags.writeable = False
    assert kept.get((a, frozen, 0.1), lambda: calls.append(1)) is None   # None is a value
    assert kept.holds((a.copy(), frozen, 0.1)) and len(calls) == 1
    assert kept.get((a, frozen, 0.1), lambda: calls.append(2)) is None and calls == [1]
    a[0] = 5.0                     # changed in place: the copy kept tells
    assert not kept.holds((a, frozen, 0.1))
    assert not kept.holds((a, frozen, 0.2)) and not kept.holds((a, frozen))
    assert kept.keep((a, frozen, 0.2), "x") == "x" and kept.value == "x"
    kept.clear()
    assert not kept.holds((a, frozen, 0.2)) and kept.value is None
    # the key is the inputs' bits: the same bits give the same value, whatever they hold
    nan = np.array([np.nan, 1.0])
    kept.keep((nan,), "from nan")
    assert kept.holds((nan.copy(),))
    assert not kept.holds((np.array([np.nan, -1.0]),))
    kept.keep((np.zeros(2),), "from +0")
    assert not kept.holds((-np.zeros(2),))                   # equal values, other bits
    assert not kept.holds((np.zeros(2, dtype=np.float32),))  # same values, other dtype
    assert not kept.holds((np.zeros((2, 1)),))               # same bytes, other shape
    kept.keep((0.0, 1), "scalars")
    assert kept.holds((0.0, 1)) and not kept.holds((-0.0, 1)) and not kept.holds((0.0, True))
    with pytest.raises(TypeError, match="dtype object"):
        kept.holds((np.array([object()]), 1))


@pytest.mark.parametrize("make", [PD, FixedLQG, AdaptiveLQG])
def test_a_controller_on_another_env_says_what_it_flies(make):
    with pytest.raises(TypeError, match=r"flies a flexible-spacecraft environment.*PendulumEnv"):
        make(gym.make("Pendulum-v1"))
