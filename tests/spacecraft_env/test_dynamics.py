"""Truth-model checks against closed forms (docs/design/model.md)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from spacecraft_env import (
    ANTENNA_FREQUENCIES_HZ,
    PADDLE_FREQUENCIES_HZ,
    SCENARIOS,
    DockingModule,
    DockingScenario,
    FlexibleSpacecraftModel,
    SolarRotationScenario,
    ets8_parameters,
)
from spacecraft_env.modes import (
    cantilever_eigenvalues,
    cantilever_mode_shape,
    cantilever_moments,
    coupling_matrix,
)


def _modal(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (Hz) and damping of the oscillatory eigenvalues."""
    ev = np.linalg.eigvals(a)
    ev = ev[ev.imag > 1e-9]
    wn = np.abs(ev)
    order = np.argsort(wn)
    return wn[order] / (2 * np.pi), -ev.real[order] / wn[order]


@pytest.mark.parametrize("n_modes", [1, 2, 5, 8])
def test_uncoupled_frequencies_and_damping_equal_table2(n_modes):
    model = FlexibleSpacecraftModel(ets8_parameters(n_modes, coupling=False))
    freq, zeta = _modal(model.continuous(0.0).A)
    expected = np.sort(np.concatenate([PADDLE_FREQUENCIES_HZ[:n_modes]] * 2
                                      + [ANTENNA_FREQUENCIES_HZ[:n_modes]] * 2))
    np.testing.assert_allclose(freq, expected, rtol=1e-10)
    np.testing.assert_allclose(zeta, 0.01, rtol=1e-10)
    assert model.n == 2 * (3 + 4 * n_modes)


def test_coupling_raises_system_frequencies():
    """Clamped-hub (cantilever) frequencies are lower bounds of the free ones."""
    coupled = _modal(FlexibleSpacecraftModel(ets8_parameters(2)).continuous(0.0).A)[0]
    uncoupled = _modal(FlexibleSpacecraftModel(ets8_parameters(2, coupling=False))
                       .continuous(0.0).A)[0]
    assert np.all(coupled >= uncoupled - 1e-12)
    assert np.max(coupled / uncoupled) > 1.01  # the coupling really is there


def test_cantilever_roots_and_closed_form_moments():
    np.testing.assert_allclose(cantilever_eigenvalues(4),
                               [1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349],
                               rtol=1e-9)
    xi = np.linspace(0.0, 1.0, 200001)
    psi = cantilever_mode_shape(xi, 8)
    np.testing.assert_allclose(np.trapezoid(psi**2, xi, axis=0), 1.0, rtol=1e-6)
    i0, i1 = cantilever_moments(8)
    np.testing.assert_allclose(np.trapezoid(psi, xi, axis=0), i0, rtol=1e-6)
    np.testing.assert_allclose(np.trapezoid(xi[:, None] * psi, xi, axis=0), i1, rtol=1e-6)
    np.testing.assert_allclose(np.abs(psi[-1]), 2.0, rtol=1e-9)   # tip of unit-norm shape
    np.testing.assert_allclose(psi[0], 0.0, atol=1e-9)             # clamped root


def test_coupling_matrix_equals_span_integral():
    mass, length = 115.2, 7.55
    hinge, span, bend = np.array([0.0, 1.2, 0.5]), np.array([0.0, 1.0, 0.0]), np.array(
        [0.6, 0.0, 0.8])
    s = np.linspace(0.0, length, 100001)
    phi = cantilever_mode_shape(s / length, 3) / np.sqrt(mass)
    rho = hinge[None, :] + s[:, None] * span[None, :]
    lever = np.cross(rho, bend)                                   # (s, 3)
    numeric = np.trapezoid(lever[:, :, None] * phi[:, None, :] * mass / length, s, axis=0)
    np.testing.assert_allclose(coupling_matrix(mass, length, hinge, span, bend, 3), numeric,
                               rtol=1e-6, atol=1e-9)


def test_rigid_hub_double_integrator():
    """Without coupling a constant torque gives psi = J^-1 u t^2 / 2 exactly."""
    model = FlexibleSpacecraftModel(ets8_parameters(2, coupling=False))
    u = np.array([2.0, -1.0, 0.5])
    n_steps = 300
    states, _ = model.simulate(np.tile(u, (n_steps, 1)))
    t = n_steps * model.dt
    expected = np.linalg.solve(model.inertia(0.0), u) * t**2 / 2
    np.testing.assert_allclose(states[-1, :3], expected, rtol=1e-9)
    np.testing.assert_allclose(states[-1, model.n_dof:model.n_dof + 3],
                               np.linalg.solve(model.inertia(0.0), u) * t, rtol=1e-9)


