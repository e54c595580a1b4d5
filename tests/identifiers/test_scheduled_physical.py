"""The drive-scheduled physical model (closed forms), its fit and its identifier."""

from __future__ import annotations

import dataclasses
import itertools
import pickle

import numpy as np
import pytest
from scipy.stats import chi2

from identifiers import (
    ScheduledPhysicalIdentifier,
    ScheduledPhysicalModel,
    StateSpaceModel,
    fit_scheduled_model,
    h_step_predictions,
    prediction_vaf,
    relative_gain_error,
)
from identifiers.core.change_detection import ChangeEvent
from identifiers.physical import warmup_fit
from identifiers.physical.scheduled_fit import noise_floor
from identifiers.physical.scheduled_identifier import EXPORT_RESOLUTION
from identifiers.physical.scheduled_model import _cross, drive_rotation, plane_basis
from identifiers.physical.scheduled_simulation import segments, simulate_scheduled
from spacecraft_conventions import STANDARD_OUTPUTS, OutputLayout
from spacecraft_lab.identification import drive_angles, env_record

TURNING = (True, True, False, False)
REST = np.array([[2.0e4, 500.0, 300.0], [500.0, 1.5e4, -200.0], [300.0, -200.0, 2.5e4]])
COUPLINGS = np.array([[40.0, 5.0, 20.0], [-40.0, 5.0, -20.0], [10.0, 30.0, 0.0],
                      [0.0, -25.0, 15.0]])


def _model(anisotropy=(800.0, -300.0)) -> ScheduledPhysicalModel:
    return ScheduledPhysicalModel(REST, anisotropy, [0.07, 0.08, 0.09, 0.12],
                                  [0.01, 0.02, 0.01, 0.005], COUPLINGS, TURNING,
                                  [0.01, -0.012, 0.008, 0.01], [0, 1, 2, 3],
                                  (0.0, 1.0, 0.0))


