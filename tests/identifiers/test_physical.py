"""The physical model (closed forms), its output-error fit and the identifier around it."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from identifiers import (
    PhysicalFitIdentifier,
    PhysicalModel,
    StateSpaceModel,
    fit_physical_model,
)
from identifiers.physical.physical_model import simulate
from spacecraft_conventions import STANDARD_OUTPUTS, OutputLayout

#: Starting frequencies of the tests' fits (Hz): a coarse grid, for time.
GRID = (0.07, 0.09, 0.12)
GAIN = np.array([[4.0e-5, 3.0e-6, 0.0], [3.0e-6, 3.0e-5, 1.0e-6], [0.0, 1.0e-6, 5.0e-5]])


def _model(rng: np.random.Generator) -> PhysicalModel:
    """Two modes of comparable strength (0.08 and 0.11 Hz) and random tip rows."""
    couplings = np.array([[3e-3, 1e-3, 0.0], [0.0, 2e-3, 3e-3]])
    return PhysicalModel(GAIN, [0.08, 0.11], [0.01, 0.01], couplings,
                         rng.normal(size=(4, 2)) * 0.1)


def _record(model: PhysicalModel, steps: int, rng: np.random.Generator):
    """Random binary torques of 1 N m held 1 s, and the noise-free outputs (10 columns)."""
    u = np.repeat(rng.choice([-1.0, 1.0], size=(steps // 10 + 1, 3)), 10, axis=0)[:steps]
    attitude, rate, q = simulate(model, u, 0.1)
    return u, np.column_stack([attitude, rate, q @ model.tips.T])


def test_simulation_is_the_zero_order_hold_model():
    rng = np.random.default_rng(0)
    model = _model(rng)
    u = rng.normal(size=(300, 3))
    x0 = rng.normal(size=10) * 1e-3
    attitude, rate, q = simulate(model, u, 0.1, x0)
    d = model.discrete(0.1, STANDARD_OUTPUTS)
    assert isinstance(d, StateSpaceModel) and d.A.shape == (10, 10)
    np.testing.assert_allclose(d.A[0:3, 3:6], 0.1 * np.eye(3), atol=1e-15)
    x, out = x0.copy(), []
    for k in range(300):
        out.append(d.C @ x)
        x = d.A @ x + d.B @ u[k]
    out = np.array(out)
    np.testing.assert_allclose(out[:, 0:3], attitude, rtol=0, atol=1e-12 * np.abs(attitude).max())
    np.testing.assert_allclose(out[:, 3:6], rate, rtol=0, atol=1e-12 * np.abs(rate).max())
    np.testing.assert_allclose(out[:, 6:], q @ model.tips.T, rtol=0, atol=1e-15)


def test_the_torque_to_rate_response_is_passive_and_tends_to_the_rigid_body():
    model = _model(np.random.default_rng(1))
    response = model.rate_response(np.geomspace(1e-3, 2.0, 400))
    hermitian = [np.linalg.eigvalsh(0.5 * (h + h.conj().T)).min() for h in response]
    assert min(hermitian) >= -1e-12 * np.abs(response).max()
    low = model.rate_response([1e-6])[0]
    np.testing.assert_allclose(low * 2j * np.pi * 1e-6, GAIN, rtol=0, atol=1e-6 * GAIN.max())


@pytest.mark.parametrize(("change", "message"), [
    ({"gain": -GAIN}, "positive definite"),
    ({"gain": GAIN + np.triu(np.full((3, 3), 1e-6), 1)}, "symmetric"),
    ({"couplings": np.zeros((3, 3))}, r"couplings must have shape \(2, 3\)"),
    ({"tips": np.zeros((4, 3))}, r"tips must have shape \(n_tip, 2\)"),
    ({"frequencies_hz": [0.08, -0.1]}, "frequencies_hz must be > 0"),
])
def test_a_model_that_is_not_physical_is_refused(change, message):
    fields = {"gain": GAIN, "frequencies_hz": [0.08, 0.1], "damping": [0.01, 0.01],
              "couplings": np.ones((2, 3)) * 1e-3, "tips": np.ones((4, 2)), **change}
    with pytest.raises(ValueError, match=message):
        PhysicalModel(**fields)


def test_the_fit_recovers_a_noise_free_model():
    rng = np.random.default_rng(2)
    truth = _model(rng)
    u, y = _record(truth, 300, rng)
    fit = fit_physical_model(u, y, 0.1, STANDARD_OUTPUTS, n_modes=2, grid_hz=GRID)
    assert np.linalg.norm(fit.model.gain - GAIN) / np.linalg.norm(GAIN) < 1e-3
    np.testing.assert_allclose(np.sort(fit.model.frequencies_hz), [0.08, 0.11], rtol=1e-3)
    assert fit.cost < 1e-8
    assert fit.gain_covariance.shape == (9, 9)


def test_the_fitted_gain_band_covers_the_truth_under_noise():
    rng = np.random.default_rng(3)
    truth = _model(rng)
    u, y = _record(truth, 300, rng)
    y = y + rng.normal(size=y.shape) * STANDARD_OUTPUTS.scales() * 1e-2      # 40 dB
    fit = fit_physical_model(u, y, 0.1, STANDARD_OUTPUTS, n_modes=2, grid_hz=GRID)
    error = (fit.model.gain - GAIN).ravel()
    std = np.sqrt(np.diag(fit.gain_covariance))
    assert np.all(np.abs(error) <= 3 * std + 1e-12)
    assert np.all(std < 0.05 * np.abs(GAIN).max())


def test_the_identifier_fits_at_the_end_of_its_warmup_and_holds_the_model():
    rng = np.random.default_rng(4)
    truth = _model(rng)
    u, y = _record(truth, 260, rng)
    ident = PhysicalFitIdentifier(n_modes=2, warmup=200)
    for k in range(199):
        ident.update(u[k], y[k])
    assert ident.model is None and ident.rigid_gain is None and ident.state is None
    ident.update(u[199], y[199])
    model = ident.model
    assert model is not None and model.A.shape == (10, 10) and model.C.shape == (10, 10)
    gain = ident.rigid_gain
    assert np.linalg.norm(gain.gain - GAIN) / np.linalg.norm(GAIN) < 1e-3
    for k in range(200, 259):
        ident.update(u[k], y[k])
    np.testing.assert_array_equal(ident.model.A, model.A)        # held
    # its filter follows the record: the one-step prediction of the next (noise-free)
    # outputs is right to a thousandth of their nominal levels
    predicted = ident.model.C @ ident.state
    assert np.all(np.abs(predicted - y[259]) < 1e-3 * STANDARD_OUTPUTS.scales())
    copy = pickle.loads(pickle.dumps(ident))
    np.testing.assert_array_equal(copy.state, ident.state)
    assert ident.health.healthy


def test_fit_is_the_update_loop():
    """``fit(U, Y)``, the streaming API's batch call, was shadowed by the attribute that
    holds the fit (``held_fit`` since): it must run and equal ``update`` in a loop."""
    rng = np.random.default_rng(4)
    u, y = _record(_model(rng), 230, rng)
    batch = PhysicalFitIdentifier(n_modes=2, warmup=200)
    seq = batch.fit(u, y)
    loop = PhysicalFitIdentifier(n_modes=2, warmup=200)
    for k in range(230):
        loop.update(u[k], y[k])
    assert not seq.valid[198] and seq.valid[199:].all()
    np.testing.assert_array_equal(seq[229].A, loop.model.A)
    np.testing.assert_array_equal(seq.states[229], loop.state)
    assert batch.held_fit is not None


def test_the_identifier_refuses_what_it_cannot_identify():
    with pytest.raises(ValueError, match=r"sensor groups \['rate'\]"):
        PhysicalFitIdentifier(OutputLayout((("attitude", 3),)))
    with pytest.raises(ValueError, match="n_modes must be >= 1"):
        PhysicalFitIdentifier(n_modes=0)
    ident = PhysicalFitIdentifier()
    with pytest.raises(ValueError, match="3 body torques"):
        ident.update(np.zeros(2), np.zeros(10))
    with pytest.raises(ValueError, match="y must have 10 entries"):
        PhysicalFitIdentifier().update(np.zeros(3), np.zeros(7))
