"""A recursive PBSID with an exact rigid block: exact where physics is exact, a
calibrated gain on the spacecraft, a flexible part that predicts, the streaming API."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from identifiers import (
    IdentifierHealthWarning,
    RigidGainEstimate,
    StructuredRPBSID,
    h_step_predictions,
    persistence_predictions,
    prediction_vaf,
    relative_gain_error,
    rigid_body_gain,
)
from spacecraft_conventions import STANDARD_OUTPUTS, OutputLayout
from spacecraft_env import FlexibleSpacecraftModel
from spacecraft_lab.identification import identification_records

RIGID = OutputLayout.of(("attitude", "rate"), n_sensors=0)
INERTIA = np.array([[30_000.0, 500.0, 0.0], [500.0, 20_000.0, 0.0], [0.0, 0.0, 22_000.0]])


def _spacecraft(scenario: str, n_samples: int = 2500):
    """Seed 0's identification record of ``scenario`` at 40 dB: ``(truth, u, y)``."""
    truth = FlexibleSpacecraftModel(scenario=scenario)
    record = identification_records(truth, 0, n_samples)
    return truth, record.u, record.y


def test_the_rigid_block_is_exact_on_a_noise_free_rigid_body(rigid_body_record):
    """From a non-zero start (attitude and rate)."""
    u, y = rigid_body_record(INERTIA, psi0=[0.01, -0.02, 0.005], omega0=[1e-4, 0.0, -2e-4])
    ident = StructuredRPBSID(RIGID, n=8, detect_changes=False)
    seq = ident.fit(u, y)
    model = seq[len(seq) - 1]
    g = np.linalg.inv(INERTIA)
    assert relative_gain_error(ident.rigid_gain.gain, g) < 1e-3
    # the exported model (refreshed every 10 samples) carries that gain in exact ZOH
    # double integrators
    np.testing.assert_allclose(np.linalg.eigvals(model.A[:6, :6]), 1.0, atol=1e-12)
    assert relative_gain_error(rigid_body_gain(model, slice(3, 6)), g) < 1e-3


@pytest.mark.parametrize("scenario, tolerance", [("constant", 0.02), ("docking", 0.1)])
def test_on_the_spacecraft_the_gain_is_found_under_the_flexible_modes(scenario, tolerance):
    """With the attitude and rate levels in the predictor's window the regression
    absorbs any gain error into an integrator of its own (measured: 34-47 % on the
    constant plant, noise-free); without them, and with the docking detected, the
    gain is within a few per cent (0.4 % constant, 4.8 % docking at 250 s)."""
    truth, u, y = _spacecraft(scenario)
    ident = StructuredRPBSID(truth.output_layout)
    ident.fit(u, y)
    truth_gain = np.linalg.inv(truth.inertia(250.0))
    estimate = ident.rigid_gain
    assert isinstance(estimate, RigidGainEstimate)
    assert relative_gain_error(estimate.gain, truth_gain) < tolerance
    alarms = np.array([event.time for event in ident.events])
    if scenario == "docking":          # modules dock at 100 s and 180 s
        assert alarms.min() >= 100.0 and np.any(alarms <= 110.0)
    else:
        assert alarms.size == 0
    assert ident.model.A.shape == (ident.order, ident.order) == (22, 22)


def test_the_model_predicts_attitude_and_rates_10_s_ahead_better_than_persistence():
    """The rigid block carries these; the deflections' 10 s prediction is about
    persistence's on this short record (docs/results/identification.md)."""
    truth, u, y = _spacecraft("constant", n_samples=1500)
    ident = StructuredRPBSID(truth.output_layout)
    seq = ident.fit(u, y)
    model = prediction_vaf(y, h_step_predictions(seq, u, (100,)), 1000)[100]
    persistence = prediction_vaf(y, persistence_predictions(y, (100,)), 1000)[100]
    for group in ("attitude", "rate"):
        rows = truth.output_layout.slice(group)
        assert np.median(model[rows]) > np.median(persistence[rows]) + 10, group