def _record(model, steps, rng, rate=0.017453292519943295, start=0.3, disturbance=0.0):
    """Random binary torques of 1 N m held 1 s, the drive turning at ``rate`` rad/s (1 deg/s),
    and the noise-free outputs (with a constant torque ``disturbance`` acting besides)."""
    u = np.repeat(rng.choice([-1.0, 1.0], size=(steps // 10 + 1, 3)), 10, axis=0)[:steps]
    angle = start + rate * 0.1 * np.arange(steps)
    x = simulate_scheduled(model, u + disturbance, angle, 0.1, np.zeros(model.order))
    return u, x @ model.output_matrix(STANDARD_OUTPUTS).T, angle


def test_rotation_about_the_drive_axis():
    a = 0.7
    c, s = np.cos(a), np.sin(a)
    np.testing.assert_allclose(drive_rotation((0, 1, 0), a),
                               [[c, 0, s], [0, 1, 0], [-s, 0, c]], atol=1e-15)
    e1, e2 = plane_basis((0.0, 0.0, 1.0))
    np.testing.assert_allclose(np.cross(e1, e2), [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose([e1 @ [0, 0, 1], e2 @ [0, 0, 1], e1 @ e2], 0, atol=1e-15)


@pytest.mark.parametrize("angle", [0.0, 0.9, 2.5])
def test_the_state_equations_are_the_mass_matrix_equations(angle):
    """``M(a) [omega'; eta''] = [u; -W^2 eta - 2 Z W eta']`` for any state and torque."""
    model = _model()
    a, b = model.continuous(angle)
    rng = np.random.default_rng(0)
    x, u = rng.normal(size=model.order), rng.normal(size=3)
    dx = a @ x + b @ u
    f, j = model.coupling(angle), model.inertia(angle)
    mass = np.block([[j, f], [f.T, np.eye(4)]])
    w = 2 * np.pi * model.frequencies_hz
    eta, deta = x[6:10], x[10:14]
    rhs = np.concatenate([u, -(w**2) * eta - 2 * model.damping * w * deta])
    accelerations = np.concatenate([dx[3:6], dx[10:14]])
    np.testing.assert_allclose(mass @ accelerations, rhs, rtol=1e-9,
                               atol=1e-9 * np.abs(rhs).max())
    np.testing.assert_allclose(dx[0:3], x[3:6])
    assert np.linalg.eigvalsh(mass).min() > 0


def test_the_drive_turns_only_what_it_carries():
    model = _model()
    f0, f1 = model.coupling(0.0), model.coupling(1.2)
    np.testing.assert_array_equal(f0[:, 2:], f1[:, 2:])
    np.testing.assert_allclose(f1[:, :2], drive_rotation((0, 1, 0), 1.2).T @ f0[:, :2])
    # the turning inertia is R^T (|P| Pi + P) R: in-plane eigenvalues 2 |P| and 0
    for angle in (0.0, 1.2, 4.0):
        f = model.coupling(angle)
        turning = model.inertia(angle) - REST - f @ f.T
        np.testing.assert_allclose(np.linalg.eigvalsh(turning),
                                   [0.0, 0.0, 2 * np.hypot(800.0, 300.0)], atol=1e-9)
        np.testing.assert_allclose(turning @ [0.0, 1.0, 0.0], 0.0, atol=1e-12)
    assert not np.allclose(model.inertia(0.0), model.inertia(1.2))
    # an anisotropy as large as the rest inertia still leaves M(a) definite everywhere
    heavy = _model(anisotropy=(3e4, 2e4))
    for angle in np.linspace(0, 2 * np.pi, 13):
        a, _ = heavy.continuous(angle)
        assert np.all(np.isfinite(a))
    still = _model(anisotropy=(0.0, 0.0))
    fixed = ScheduledPhysicalModel(REST, (0.0, 0.0), still.frequencies_hz, still.damping,
                                   COUPLINGS, (False,) * 4, still.tips, [0, 1, 2, 3],
                                   (0.0, 1.0, 0.0))
    np.testing.assert_array_equal(fixed.zoh(0.0, 0.1)[0], fixed.zoh(2.0, 0.1)[0])


def test_the_discrete_model_is_the_zero_order_hold_of_the_continuous_one():
    model = _model()
    d = model.discrete(0.4, 0.1, STANDARD_OUTPUTS)
    assert isinstance(d, StateSpaceModel) and d.A.shape == (14, 14) and d.C.shape == (10, 14)
    a, b = model.continuous(0.4)
    # small dt: A_d ~ I + A dt, B_d ~ B dt
    small = model.zoh(0.4, 1e-6)
    np.testing.assert_allclose(small[0], np.eye(14) + a * 1e-6, atol=1e-10)
    np.testing.assert_allclose(small[1], b * 1e-6, atol=1e-10 * np.abs(b).max())
    np.testing.assert_array_equal(d.C[6:, 6:10], np.diag(model.tips))


def test_stacked_angles_give_the_per_angle_model_and_the_simulation_its_recursion():
    """``continuous``/``zoh`` on K angles equal the K single-angle calls (to rounding), and
    the compiled simulation equals ``x_{t+1} = A_b x_t + B_b u_t`` block by block."""
    model = _model()
    angles = np.array([0.1, 0.9, 2.5, -1.3])
    a, b = model.continuous(angles)
    ad, bd = model.zoh(angles, 0.1)
    assert a.shape == ad.shape == (4, 14, 14) and b.shape == bd.shape == (4, 14, 3)
    assert model.coupling(angles).shape == (4, 3, 4)
    for k, angle in enumerate(angles):
        for stacked, single in zip((a[k], b[k], ad[k], bd[k]),
                                   (*model.continuous(angle), *model.zoh(angle, 0.1)),
                                   strict=True):
            np.testing.assert_allclose(stacked, single, rtol=1e-13,
                                       atol=1e-13 * np.abs(single).max())
    u, _, angle = _record(model, 120, np.random.default_rng(2), rate=0.01)
    x0 = np.random.default_rng(3).normal(size=model.order) * 1e-3
    blocks = segments(angle)
    assert 5 < len(blocks) < 60             # blocks of several samples
    states = simulate_scheduled(model, u, angle, 0.1, x0)
    x, expected = x0.copy(), np.empty_like(states)
    for s0, s1 in blocks:
        a_d, b_d = model.zoh(0.5 * (angle[s0] + angle[s1 - 1]), 0.1)
        for t in range(s0, s1):
            expected[t] = x
            x = a_d @ x + b_d @ u[t]
    np.testing.assert_allclose(states, expected, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("disturbance", [False, True])
def test_the_fits_jacobian_is_the_forward_difference_of_its_residuals(disturbance):
    """The initial state's (and the disturbance's) columns, which reuse the blocks'
    matrices, equal those of a full re-simulation; every column is the forward
    difference of the residuals."""
    from identifiers.physical.scheduled_fit import _Problem

    truth = _model()
    u, y, angle = _record(truth, 150, np.random.default_rng(4))
    problem = _Problem(u, y, angle, 0.1, STANDARD_OUTPUTS, 1.0 / STANDARD_OUTPUTS.scales(),
                       np.array(TURNING), np.arange(4), np.array([0.0, 1.0, 0.0]),
                       disturbance)
    x0 = np.random.default_rng(5).normal(size=truth.order) * 1e-3
    p = problem.pack(truth.rest_inertia, truth.drive_anisotropy,
                     2 * np.pi * truth.frequencies_hz, truth.damping, truth.couplings, x0,
                     (0.02, -0.01, 0.03))
    assert p.size == 8 + 5 * 4 + truth.order + (3 if disturbance else 0)
    lo, hi = problem.bounds(p.size)
    jac = problem.jacobian(p, lo, hi)
    f0 = problem.evaluate(p)[0]
    expected = np.empty_like(jac)
    for i in range(p.size):
        q = p.copy()
        q[i] += np.sqrt(np.finfo(float).eps) * max(1.0, abs(p[i])) * (1 if p[i] >= 0 else -1)
        expected[:, i] = (problem.evaluate(q)[0] - f0) / (q[i] - p[i])
    scale = np.linalg.norm(expected, axis=0)
    assert np.all(scale[-problem.n_state:] > 0)      # the state's columns are not empty
    np.testing.assert_allclose(jac / scale, expected / scale, rtol=0, atol=1e-6)


@pytest.mark.parametrize("anisotropy", [(800.0, -300.0), (0.0, 0.0)])
@pytest.mark.parametrize("angle", [0.0, 0.7, 2.5])
def test_the_gains_derivative_is_its_central_difference(anisotropy, angle):
    """The closed-form derivative of ``J(a)^-1`` with respect to the inertia's
    parameters (rest inertia's upper triangle, anisotropy, couplings) equals central
    differences of the gain through the model's own constructor, turning and fixed
    appendages both, at ``P = 0`` too (where ``|P|`` has no derivative: 0 both)."""
    from identifiers.physical.scheduled_uncertainty import (
        _gain_derivative,
        _inertia_parameters,
    )

    model = _model(anisotropy)
    theta = _inertia_parameters(model)

    def gain(t):
        rest = np.zeros((3, 3))
        rest[np.triu_indices(3)] = t[:6]
        rest = rest + np.triu(rest, 1).T
        return ScheduledPhysicalModel(rest, t[6:8], model.frequencies_hz, model.damping,
                                      t[8:].reshape(4, 3), TURNING, model.tips,
                                      model.sensor_appendage, model.drive_axis).gain(angle)

    expected = np.empty((9, theta.size))
    for i in range(theta.size):
        h = 1e-4 * max(abs(theta[i]), 1.0)
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        expected[:, i] = (gain(up) - gain(down)).ravel() / (2 * h)
    derivative = _gain_derivative(model, angle)
    assert derivative.shape == (9, 8 + 3 * 4)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(derivative, expected, rtol=0, atol=1e-6 * scale)
    # every parameter moves the gain
    assert np.all(np.abs(derivative).max(axis=0) > 1e-6 * scale)


def test_the_three_vector_cross_product_is_numpys_bit_for_bit():
    for a, b in np.random.default_rng(3).normal(size=(500, 2, 3)) * [[1e-3], [1e4]]:
        np.testing.assert_array_equal(_cross(a, b), np.cross(a, b))


def test_the_fits_unchecked_constructor_builds_the_checked_model():
    # the fit's parametrization fixes shapes and symmetry: _trusted checks only what a
    # parameter vector can break, and builds the model the constructor builds
    checked = _model()
    fields = {f.name: np.array(getattr(checked, f.name)) for f in dataclasses.fields(checked)}
    trusted = ScheduledPhysicalModel._trusted(**fields)
    for name, value in fields.items():
        np.testing.assert_array_equal(getattr(trusted, name), value)
        assert getattr(trusted, name).dtype == value.dtype
        assert not getattr(trusted, name).flags.writeable
    np.testing.assert_array_equal(trusted.zoh(0.4, 0.1)[0], checked.zoh(0.4, 0.1)[0])
    for change, message in (({"rest_inertia": -REST}, "positive definite"),
                            ({"damping": np.array([0.01, np.nan, 0.01, 0.01])}, "finite"),
                            ({"frequencies_hz": np.array([0.07, 0.0, 0.09, 0.12])}, "> 0")):
        with pytest.raises(ValueError, match=message):
            ScheduledPhysicalModel._trusted(**{**fields, **change})


@pytest.mark.parametrize(("change", "message"), [
    ({"rest_inertia": -REST}, "symmetric positive definite"),
    ({"couplings": np.zeros((3, 3))}, r"couplings must have shape \(4, 3\)"),
    ({"turning": (True, False)}, "one flag per mode"),
    ({"sensor_appendage": [0, 1, 2, 4]}, r"indices in \[0, 4\)"),
    ({"drive_axis": (0.0, 2.0, 0.0)}, "unit vector"),
    ({"damping": [0.01, np.nan, 0.01, 0.01]}, "finite"),
])
def test_a_model_that_is_not_physical_is_refused(change, message):
    fields = {"rest_inertia": REST, "drive_anisotropy": (0.0, 0.0),
              "frequencies_hz": [0.07, 0.08, 0.09, 0.12], "damping": [0.01] * 4,
              "couplings": COUPLINGS, "turning": TURNING, "tips": [0.01] * 4,
              "sensor_appendage": [0, 1, 2, 3], "drive_axis": (0.0, 1.0, 0.0), **change}
    with pytest.raises(ValueError, match=message):
        ScheduledPhysicalModel(**fields)


@pytest.mark.parametrize("snr_db", [None, 40.0])
def test_the_fit_recovers_a_model_on_a_turning_drive(snr_db):
    """From 30 s of a drive turning at 1 deg/s: noise-free, the fitted gain J(a)^-1 at
    the last angle is within 0.1 % and the frequencies within 1 %; at 40 dB the
    gain is within 10 % and the truth inside the reported 3-sigma band."""
    rng = np.random.default_rng(1)
    truth = _model()
    u, y, angle = _record(truth, 300, rng)
    if snr_db is not None:
        y = y + rng.normal(size=y.shape) * STANDARD_OUTPUTS.scales() * 10 ** (-snr_db / 20)
    # two of the four starts, for time (the default refines all four)
    fit = fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                              filter_constants=(1.0, 0.5))
    true_gain, gain = truth.gain(angle[-1]), fit.model.gain(angle[-1])
    error = np.linalg.norm(gain - true_gain) / np.linalg.norm(true_gain)
    assert error < (1e-3 if snr_db is None else 1e-1)
    if snr_db is None:
        np.testing.assert_allclose(np.sort(fit.model.frequencies_hz),
                                   [0.07, 0.08, 0.09, 0.12], rtol=1e-2)
    else:
        # the right model class fits down to the noise
        assert 0.8 < fit.cost / fit.noise_floor < 1.25
        # no torque acted besides u: the fitted one is below the BIC penalty (3 ln N,
        # 24 here) and dropped; a threshold of 0 keeps it
        assert fit.disturbance_statistic < chi2.ppf(0.99, 3) < 3 * np.log(y.size)
        np.testing.assert_array_equal(fit.disturbance_torque, np.zeros(3))
        kept = fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                                   filter_constants=(1.0,), disturbance_threshold=0.0)
        assert np.all(kept.disturbance_torque != 0)
        assert kept.disturbance_statistic == pytest.approx(fit.disturbance_statistic,
                                                          rel=0.2)
        covariance = fit.gain_covariance(angle[-1])
        std = np.sqrt(np.diag(covariance))
        assert np.all(np.abs(gain - true_gain).ravel() <= 3 * std + 1e-12)
        # the delta method: symmetric, positive semidefinite, linear in the parameters'
        # covariance
        np.testing.assert_allclose(covariance, covariance.T, rtol=0,
                                   atol=1e-9 * np.abs(covariance).max())
        assert np.linalg.eigvalsh(covariance).min() > -1e-9 * np.abs(covariance).max()
        doubled = dataclasses.replace(fit, inertia_covariance=4.0 * fit.inertia_covariance)
        np.testing.assert_allclose(doubled.gain_covariance(angle[-1]), 4.0 * covariance,
                                   rtol=1e-9)


def test_the_start_gives_the_appendages_the_share_of_inertia_the_record_shows():
    """Solar rotation seed 0, noise-free, the warm-up's 30 s of 1 N m multisines: the
    torque balance's couplings are 1.6-4x too large there, and refined from them the
    fit put two modes on their bounds and the rigid gain 67 % off; with the start's
    couplings scaled to the record (``COUPLING_SCALES``) it is within 1 % and its
    error 30x the floor the second differences read (7,700x before)."""
    u, y, _, truth = env_record("solar_rotation", 0, None)
    u, y = u[:300], y[:300]
    angle = drive_angles(truth, 300)
    fit = fit_scheduled_model(u, y, angle, truth.dt, STANDARD_OUTPUTS, truth.appendage_turns,
                              sensor_appendage=truth.sensor_appendage,
                              drive_axis=truth.drive_axis, filter_constants=(1.0,))
    true_gain = np.linalg.inv(truth.inertia(300 * truth.dt))
    assert relative_gain_error(fit.model.gain(angle[-1]), true_gain) < 1e-2
    assert fit.cost < 100 * fit.noise_floor


def test_the_fit_separates_a_constant_disturbance_torque_from_the_inertia():
    """A constant 0.05 N m per axis acting besides binary torques of 1 N m, noise-free:
    the fit returns it and the gain to 1e-6 (the model class is exact); without the
    disturbance term the same record puts the gain more than 5 % off (15-22 % on
    seeds 7-9)."""
    rng = np.random.default_rng(7)
    truth = _model()
    torque = np.array([0.05, -0.05, 0.05])
    u, y, angle = _record(truth, 300, rng, disturbance=torque)
    true_gain = truth.gain(angle[-1])

    def gain_error(fit):
        gain = fit.model.gain(angle[-1])
        return np.linalg.norm(gain - true_gain) / np.linalg.norm(true_gain)

    fit = fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                              filter_constants=(1.0, 0.5))
    np.testing.assert_allclose(fit.disturbance_torque, torque, rtol=1e-6)
    assert gain_error(fit) < 1e-6
    assert fit.disturbance_statistic > 1e6                 # kept by the test
    assert np.all(np.diag(fit.disturbance_covariance) < 1e-12)
    blind = fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                                filter_constants=(1.0, 0.5), disturbance=False)
    np.testing.assert_array_equal(blind.disturbance_torque, np.zeros(3))
    assert np.isnan(blind.disturbance_statistic)
    assert gain_error(blind) > 5e-2
    assert blind.cost > 1e6 * fit.cost


def test_the_noise_floor_and_the_segments():
    """White noise of 0.01 nominal levels on a slow signal reads as a weighted floor of
    1e-4 (the fit's stopping rule); blocks keep the angle within their resolution."""
    rng = np.random.default_rng(5)
    t = 0.1 * np.arange(3000)[:, None]
    scales = STANDARD_OUTPUTS.scales()
    slow = np.sin(2 * np.pi * 0.08 * t + np.arange(10)) * scales
    y = slow + rng.normal(size=slow.shape) * 0.01 * scales
    assert noise_floor(y, 1.0 / scales) == pytest.approx(1e-4, rel=0.1)
    assert noise_floor(slow, 1.0 / scales) < 1e-5
    angle = np.deg2rad(np.linspace(0.0, 2.0, 50))
    blocks = segments(angle, np.deg2rad(0.25))
    assert blocks[0][0] == 0 and blocks[-1][1] == 50
    assert all(a[1] == b[0] for a, b in itertools.pairwise(blocks))
    assert all(np.ptp(angle[s0:s1]) <= np.deg2rad(0.25) for s0, s1 in blocks)
    assert segments(np.zeros(20)) == [(0, 20)]


def test_the_fit_refuses_records_it_cannot_use():
    u, y, angle = np.zeros((50, 3)), np.zeros((50, 10)), np.zeros(50)
    with pytest.raises(ValueError, match=r"\(T,\)"):
        fit_scheduled_model(u, y, angle[:10], 0.1, STANDARD_OUTPUTS, TURNING)
    with pytest.raises(ValueError, match="each appendage at least one sensor"):
        fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                            sensor_appendage=[0, 0, 1, 2])
    with pytest.raises(ValueError, match="finite"):
        fit_scheduled_model(u, y, np.full(50, np.nan), 0.1, STANDARD_OUTPUTS, TURNING)
    with pytest.raises(ValueError, match=r"disturbance_threshold must be >= 0 or None"):
        fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                            disturbance_threshold=np.nan)
    with pytest.raises(ValueError, match=r"initial must be a model of 4 appendages, its "
                                         r"\(14,\) state and optionally a finite \(3,\)"):
        fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                            initial=(_model(), np.zeros(10)))
    with pytest.raises(ValueError, match=r"finite \(3,\) torque, got 4, \(14,\) and \(2,\)"):
        fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                            initial=(_model(), np.zeros(14), np.zeros(2)))
    with pytest.raises(ValueError, match=r"got 4, \(14,\) and \(3,\) \(4 items\)"):
        fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                            initial=(_model(), np.zeros(14), np.zeros(3), np.zeros(3)))