def test_inertia_follows_appendix_a():
    model = FlexibleSpacecraftModel(scenario="docking")
    j0 = model.inertia(0.0)
    np.testing.assert_allclose(j0, [[28898.5, 0, 1707.6], [0, 19397.9, 0], [1707.6, 0, 22363.0]],
                               atol=0.5)
    # docking: each 600 kg module adds its own inertia plus m (|r|^2 I - r r^T)
    mod = DockingModule()
    own = 600.0 / 12 * np.diag([2.45**2 + 3**2, 2.35**2 + 3**2, 2.35**2 + 2.45**2])
    added = own + 600.0 * np.diag([9.0, 9.0, 0.0])
    np.testing.assert_allclose(mod.inertia_about_system_centre(), added)
    np.testing.assert_allclose(model.inertia(99.9), j0)
    np.testing.assert_allclose(model.inertia(100.0), j0 + added)
    np.testing.assert_allclose(model.inertia(179.9), j0 + added)
    np.testing.assert_allclose(model.inertia(180.0), j0 + 2 * added)


def test_inertia_under_paddle_rotation():
    """50 deg of paddle rotation: J_xz from +1708 to about -2213 (docs/design/model.md)."""
    model = FlexibleSpacecraftModel(scenario=SolarRotationScenario(rate_deg_s=0.2))
    j50 = model.inertia(250.0)
    assert j50[0, 2] == pytest.approx(-2213.4, abs=1.0)
    js = np.array([[1683.4, 0, 853.8], [0, 18.2, 0], [853.8, 0, 3629.9]])
    c, s = np.cos(np.deg2rad(50)), np.sin(np.deg2rad(50))
    t_s = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    expected = model.inertia(0.0) + 2 * (t_s.T @ js @ t_s - js)
    np.testing.assert_allclose(j50, expected, rtol=1e-12)
    # the paddles' coupling turns with them; the antennas' does not
    f0, f50 = model.coupling(0.0), model.coupling(250.0)
    assert not np.allclose(f0[:, :4], f50[:, :4])
    np.testing.assert_allclose(f0[:, 4:], f50[:, 4:])


def test_mass_matrix_positive_definite_and_checked():
    model = FlexibleSpacecraftModel(scenario="docking")
    for t in (0.0, 150.0, 200.0):
        assert np.linalg.eigvalsh(model.mass_matrix(t)).min() > 0
    # an absurdly heavy appendage on a tiny hub makes M indefinite: must raise
    from dataclasses import replace

    p = ets8_parameters(2)
    tiny = replace(p, hub_inertia=np.eye(3) * 1.0,
                   appendages=tuple(replace(a, inertia=np.eye(3) * 1.0) for a in p.appendages))
    bad = FlexibleSpacecraftModel(tiny, scenario="constant")
    with pytest.raises(ValueError, match="positive definite"):
        bad.continuous(0.0)


def test_energy_conserved_without_damping():
    model = FlexibleSpacecraftModel(ets8_parameters(3).with_damping(0.0))
    rng = np.random.default_rng(3)
    x = rng.normal(size=model.n) * 1e-3
    e0 = model.energy(x, 0.0)
    states, _ = model.simulate(np.zeros((3000, 3)), x0=x)
    energies = [model.energy(s, 0.0) for s in states[::100]]
    np.testing.assert_allclose(energies, e0, rtol=1e-9)


@pytest.mark.parametrize("scenario", ["constant", "docking", "solar_rotation"])
def test_zoh_step_matches_fine_integration(scenario):
    model = FlexibleSpacecraftModel(scenario=scenario)
    rng = np.random.default_rng(0)
    x = rng.normal(size=model.n) * 1e-3
    u = np.array([3.0, -2.0, 1.0])
    t0 = 150.0
    a, b = model.continuous(t0).A, model.continuous(t0).B
    sol = solve_ivp(lambda _t, z: a @ z + b @ u, (0.0, model.dt), x, rtol=1e-12, atol=1e-15,
                    method="DOP853")
    np.testing.assert_allclose(model.step(x, u, t0), sol.y[:, -1], rtol=1e-8, atol=1e-14)


