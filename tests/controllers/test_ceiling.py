"""The ceiling: the finite-horizon Riccati recursion against closed forms, and the
clairvoyant LQG against every controller of the package on short episodes."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

from controllers import (
    PD,
    AdaptiveLQG,
    ClairvoyantLQG,
    FixedLQG,
    OracleLQG,
    OracleLQR,
    RobustLQG,
    ScheduledLQG,
    adaptive_start,
    dlqr,
    finite_horizon_lqr,
    run_episode,
    same_start_ceiling,
    stage_costs,
    window_ceiling,
)
from controllers.harness import SAME_START_S
from spacecraft_env import ENV_IDS, env_id


def _brute_force(a, b, c, q, q_lin, r, x0, w=None, v=None):
    """The optimal inputs and cost of the affine LQ problem by stacking it into one
    least-squares problem in the inputs (the closed form for a short horizon); ``w`` and
    ``v`` weight each step's state and input cost."""
    horizon, n, m = b.shape
    w = np.ones(horizon) if w is None else w
    v = np.ones(horizon) if v is None else v
    # x_{k+1} = Phi_k x0 + Gamma_k U + d_k
    phi = np.eye(n)
    gammas, drifts, phis = [], [], []
    gamma = np.zeros((n, horizon * m))
    drift = np.zeros(n)
    for k in range(horizon):
        phi = a[k] @ phi
        gamma = a[k] @ gamma
        gamma[:, k * m:(k + 1) * m] += b[k]
        drift = a[k] @ drift + c[k]
        phis.append(phi.copy())
        gammas.append(gamma.copy())
        drifts.append(drift.copy())
    h = np.kron(np.diag(v), r)
    g = np.zeros(horizon * m)
    const = 0.0
    for wk, phi, gamma, drift in zip(w, phis, gammas, drifts, strict=True):
        free = phi @ x0 + drift
        h = h + wk * gamma.T @ q @ gamma
        g = g + wk * gamma.T @ (q @ free - q_lin)
        const += wk * (free @ q @ free - 2 * q_lin @ free)
    u = -np.linalg.solve(h, g)
    return u.reshape(horizon, m), const + g @ u


def _flown(gains, offsets, a, b, c, x0):
    """The inputs of the law ``u_k = -K_k x_k + f_k`` flown on the affine system from x0."""
    x, inputs = x0.copy(), []
    for k in range(len(gains)):
        inputs.append(-gains[k] @ x + offsets[k])
        x = a[k] @ x + b[k] @ inputs[-1] + c[k]
    return np.array(inputs)


def test_finite_horizon_lqr_is_the_optimum_of_the_stacked_problem(rng):
    horizon, n, m = 7, 4, 2
    a = rng.normal(size=(horizon, n, n)) * 0.6
    b = rng.normal(size=(horizon, n, m))
    c = rng.normal(size=(horizon, n))
    root = rng.normal(size=(n, n))
    q = root @ root.T
    q_lin = rng.normal(size=n)
    r = np.diag([0.5, 2.0])
    x0 = rng.normal(size=n)
    gains, offsets, p0, p0_lin, kappa0 = finite_horizon_lqr(a, b, c, q, q_lin, r)
    u_best, cost_best = _brute_force(a, b, c, q, q_lin, r, x0)
    # the feedback law flown from x0 gives the stacked problem's inputs and cost
    np.testing.assert_allclose(_flown(gains, offsets, a, b, c, x0), u_best, rtol=1e-9,
                               atol=1e-10)
    np.testing.assert_allclose(x0 @ p0 @ x0 - 2 * p0_lin @ x0 + kappa0, cost_best, rtol=1e-9)


def test_finite_horizon_lqr_weighs_each_step_as_told(rng):
    """A window's cost (state free on the first steps, input nearly free there): the law
    is the stacked problem's optimum for the same per-step weights."""
    horizon, n, m = 6, 3, 2
    a = rng.normal(size=(horizon, n, n)) * 0.7
    b = rng.normal(size=(horizon, n, m))
    c = rng.normal(size=(horizon, n))
    q, q_lin, r = np.diag([1.0, 2.0, 0.5]), rng.normal(size=n), np.diag([0.5, 2.0])
    w = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
    v = np.array([1e-3, 1e-3, 1e-3, 1.0, 1.0, 1.0])
    x0 = rng.normal(size=n)
    gains, offsets, p0, p0_lin, kappa0 = finite_horizon_lqr(a, b, c, q, q_lin, r, w, v)
    u_best, cost_best = _brute_force(a, b, c, q, q_lin, r, x0, w, v)
    np.testing.assert_allclose(_flown(gains, offsets, a, b, c, x0), u_best, rtol=1e-7,
                               atol=1e-9)
    np.testing.assert_allclose(x0 @ p0 @ x0 - 2 * p0_lin @ x0 + kappa0, cost_best, rtol=1e-8)
    with pytest.raises(ValueError, match=r"input_weights must be \(6,\) finite values > 0"):
        finite_horizon_lqr(a, b, c, q, q_lin, r, w, np.zeros(horizon))
    with pytest.raises(ValueError, match="stage_weights must be"):
        finite_horizon_lqr(a, b, c, q, q_lin, r, -w)