def test_the_flexible_part_predicts_the_deflections_where_the_sign_step_cannot():
    """The default flexible part, a classical RPBSID on the tip deflections, predicts
    them 10 s ahead on a constant plant at 40 dB (96.6 %, against the noise-free
    outputs); the paper's improved RPBSID inside the regression exports no resonance
    there (0 %); persistence -29.5 %."""
    truth = FlexibleSpacecraftModel(scenario="constant")
    record = identification_records(truth, 0, 2500)
    rows = truth.output_layout.slice("deflection")
    vaf = {}
    for flexible in ("classical", "improved"):
        ident = StructuredRPBSID(truth.output_layout, flexible=flexible)
        seq = ident.fit(record.u, record.y)
        scores = prediction_vaf(record.y_clean, h_step_predictions(seq, record.u, (100,)), 2000)
        vaf[flexible] = np.median(scores[100][rows])
    assert StructuredRPBSID(truth.output_layout).flexible == "classical"
    assert StructuredRPBSID(RIGID, n=8).flexible == "improved"     # no deflections
    assert vaf["classical"] > 90.0 and vaf["improved"] < 50.0, vaf


def test_the_deflection_prediction_does_not_fall_as_the_noise_falls():
    """Paddle rotation, seed 0: 10 s deflection VAF 66.7 % at 40 dB and 85.0 %
    noise-free (the modal identifier's falls from 38.6 to -9.8 % over ten and four
    seeds, docs/results/identification.md). A result that gets worse as the data get
    cleaner encodes a tuning to the noise."""
    truth = FlexibleSpacecraftModel(scenario="paddle_rotation")
    rows = truth.output_layout.slice("deflection")
    vaf = {}
    for snr_db in (40.0, None):
        record = identification_records(truth, 0, 2500, snr_db)
        seq = StructuredRPBSID(truth.output_layout).fit(record.u, record.y)
        scores = prediction_vaf(record.y_clean, h_step_predictions(seq, record.u, (100,)), 1500)
        vaf[snr_db] = np.mean(scores[100][rows])          # the results tables' reading
    assert vaf[None] >= vaf[40.0] > 50.0, vaf


def test_restart_keeps_what_was_learnt():
    truth, u, y = _spacecraft("constant", n_samples=800)
    ident = StructuredRPBSID(truth.output_layout)
    ident.fit(u, y)
    gain = ident.rigid_gain.gain.copy()
    ident.restart()
    assert ident.model is not None
    np.testing.assert_array_equal(ident.rigid_gain.gain, gain)
    ident.update(u[0], y[0])
    assert np.all(np.isfinite(ident.state))


def test_pickle_mid_run_continues_identically_and_runs_are_deterministic():
    truth, u, y = _spacecraft("constant", n_samples=700)
    first = StructuredRPBSID(truth.output_layout)
    first.fit(u[:600], y[:600])
    copy = pickle.loads(pickle.dumps(first))
    first.fit(u[600:], y[600:])
    copy.fit(u[600:], y[600:])
    np.testing.assert_array_equal(first.model.A, copy.model.A)
    again = StructuredRPBSID(truth.output_layout)
    again.fit(u, y)
    np.testing.assert_array_equal(again.model.B, first.model.B)


@pytest.mark.parametrize("kwargs, error", [
    (dict(layout=OutputLayout.of(("attitude",), n_sensors=0)), ValueError),
    (dict(layout="standard"), TypeError),
    (dict(n=6), ValueError),
    (dict(highpass=1.0), ValueError),
    (dict(process_torque=0.0), ValueError),
    (dict(flexible="sign"), ValueError),
    (dict(layout=RIGID, flexible="classical"), ValueError),
])
def test_bad_constructor_arguments(kwargs, error):
    with pytest.raises(error):
        StructuredRPBSID(**kwargs)


def test_wrong_input_sizes_are_refused_with_the_expected_shape():
    ident = StructuredRPBSID()
    with pytest.raises(ValueError, match="3 body torques"):
        ident.update(np.zeros(2), np.zeros(STANDARD_OUTPUTS.size))
    ident = StructuredRPBSID()
    with pytest.raises(ValueError, match="entries"):
        ident.update(np.zeros(3), np.zeros(5))


def _resonator(hz: float, zeta: float, dt: float = 0.1) -> np.ndarray:
    r = np.exp(-zeta * 2 * np.pi * hz * dt)
    th = 2 * np.pi * hz * dt * np.sqrt(1 - zeta**2)
    return r * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])