def test_zoh_over_a_docking_event_uses_the_segment_matrices():
    model = FlexibleSpacecraftModel(scenario="docking")
    before, after = model.discrete(99.9), model.discrete(100.0)
    assert not np.allclose(before.A, after.A)
    np.testing.assert_array_equal(model.discrete(100.0).A, model.discrete(150.0).A)


def test_true_matrices_api_shapes():
    model = FlexibleSpacecraftModel(scenario="docking", outputs=("attitude", "rate"))
    cont, disc = model.continuous(10.0), model.discrete(10.0)
    assert cont.A.shape == (22, 22) and cont.B.shape == (22, 3) and cont.C.shape == (6, 22)
    assert cont.dt is None and disc.dt == pytest.approx(0.1)
    assert model.output_labels == ("psi_x", "psi_y", "psi_z", "omega_x", "omega_y", "omega_z")
    disc.A[0, 0] = 123.0  # a copy: the cache is untouched
    assert model.discrete(10.0).A[0, 0] != 123.0


def test_randomized_scenarios_are_seeded():
    base = DockingScenario()
    a = base.randomized(np.random.default_rng(5))
    b = base.randomized(np.random.default_rng(5))
    c = base.randomized(np.random.default_rng(6))
    assert a == b and a != c
    t1, t2 = a.event_times()
    assert 60 <= t1 <= 140 and t2 >= t1 + 20
    rate = SolarRotationScenario().randomized(np.random.default_rng(1)).rate_deg_s
    assert 0.1 <= rate <= 0.4


def test_model_pickles():
    model = FlexibleSpacecraftModel(scenario="solar_rotation")
    model.discrete(3.0)
    clone = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(clone.discrete(3.0).A, model.discrete(3.0).A)


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"scenario": "dockin"}, ValueError),
        ({"scenario": 3}, TypeError),
        ({"outputs": ("attitude", "speed")}, ValueError),
        ({"dt": -0.1}, ValueError),
        ({"params": "ets8"}, TypeError),
    ],
)
def test_model_bad_input(kwargs, error):
    with pytest.raises(error):
        FlexibleSpacecraftModel(**kwargs)


@pytest.mark.parametrize(
    "call",
    [
        lambda: ets8_parameters(0),
        lambda: ets8_parameters(9),
        lambda: ets8_parameters(2.5),
        lambda: ets8_parameters(2, damping=-0.1),
        lambda: ets8_parameters(2, sensor_positions=(1.2,)),
        lambda: DockingModule(mass=-1.0),
        lambda: DockingModule(dimensions=(1.0, 2.0)),
        lambda: SolarRotationScenario(rate_deg_s=float("nan")),
    ],
)
def test_parameter_validation(call):
    with pytest.raises((ValueError, TypeError)):
        call()


def test_modal_matches_eigenvalues_and_table2_without_coupling():
    model = FlexibleSpacecraftModel(ets8_parameters(2, coupling=False))
    freq, zeta = model.modal(0.0)
    expected = np.sort(np.concatenate([PADDLE_FREQUENCIES_HZ[:2]] * 2
                                      + [ANTENNA_FREQUENCIES_HZ[:2]] * 2))
    np.testing.assert_allclose(freq, expected, rtol=1e-10)
    np.testing.assert_allclose(zeta, 0.01, rtol=1e-10)