def test_the_identifiers_filter_propagates_the_fitted_disturbance():
    """Noise-free, 0.05 N m acting besides the torques: the identifier's fit holds the
    torque and its filter, which propagates ``u + d``, predicts the rigid states 6 s
    after the fit to 1e-6 of their size (8e-10; 7e-5 with the fit's torque off)."""
    truth = _model()
    torque = np.array([0.05, -0.05, 0.05])
    u, y, angle = _record(truth, 261, np.random.default_rng(2), disturbance=torque)
    states = simulate_scheduled(truth, u + torque, angle, 0.1, np.zeros(truth.order))
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=200,
                                        fit_options={"filter_constants": (1.0,)})
    for k in range(260):
        ident.set_schedule(angle[k])
        ident.update(u[k], y[k])
    np.testing.assert_allclose(ident.held_fit.disturbance_torque, torque, rtol=1e-4)
    rigid = states[260, :6]
    np.testing.assert_allclose(ident.state[:6], rigid, rtol=0, atol=1e-6 * np.abs(rigid).max())


def test_the_identifier_follows_the_drive_after_its_fit():
    rng = np.random.default_rng(2)
    truth = _model()
    u, y, angle = _record(truth, 260, rng)
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=200,
                                        fit_options={"filter_constants": (1.0,)})
    for k in range(199):
        ident.set_schedule(angle[k])
        ident.update(u[k], y[k])
    assert ident.model is None and ident.rigid_gain is None
    ident.set_schedule(angle[199])
    ident.update(u[199], y[199])
    first = ident.model
    assert first is not None and first.A.shape == (14, 14)
    for k in range(200, 260):
        ident.set_schedule(angle[k])
        ident.update(u[k], y[k])
    # the drive moved 6 deg: the model followed it, and it is the truth's at that angle
    expected = truth.discrete(angle[-1], 0.1, STANDARD_OUTPUTS)
    assert not np.allclose(ident.model.A, first.A)
    np.testing.assert_allclose(ident.model.A[3:6, :6], expected.A[3:6, :6], atol=1e-4)
    gain = ident.rigid_gain.gain
    true_gain = truth.gain(angle[-1])
    assert np.linalg.norm(gain - true_gain) / np.linalg.norm(true_gain) < 1e-3
    predicted = ident.model.C @ ident.state
    assert np.all(np.abs(predicted - y[259]) < 1e-2 * STANDARD_OUTPUTS.scales())
    copy = pickle.loads(pickle.dumps(ident))
    np.testing.assert_array_equal(copy.state, ident.state)
    assert ident.health.healthy
    # the exported model holds until the drive has moved EXPORT_RESOLUTION; the gain's
    # estimate follows it between exports: the fit's J(a)^-1 at the latest angle, with
    # the covariance at the exported model's
    far = angle[-1] + 2 * EXPORT_RESOLUTION
    ident.set_schedule(far)
    ident.update(u[259], y[259])
    exported = ident.model.A
    near = far + 0.5 * EXPORT_RESOLUTION
    ident.set_schedule(near)
    ident.update(u[259], y[259])
    np.testing.assert_array_equal(ident.model.A, exported)
    np.testing.assert_array_equal(ident.rigid_gain.gain, ident.held_fit.model.gain(near))
    np.testing.assert_allclose(ident.rigid_gain.covariance, ident.held_fit.gain_covariance(far),
                               rtol=1e-9, atol=0)
    assert not np.array_equal(ident.held_fit.model.gain(near), ident.held_fit.model.gain(far))