def test_resonant_part_keeps_exactly_the_modes_above_the_corner():
    """A 0.2 Hz mode kept; a real pole, an unstable pair, a 0.01 Hz pair and a pair
    damped at 0.5 removed: the projected response equals the 0.2 Hz mode's alone,
    same order."""
    from identifiers.structured.resonant import resonant_part
    blocks = [_resonator(0.2, 0.01), np.array([[0.99]]), 1.01 * _resonator(0.3, 0.0),
              _resonator(0.01, 0.01), _resonator(0.3, 0.5)]
    n = sum(b.shape[0] for b in blocks)
    a = np.zeros((n, n))
    i = 0
    for block in blocks:
        a[i:i + block.shape[0], i:i + block.shape[0]] = block
        i += block.shape[0]
    rng = np.random.default_rng(0)
    t = rng.normal(size=(n, n))                 # hide the blocks in other coordinates
    a = t @ a @ np.linalg.inv(t)
    b, c = t @ rng.normal(size=(n, 2)), rng.normal(size=(3, n)) @ np.linalg.inv(t)
    a_k, b_k, c_k = resonant_part(a, b, c, dt=0.1, min_hz=0.05)
    assert a_k.shape == a.shape
    kept = np.sort_complex(np.linalg.eigvals(a_k)[np.abs(np.linalg.eigvals(a_k)) > 1e-9])
    np.testing.assert_allclose(kept, np.sort_complex(np.linalg.eigvals(_resonator(0.2, 0.01))),
                               atol=1e-9)
    tinv = np.linalg.inv(t)
    b_mode, c_mode = (tinv @ b)[:2], (c @ t)[:, :2]
    for z in np.exp(1j * np.array([0.01, 0.1, 1.0])):
        want = c_mode @ np.linalg.solve(z * np.eye(2) - blocks[0], b_mode)
        got = c_k @ np.linalg.solve(z * np.eye(n) - a_k, b_k)
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_a_mode_just_outside_the_circle_is_reflected_inside():
    """A 0.088 Hz pair at |lambda| = 1.0003 (damping -0.005) is a lightly damped mode
    placed on the wrong side: kept at 1 / 1.0003, same frequency, its residues
    unchanged; a pair at 1.01 (damping -0.053 at 0.3 Hz) is not a mode and goes."""
    from identifiers.structured.resonant import REFLECTED_DAMPING, resonant_part
    light, wild = 1.0003 * _resonator(0.088, 0.0), 1.01 * _resonator(0.3, 0.0)
    a = np.zeros((4, 4))
    a[:2, :2], a[2:, 2:] = light, wild
    rng = np.random.default_rng(1)
    t = rng.normal(size=(4, 4))
    a_t = t @ a @ np.linalg.inv(t)
    b, c = t @ rng.normal(size=(4, 2)), rng.normal(size=(3, 4)) @ np.linalg.inv(t)
    a_k, b_k, c_k = resonant_part(a_t, b, c, dt=0.1, min_hz=0.05)
    lam = np.linalg.eigvals(a_k)
    kept = lam[np.abs(lam) > 1e-9]
    np.testing.assert_allclose(np.abs(kept), 1 / 1.0003, rtol=1e-12)
    np.testing.assert_allclose(np.abs(np.angle(kept)), 2 * np.pi * 0.088 * 0.1, rtol=1e-12)
    # the reflected pair keeps the mode's input and output directions: C P B as before
    tinv = np.linalg.inv(t)
    np.testing.assert_allclose(c_k @ b_k, (c @ t)[:, :2] @ (tinv @ b)[:2], atol=1e-9)
    assert 0.005 < REFLECTED_DAMPING < 0.053


def test_bad_samples_are_skipped_and_a_quiet_spell_leaves_everything_finite():
    """NaN, inf and a wild outlier are skipped and counted; 5000 samples of sensor
    noise without torque (a loop holding still) leave the covariances bounded and
    the model finite, and the health report says the input response is being
    forgotten."""
    truth, u, y = _spacecraft("constant", n_samples=800)
    y, u = y.copy(), u.copy()
    y[600, 2] = np.nan
    u[650, 1] = np.inf
    y[700, 4] = 1e3 * truth.output_layout.scales()[4]        # a glitch: 1000 nominal levels
    ident = StructuredRPBSID(truth.output_layout)
    ident.fit(u, y)
    assert ident.n_skipped == 3 and ident.n_outliers == 1 and ident.n_samples == 800
    rng = np.random.default_rng(1)
    noise = 1e-2 * np.sqrt(np.nanmean(y[:500] ** 2, axis=0))     # 40 dB, as recorded
    with pytest.warns(IdentifierHealthWarning, match="unexcited"):
        for _ in range(5000):
            ident.update(np.zeros(3), y[-1] + noise * rng.standard_normal(noise.size))
    assert np.all(np.isfinite(ident._varx.P)) and np.trace(ident._varx.P) < 1e8
    assert np.all(np.isfinite(ident.model.A)) and np.all(np.isfinite(ident.state))
    health = ident.health
    assert not health.healthy and any("forgotten" in fault for fault in health.faults)
    assert health.rollbacks == 0 and health.restarts == 0