def test_mass_centre_shift_gives_the_reduced_mass_inertia_and_moves_every_root():
    from spacecraft_env.modes import coupling_matrix
    from spacecraft_env.parameters import DockingModule
    from spacecraft_env.scenarios import DockingScenario

    module = DockingModule(mass=900.0, position=(1.2, -0.7, 3.0), time=5.0)
    plain = FlexibleSpacecraftModel(scenario=DockingScenario(modules=(module,)))
    shifted = FlexibleSpacecraftModel(
        scenario=DockingScenario(modules=(module,), mass_centre_shift=True))
    p = plain.params
    m0 = p.hub_mass + sum(a.mass for a in p.appendages)
    r = np.asarray(module.position)
    # closed form: the module's parallel-axis term with the reduced mass m m0 / (m + m0)
    mu = module.mass * m0 / (module.mass + m0)
    own = module.inertia_about_system_centre() - module.mass * (r @ r * np.eye(3)
                                                                 - np.outer(r, r))
    expected = plain.inertia(0.0) + own + mu * (r @ r * np.eye(3) - np.outer(r, r))
    np.testing.assert_allclose(shifted.inertia(10.0), expected, rtol=1e-12)
    np.testing.assert_array_equal(shifted.inertia(0.0), plain.inertia(0.0))  # before docking
    # a non-rotating appendage's coupling is the one of its root seen from the new centre
    c = module.mass * r / (module.mass + m0)
    f = shifted.coupling(10.0)
    start = 3
    for a in p.appendages:
        if not a.rotates:
            cols = slice(start - 3, start - 3 + a.n_modes)
            np.testing.assert_allclose(
                f[:, cols], coupling_matrix(a.mass, a.length, np.asarray(a.hinge) - c,
                                            np.asarray(a.span_axis), np.asarray(a.bending_axis),
                                            a.n_modes), rtol=1e-12, atol=1e-12)
        start += a.n_modes


@pytest.mark.parametrize("momentum", [(0.0, 0.0, 0.0), (20.0, -5.0, 40.0)])
def test_capture_conserves_angular_momentum(momentum):
    import gymnasium as gym

    from spacecraft_env.parameters import DockingModule
    from spacecraft_env.scenarios import DockingScenario

    module = DockingModule(mass=800.0, position=(0.5, 0.0, 3.0), time=10.0,
                           angular_momentum=momentum)
    env = gym.make("FlexibleSpacecraft-v2", scenario=DockingScenario(modules=(module,)),
                   snr_db=None).unwrapped
    env.reset(seed=0, options={"initial_rate": [0.002, -0.001, 0.003]})
    model, nd = env.model, env.model.n_dof

    def body_momentum():   # top rows of M(t) delta': the total angular momentum, N m s
        t = env.time
        return (model.mass_matrix(t) @ env._x[nd:])[:3]

    history = []
    for _ in range(200):
        history.append(body_momentum())
        env.step(np.zeros(3, dtype=np.float32))
    history = np.array(history)
    capture = 100          # step 100 starts at t = 10 s; its state is the one before the capture
    scale = np.abs(history[0]).max()
    np.testing.assert_allclose(history[:capture] - history[0], 0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(history[capture + 1:] - history[0] - momentum, 0.0,
                               atol=1e-12 * scale)
    rates = np.array(env._x[nd:nd + 3])
    assert not np.allclose(rates, [0.002, -0.001, 0.003], rtol=0.05)   # the rates did jump


def test_co_rotating_modules_leave_the_rates_alone():
    from spacecraft_env.parameters import DockingModule
    from spacecraft_env.scenarios import DockingScenario

    model = FlexibleSpacecraftModel(scenario=DockingScenario(
        modules=(DockingModule(time=10.0),)))
    assert model.capture_steps() == frozenset()
    x = np.arange(model.n, dtype=float)
    np.testing.assert_array_equal(model.capture(x, 10.0), x)


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_scenario_paddle_angle_is_the_configurations(name):
    rng = np.random.default_rng(7)
    scenario = SCENARIOS[name]().randomized(rng)
    for t in (0.0, 0.1, 37.3, 150.0, 249.9):
        assert scenario.paddle_angle(t) == scenario.configuration(t).paddle_angle


def test_the_drive_axis_and_the_appendage_map_describe_the_model():
    """``DRIVE_AXIS`` is the axis ``rotation_pitch`` turns about; ``sensor_appendage``
    and ``appendage_turns`` follow the parameters (what a scheduled identifier reads)."""
    from spacecraft_env import DRIVE_AXIS, FlexibleSpacecraftModel, ets8_parameters
    from spacecraft_env.dynamics import rotation_pitch

    for angle in (0.3, 1.7, -2.0):
        r = rotation_pitch(angle)
        np.testing.assert_allclose(r @ DRIVE_AXIS, DRIVE_AXIS, atol=1e-15)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
        assert np.trace(r) == pytest.approx(1 + 2 * np.cos(angle))
    params = ets8_parameters(sensor_positions=(0.5, 1.0))
    model = FlexibleSpacecraftModel(params)
    assert model.sensor_appendage == (0, 0, 1, 1, 2, 2, 3, 3)
    assert model.appendage_turns == tuple(a.rotates for a in params.appendages)
    assert sum(model.appendage_turns) == 2