def test_fit_takes_the_drive_schedule_and_is_the_update_loop():
    """``fit(U, Y, schedule=angles)`` sets each sample's angle before its update: the same
    models and states as the loop; without a schedule the angle is held."""
    rng = np.random.default_rng(2)
    u, y, angle = _record(_model(), 230, rng)
    options = {"turning": TURNING, "warmup": 200, "fit_options": {"filter_constants": (1.0,)}}
    seq = ScheduledPhysicalIdentifier(**options).fit(u, y, schedule=angle)
    loop = ScheduledPhysicalIdentifier(**options)
    for k in range(230):
        loop.set_schedule(angle[k])
        loop.update(u[k], y[k])
    assert seq.valid[199:].all() and not seq.valid[:199].any()
    np.testing.assert_array_equal(seq[229].A, loop.model.A)
    np.testing.assert_array_equal(seq.states[229], loop.state)
    held = ScheduledPhysicalIdentifier(**options)
    held.set_schedule(0.3)
    unscheduled = held.fit(u, y)
    assert held.angle == 0.3 and unscheduled.valid[229]
    assert not np.allclose(unscheduled[229].A, seq[229].A)   # the drive turned 23 deg
    for bad in (angle[:5], np.where(np.arange(230) == 7, np.nan, angle), angle[:, None]):
        with pytest.raises(ValueError, match="one finite drive angle"):
            ScheduledPhysicalIdentifier(**options).fit(u, y, schedule=bad)