def test_a_long_horizon_gives_the_stationary_lqr_gain_at_its_start():
    dt = 0.1
    a = np.array([[1.0, dt], [0.0, 1.0]])
    b = np.array([[0.5 * dt * dt], [dt]])
    q, r = np.diag([1.0, 0.1]), np.array([[0.3]])
    horizon = 2000
    gains, *_ = finite_horizon_lqr(np.broadcast_to(a, (horizon, 2, 2)),
                                   np.broadcast_to(b, (horizon, 2, 1)),
                                   np.zeros((horizon, 2)), q, np.zeros(2), r)
    stationary, _ = dlqr(a, b, q, r)
    np.testing.assert_allclose(gains[0], stationary, rtol=1e-8)
    # the last step's gain looks one step ahead only: H^-1 B^T Q A
    np.testing.assert_allclose(gains[-1], np.linalg.solve(r + b.T @ q @ b, b.T @ q @ a))


def test_finite_horizon_lqr_rejects_bad_shapes_and_values():
    with pytest.raises(ValueError, match=r"a must have shape \(N, n, n\)"):
        finite_horizon_lqr(np.ones((2, 2)), np.ones((1, 2, 1)), np.zeros((1, 2)),
                           np.eye(2), np.zeros(2), np.eye(1))
    with pytest.raises(ValueError, match="c must be"):
        finite_horizon_lqr(np.ones((1, 2, 2)), np.ones((1, 2, 1)), np.zeros((2, 2)),
                           np.eye(2), np.zeros(2), np.eye(1))
    with pytest.raises(ValueError, match="finite"):
        finite_horizon_lqr(np.full((1, 2, 2), np.nan), np.ones((1, 2, 1)), np.zeros((1, 2)),
                           np.eye(2), np.zeros(2), np.eye(1))


def _cost(env, controller, seed):
    traj = run_episode(env, controller, seed=seed)
    if traj.terminated:
        return np.inf
    return float(stage_costs(traj, env.unwrapped.model)[:, :4].sum(axis=1).mean())


#: Every fixed controller of the package (the adaptive loop's short-episode check is below).
FIXED = {"PD": PD, "fixed LQG": FixedLQG, "robust LQG": RobustLQG,
         "scheduled LQG": ScheduledLQG, "oracle LQG": OracleLQG,
         "full-state oracle": OracleLQR}


@pytest.mark.parametrize("task", ["slew", "regulation"])
@pytest.mark.parametrize("scenario", sorted(ENV_IDS.values()))
def test_no_controller_beats_the_ceiling(scenario, task):
    """Short episodes (40 s) of every registered scenario and both tasks: no controller's
    whole-episode cost is more than 2 % below the ceiling's, on two seeds. (The 10-seed,
    full-length check is ``benchmarks/bench_ceiling.py`` and its slow test.)"""
    for seed in (0, 1):
        env = gym.make(env_id(scenario), task=task, max_episode_steps=400)
        ceiling = _cost(env, ClairvoyantLQG(env), seed)
        assert np.isfinite(ceiling) and ceiling > 0
        for name, make in FIXED.items():
            cost = _cost(env, make(env), seed)
            assert cost >= 0.98 * ceiling, (name, seed, cost / ceiling)
        env.close()


@pytest.mark.parametrize("scenario", ["paddle_rotation", "docking"])
def test_no_controller_beats_the_window_ceiling_over_its_window(scenario):
    """The window ceiling's plan of the cost from 20 s on (40 s episodes): every fixed
    controller and the whole-episode ceiling cost at least 0.98 times its cost over that
    window, and it pays for it before the window."""
    env = gym.make(env_id(scenario), max_episode_steps=400)

    def costs(controller):
        traj = run_episode(env, controller, seed=2)
        stage = stage_costs(traj, env.unwrapped.model)[:, :4].sum(axis=1)
        return stage[traj.time >= 20.0].mean(), stage.mean()

    window, whole = costs(window_ceiling(env, from_s=20.0))
    assert window_ceiling(env).name == "window ceiling"
    ceiling = costs(ClairvoyantLQG(env))
    assert ceiling[0] > 2 * window and ceiling[1] < whole
    for name, make in FIXED.items():
        cost = costs(make(env))[0]
        assert cost >= 0.98 * window, (name, cost / window)
    env.close()


def test_the_adaptive_loop_and_its_same_start_ceiling_stay_above_the_ceiling():
    """The adaptive loop past its warm-up (fit included), the same-start ceiling behind
    the same start, and the ceiling: ordered as they must be."""
    env = gym.make(env_id("constant"), task="slew", max_episode_steps=520)
    ceiling = _cost(env, ClairvoyantLQG(env), 3)
    same_start = _cost(env, same_start_ceiling(env), 3)
    adaptive = _cost(env, AdaptiveLQG(env), 3)
    assert ceiling < same_start <= 1.02 * adaptive
    env.close()