def test_the_identifier_refuses_what_it_cannot_identify():
    with pytest.raises(ValueError, match="needs attitude, rate and deflection"):
        ScheduledPhysicalIdentifier(OutputLayout.of(("attitude", "rate"), 0))
    with pytest.raises(ValueError, match="each appendage at least one sensor"):
        ScheduledPhysicalIdentifier(turning=(True, False))
    with pytest.raises(ValueError, match="drive_axis"):
        ScheduledPhysicalIdentifier(drive_axis=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="fit_options may hold"):
        ScheduledPhysicalIdentifier(fit_options={"tolerance": 1.0})
    for amplitude in (0.0, -0.5, np.inf):
        with pytest.raises(ValueError, match="warmup_amplitude must be positive"):
            ScheduledPhysicalIdentifier(warmup_amplitude=amplitude)
    ident = ScheduledPhysicalIdentifier()
    with pytest.raises(ValueError, match="finite"):
        ident.set_schedule(np.nan)
    with pytest.raises(ValueError, match="3 body torques"):
        ident.update(np.zeros(2), np.zeros(10))


def test_a_failed_fit_is_retried_after_half_a_warmup_not_every_sample(monkeypatch):
    import identifiers.physical.scheduled_identifier as module

    calls = []

    def failing(*args, **kwargs):
        calls.append(len(args[0]))
        raise np.linalg.LinAlgError("no usable start")

    monkeypatch.setattr(module, "fit_scheduled_model", failing)
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=40)
    rng = np.random.default_rng(6)
    for _ in range(79):
        ident.update(rng.normal(size=3), rng.normal(size=10) * STANDARD_OUTPUTS.scales())
    assert calls == [40, 60]                      # at the warm-up, then 20 samples later
    assert ident.model is None and ident.held_fit is None