def test_the_same_start_is_the_adaptive_loops_start():
    """The same-start ceiling flies exactly the torques the adaptive loop flies until the
    loop's first model can fly (its identifier's warm-up and the fit's latency)."""
    env = gym.make(env_id("paddle_rotation"), max_episode_steps=401)
    start, steps = adaptive_start(env)
    assert steps == 400 and start.excitation.warmup_steps == 300
    # the tables' window starts where the same start ends
    assert steps * env.unwrapped.model.dt == pytest.approx(SAME_START_S)
    loop = run_episode(env, AdaptiveLQG(env), seed=7)
    ceiling = run_episode(env, same_start_ceiling(env), seed=7)
    np.testing.assert_array_equal(loop.torque[:steps], ceiling.torque[:steps])
    assert np.abs(ceiling.excitation[:300]).max() == pytest.approx(0.5)
    assert not ceiling.excitation[300:].any()
    env.close()


def test_the_ceiling_knows_the_noise_it_flies_in():
    """Noise-free from the slew's known start (at rest at zero), the ceiling's filter is
    exact: the plan flown is the plan's optimum (its cost equals the value function's
    prediction from the initial state)."""
    env = gym.make(env_id("docking"), task="slew", snr_db=None, max_torque=100.0,
                   max_episode_steps=1900)
    ctrl = ClairvoyantLQG(env)
    traj = run_episode(env, ctrl, seed=2)
    model = env.unwrapped.model
    costs = stage_costs(traj, model)[:, :4].sum(axis=1)
    assert np.abs(traj.actions).max() < 0.999           # no saturation: the linear plant
    # the plan's problem solved in closed form from the initial state
    *problem, constant = ctrl.problem(0, traj.reference[0])
    _, _, p0, p0_lin, kappa0 = finite_horizon_lqr(*problem)
    x0 = traj.states[0]
    predicted = x0 @ p0 @ x0 - 2 * p0_lin @ x0 + kappa0 + len(traj.time) * constant
    np.testing.assert_allclose(costs.sum(), predicted, rtol=1e-6)
    assert traj.events and traj.time[-1] > max(traj.events)       # through both dockings
    env.close()


def test_the_ceiling_plans_through_a_delay_and_a_disturbance():
    """An actuator delay and a constant disturbance torque are in the plan: the ceiling
    stays below the oracle LQG, which knows neither in advance."""
    env = gym.make(env_id("constant"), task="slew", actuator_delay_steps=3,
                   disturbance_torque=[0.02, -0.01, 0.0], max_episode_steps=400)
    assert _cost(env, ClairvoyantLQG(env), 0) < _cost(env, OracleLQG(env), 0)
    env.close()


def test_the_ceiling_is_deterministic_and_pickles():
    env = gym.make(env_id("paddle_rotation"), max_episode_steps=50)
    ctrl = ClairvoyantLQG(env)
    first = run_episode(env, ctrl, seed=4)
    again = run_episode(env, pickle.loads(pickle.dumps(ctrl)), seed=4)
    np.testing.assert_allclose(first.torque, again.torque, rtol=1e-12, atol=1e-15)
    env.close()


def test_the_ceiling_validates_its_arguments():
    env = gym.make(env_id("constant"), max_episode_steps=50)
    with pytest.raises(ValueError, match="horizon_steps must be an integer >= 1"):
        ClairvoyantLQG(env, horizon_steps=0)
    with pytest.raises(ValueError, match="start_steps must be an integer >= 0"):
        ClairvoyantLQG(env, start=PD(env), start_steps=-1)
    with pytest.raises(TypeError, match="start must be a controller"):
        ClairvoyantLQG(env, start=object(), start_steps=3)
    with pytest.raises(ValueError, match="window_start_steps must be an integer >= 0"):
        ClairvoyantLQG(env, window_start_steps=-2)
    with pytest.raises(ValueError, match="from_s must be a finite time >= 0"):
        window_ceiling(env, from_s=float("nan"))
    ctrl = ClairvoyantLQG(env)
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="needs the env's info dict"):
        ctrl.act(obs)
    env.close()


def test_the_ceiling_plans_through_a_captured_momentum():
    """Modules that bring angular momentum: the capture (an affine jump of the rates) is in
    the plan, so the ceiling meets it prepared and stays below the controllers that do not
    know it is coming."""
    from spacecraft_lab.control import env_kwargs_for

    kwargs = env_kwargs_for("docking", capture_momentum=(0.0, 0.0, 50.0), task="regulation")
    env = gym.make(env_id("docking"), max_episode_steps=1900, **kwargs)
    assert env.unwrapped.model.capture_steps()
    ceiling = _cost(env, ClairvoyantLQG(env), 0)
    assert ceiling < 0.9 * min(_cost(env, OracleLQG(env), 0), _cost(env, PD(env), 0))
    env.close()