def test_the_record_doubles_and_each_refit_starts_from_the_held_model(monkeypatch):
    """With ``accumulate`` (the default) the fit is redone when as many samples have come
    as it used, on at most ``max_record`` samples, from the held model and its state at
    the record's first sample; without it the warm-up's fit is held."""
    import identifiers.physical.scheduled_identifier as module
    from identifiers import ScheduledFit

    truth = _model()
    calls = []

    starts = []

    def fake(u, y, angle, *args, initial=None, **kwargs):
        calls.append((len(u), None if initial is None else bool(np.isfinite(initial[1]).all())))
        starts.append(kwargs.get("filter_constants", "default"))
        return ScheduledFit(truth, np.zeros(truth.order), np.eye(20), 1.0, 1.0)

    monkeypatch.setattr(module, "fit_scheduled_model", fake)
    rng = np.random.default_rng(7)
    data = [(rng.normal(size=3), rng.normal(size=10) * STANDARD_OUTPUTS.scales())
            for _ in range(400)]
    for accumulate, expected in ((True, [(40, None), (80, True)] + [(120, True)] * 3),
                                 (False, [(40, None)])):
        calls.clear()
        ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=40, max_record=120,
                                            accumulate=accumulate, screen_refits=False)
        for k, (u, y) in enumerate(data):
            ident.set_schedule(0.01 * k)
            ident.update(u, y)
        # at 40 samples, then 80 (the record doubled), 160, 280 and 400 (every max_record)
        assert calls == expected
        assert ident.n_refits == len(expected) - 1
    # the first fit refines every equation-error start, an accumulating refit the held
    # model alone unless refit_restarts asks for them too
    assert starts[:5] == ["default"] + [()] * 4        # the accumulating run, then the held
    starts.clear()
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=40, max_record=120,
                                        refit_restarts=True, screen_refits=False,
                                        fit_options={"filter_constants": (1.0, 2.0)})
    for k, (u, y) in enumerate(data[:100]):
        ident.set_schedule(0.01 * k)
        ident.update(u, y)
    assert starts == [(1.0, 2.0)] * 2 and not ident.accumulating_refit
    # a refit that knows the gain less well (here: a four times larger covariance on
    # the third fit) is kept out, the held fit and its filter kept
    fits = []

    def widening(u, y, angle, *args, initial=None, **kwargs):
        fits.append(ScheduledFit(truth, np.zeros(truth.order),
                                 np.eye(20) * (4.0 if len(fits) == 2 else 1.0), 1.0, 1.0))
        return fits[-1]

    monkeypatch.setattr(module, "fit_scheduled_model", widening)
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=40, max_record=120,
                                        screen_refits=False)
    for k, (u, y) in enumerate(data[:170]):
        ident.set_schedule(0.01 * k)
        ident.update(u, y)
        if k == 158:
            held_filter = ident._kf
    assert len(fits) == 3 and ident.held_fit is fits[1]
    assert ident.n_refits == 1 and ident.n_refits_kept_out == 1
    assert ident._kf is held_filter                # updated on, not replaced
    with pytest.raises(ValueError, match="max_record must be at least warmup"):
        ScheduledPhysicalIdentifier(warmup=300, max_record=200)
    with pytest.raises(TypeError, match="accumulate must be a bool"):
        ScheduledPhysicalIdentifier(accumulate="yes")
    with pytest.raises(TypeError, match="refit_restarts must be a bool"):
        ScheduledPhysicalIdentifier(refit_restarts=1)
    with pytest.raises(TypeError, match="screen_refits must be a bool"):
        ScheduledPhysicalIdentifier(screen_refits="no")


def test_the_information_a_record_holds_at_a_fits_own_parameters_is_its_covariance():
    """Judged at a fit's own parameters and initial state on its own record, the
    predicted gain covariance is the fit's with the record's noise floor for the
    residual variance (the Jacobian's forward differences at the re-packed parameters
    agree to rounding, which the ill-conditioned ``(J^T J)^-1`` amplifies to about
    1e-3)."""
    from identifiers.physical.scheduled_information import predicted_gain_covariance

    truth = _model()
    rng = np.random.default_rng(11)
    u, y, angle = _record(truth, 200, rng)
    y = y + rng.normal(size=y.shape) * 1e-2 * STANDARD_OUTPUTS.scales()
    fit = fit_scheduled_model(u, y, angle, 0.1, STANDARD_OUTPUTS, TURNING,
                              filter_constants=(1.0,))
    np.testing.assert_array_equal(fit.disturbance_torque, np.zeros(3))
    predicted = predicted_gain_covariance(fit, u, y, angle, 0.1, STANDARD_OUTPUTS,
                                          fit.initial_state)
    n_residuals, n_parameters = y.size, 8 + 5 * 4 + truth.order
    residual_variance = fit.cost * n_residuals / (n_residuals - n_parameters)
    expected = fit.gain_covariance(angle[-1]) * fit.noise_floor / residual_variance
    assert 0.8 < fit.noise_floor / residual_variance < 1.25
    np.testing.assert_allclose(predicted, expected, rtol=0,
                               atol=1e-2 * np.abs(expected).max())
    with pytest.raises(ValueError, match="initial_state must have shapes"):
        predicted_gain_covariance(fit, u, y, angle, 0.1, STANDARD_OUTPUTS, np.zeros(3))
    with pytest.raises(ValueError, match="must be finite"):
        predicted_gain_covariance(fit, u, y, angle, 0.1, STANDARD_OUTPUTS,
                                  np.full(truth.order, np.nan))


@pytest.mark.parametrize("held_variance, refits, skipped", [(1e-12, 0, 9), (1e6, 4, 0)])
def test_a_refit_the_record_cannot_pay_for_is_skipped(monkeypatch, held_variance, refits,
                                                      skipped):
    """``screen_refits``: a held fit whose gain is known far better than any record of
    this length can tell is not refitted at all (``n_refits_skipped``); one known far
    worse is refitted every time (at 80, 160, 280 and 400 samples). A skipped refit
    leaves what a refit the guard keeps out leaves: the next is tried as many samples
    later as the held fit used (every 40 here)."""
    import identifiers.physical.scheduled_identifier as module
    from identifiers import ScheduledFit

    truth = _model()
    calls = []

    def fake(u, y, angle, *args, initial=None, **kwargs):
        calls.append(len(u))
        return ScheduledFit(truth, np.zeros(truth.order), np.eye(20) * held_variance, 1.0,
                            1.0)

    monkeypatch.setattr(module, "fit_scheduled_model", fake)
    rng = np.random.default_rng(12)
    u, y, angle = _record(truth, 400, rng)
    y = y + rng.normal(size=y.shape) * 1e-2 * STANDARD_OUTPUTS.scales()
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=40, max_record=120)
    for k in range(400):
        ident.set_schedule(angle[k])
        ident.update(u[k], y[k])
    assert calls[0] == 40 and len(calls) == 1 + refits
    assert ident.n_refits == refits and ident.n_refits_kept_out == 0
    assert ident.n_refits_skipped == skipped


def test_a_change_the_innovations_show_is_reported_and_refitted():
    """Rest inertia doubled at 26 s under 1 N m excitation: the innovation test fires
    within 15 s, the record after it is fitted from the held model, and the new gain
    is closer to the changed plant's than the held one (3 seeds measured: 0.06-0.36
    against 0.76-1.00 relative error)."""
    rng = np.random.default_rng(2)
    before = _model()
    after = dataclasses.replace(before, rest_inertia=2.0 * REST)
    steps, change = 500, 260
    u = np.repeat(rng.choice([-1.0, 1.0], size=(steps // 10 + 1, 3)), 10, axis=0)[:steps]
    angle = 0.3 + np.deg2rad(1.0) * 0.1 * np.arange(steps)
    x1 = simulate_scheduled(before, u[:change + 1], angle[:change + 1], 0.1,
                            np.zeros(before.order))
    x2 = simulate_scheduled(after, u[change:], angle[change:], 0.1, x1[change])
    y = np.vstack([x1[:change], x2]) @ before.output_matrix(STANDARD_OUTPUTS).T
    y = y + 1e-3 * STANDARD_OUTPUTS.scales() * rng.normal(size=y.shape)
    options = {"filter_constants": (1.0,), "start_nfev": 20, "max_nfev": 30}
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=100, refit_on_change=True,
                                        accumulate=False, fit_options=options)
    assert ScheduledPhysicalIdentifier().refit_on_change       # the default
    first = None
    for k in range(steps):
        ident.set_schedule(angle[k])
        ident.update(u[k], y[k])
        if k == change - 1:
            assert ident.events == [] and not ident.refitting     # no false alarm
            first = ident.held_fit
    assert len(ident.events) >= 1 and ident.n_refits == 1
    assert change <= ident.events[0].sample <= change + 150
    truth = after.gain(angle[-1])

    def error(gain):
        return np.linalg.norm(gain - truth) / np.linalg.norm(truth)

    assert ident.held_fit is not first and ident.events[0].confirmed is True
    assert ident.n_alarms_unconfirmed == 0
    assert error(ident.rigid_gain.gain) < 0.6 * error(first.model.gain(angle[-1]))
    with pytest.raises(TypeError, match="refit_on_change"):
        ScheduledPhysicalIdentifier(refit_on_change="yes")


class FiresOnce:
    """A stand-in change test that fires at the 50th innovation it is fed."""

    def __init__(self, **_):
        self.k = 0

    def update(self, innovation, covariance):
        self.k += 1
        return ChangeEvent(sample=self.k - 1, onset=self.k - 1, time=0.0,
                           statistic=99.0) if self.k == 50 else None


@pytest.mark.parametrize("accumulate", [True, False])
def test_an_alarm_the_data_after_it_do_not_confirm_keeps_the_record(monkeypatch, accumulate):
    """A change test that fires (a stand-in, 5 s after the fit) on a plant that did not
    change: the refit on the 20 s after it explains them no better than the no-change
    model (the held model refined on the whole record; without ``accumulate``, the held
    model), so the alarm is reported unconfirmed and the record is kept: the held model
    refined on all of it flies (an accumulating refit), or the held model and its
    filter as they were."""
    monkeypatch.setattr(warmup_fit, "InnovationCUSUM", FiresOnce)
    rng = np.random.default_rng(3)
    model, warmup, steps = _model(), 200, 500
    u = np.repeat(rng.choice([-1.0, 1.0], size=(steps // 10 + 1, 3)), 10, axis=0)[:steps]
    angle = 0.3 + np.deg2rad(1.0) * 0.1 * np.arange(steps)
    y = simulate_scheduled(model, u, angle, 0.1, np.zeros(model.order)) \
        @ model.output_matrix(STANDARD_OUTPUTS).T
    y = y + 1e-3 * STANDARD_OUTPUTS.scales() * rng.normal(size=y.shape)
    options = {"filter_constants": (1.0,), "start_nfev": 20, "max_nfev": 30}
    ident = ScheduledPhysicalIdentifier(turning=TURNING, warmup=warmup, refit_on_change=True,
                                        accumulate=accumulate, max_record=1000,
                                        fit_options=options)
    held = None
    for k in range(steps):
        ident.set_schedule(angle[k])
        ident.update(u[k], y[k])
        if k == warmup - 1:
            held = ident.held_fit
            assert held is not None
        if k == warmup + 49:
            assert ident.refitting and len(ident.events) == 1
            kf = ident._kf
        if k > warmup + 49 and not ident.refitting:
            break
    assert k == warmup + 49 + warmup - 1           # the refit's record, then the verdict
    assert ident.n_alarms_unconfirmed == 1
    assert [e.confirmed for e in ident.events] == [False]
    if accumulate:
        # every sample kept, the alarm's included, and fitted from the held model
        assert len(ident._history) == k + 1 and ident.n_refits == 1
        assert ident.held_fit is not held
        assert (ident._fit_origin, ident._fit_length) == (0, k + 1)
    else:
        # the held model's filter ran on through the alarm's record
        assert ident.held_fit is held and ident.n_refits == 0
        assert ident._kf is kf and np.all(np.isfinite(kf.x))


@pytest.mark.slow
def test_on_a_turning_paddle_the_scheduled_fit_tracks_the_mode_at_every_noise_level(
        load_benchmark):
    """The adaptive LQG's identifier on the tracking benchmark's paddle-rotation records
    (seeds 0-2): the mode the paddles move within a tenth of the true model frozen at
    100 s over the benchmark's window (medians of each second's error from 100 s; the
    frozen model's: 1.46 %), within a third of it at 175 and 249 s, and the 10 s
    deflection predictions from 150 s no worse noise-free or at 60 dB than at 40 dB.
    (The yardstick is the frozen model's error over the window, not at the instant: at
    249 s another of its modes sits 0.25 % from the moved one.)"""
    bench = load_benchmark("bench_tracking")
    deflection = STANDARD_OUTPUTS.slice("deflection")
    vaf = {}
    for snr in (40.0, 60.0, None):
        vafs = []
        for seed in range(3):
            u, y, y0, truth = env_record("paddle_rotation", seed, snr)
            ident = bench.make_identifier("scheduled", truth)
            seq = ident.fit(u, y, schedule=drive_angles(truth, len(u)))
            vafs.append(prediction_vaf(y0, h_step_predictions(seq, u, (100,)), 1500)[100]
                        [deflection].mean())
            frozen_modes = truth.modal_residues(99.9)[0]
            errors, frozen = {}, []
            for t in np.arange(100.0, 250.0, 1.0):
                moved = truth.modal_residues(t)[0][3]           # the benchmark's mode
                f_id = seq[round(t / truth.dt)].modal(unique=False)[0]
                errors[t] = np.min(np.abs(f_id / moved - 1.0))
                frozen.append(np.min(np.abs(frozen_modes / moved - 1.0)))
            yardstick = np.median(frozen)
            assert np.median(list(errors.values())) <= yardstick / 10, (snr, seed)
            for t in (175.0, 249.0):
                assert errors[t] <= yardstick / 3, (snr, seed, t, errors[t])
        vaf[snr] = np.median(vafs)
    assert vaf[None] >= vaf[40.0] - 0.1 and vaf[60.0] >= vaf[40.0] - 0.1, vaf
    assert vaf[40.0] > 95.0, vaf


@pytest.mark.slow
def test_through_two_dockings_the_scheduled_fit_tracks_the_mode(load_benchmark):
    """The tracking benchmark's docking records (seeds 0-2, at 40 dB and noise-free): the
    confirmed change test refits after the dockings, so over the benchmark's windows
    (from 20 s after each docking) the median seed's mode error is within two thirds of
    the true model frozen before each docking, and the rigid gain within 10 %; at least
    one docking is confirmed on every record."""
    bench = load_benchmark("bench_tracking")
    for snr in (40.0, None):
        runs = [bench.score("docking", seed, snr, 1.0, identifier="scheduled")
                for seed in range(3)]
        mode = np.median([r["mode_error_pct"] for r in runs])
        frozen = np.median([r["frozen_mode_error_pct"] for r in runs])
        assert mode <= 2 / 3 * frozen, (snr, [r["mode_error_pct"] for r in runs])
        assert np.median([r["gain_error_pct"] for r in runs]) < 10.0, snr
        assert all(any(100.0 < t < 220.0 for t in r["change_events"]) for r in runs), snr
