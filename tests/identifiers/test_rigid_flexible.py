"""The package's default online identifier: exact where physics is exact, the
streaming API, and what it must deliver on the spacecraft."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from identifiers import (
    ImprovedRPBSID,
    Resonator,
    RigidFlexibleIdentifier,
    default_identifier,
    h_step_predictions,
    persistence_predictions,
    prediction_vaf,
    relative_gain_error,
    rigid_body_gain,
    unstable_share,
)
from identifiers.modal.record_replay import clearly_worse, horizon_errors
from spacecraft_conventions import STANDARD_OUTPUTS, OutputLayout
from spacecraft_env import FlexibleSpacecraftModel
from spacecraft_lab.identification import env_record, identification_records

RIGID = OutputLayout.of(("attitude", "rate"), n_sensors=0)
RATE = STANDARD_OUTPUTS.slice("rate")


def _spacecraft(scenario: str, seed: int, n_samples: int = 2500, snr_db: float | None = 40.0):
    truth = FlexibleSpacecraftModel(scenario=scenario)
    record = identification_records(truth, seed, n_samples, snr_db)
    return truth, record.u, record.y_clean, record.y


# --------------------------------------------------------------------- exact cases
def test_rigid_body_gain_and_model_are_exact_on_a_noise_free_rigid_body(rigid_body_record):
    inertia = np.array([[30_000.0, 500.0, 0.0], [500.0, 20_000.0, 0.0], [0.0, 0.0, 22_000.0]])
    u, y = rigid_body_record(inertia)
    ident = RigidFlexibleIdentifier(RIGID, n=6, detect_changes=False)
    seq = ident.fit(u, y)
    model = seq[len(seq) - 1]
    # exact up to the Tikhonov floor's pull and the high-pass start-up
    assert relative_gain_error(rigid_body_gain(model, slice(3, 6)), np.linalg.inv(inertia)) \
        < 1e-5
    np.testing.assert_allclose(np.abs(np.linalg.eigvals(model.A)), 1.0, atol=1e-12)
    vaf = prediction_vaf(y, h_step_predictions(seq, u, (100,)), start=600)[100]
    assert vaf.min() > 99.999


# --------------------------------------------------------------------- streaming API
@pytest.fixture(scope="module")
def constant_record():
    return _spacecraft("constant", 0, n_samples=900)


def test_fit_equals_the_update_loop_and_pickles_mid_run(constant_record):
    _, u, _, y = constant_record
    a = default_identifier()
    seq = a.fit(u, y)
    b = default_identifier()
    for k in range(600):
        b.update(u[k], y[k])
    c = pickle.loads(pickle.dumps(b))
    for k in range(600, len(u)):
        b.update(u[k], y[k])
        c.update(u[k], y[k])
    for other in (b, c):
        np.testing.assert_array_equal(other.model.A, seq[len(seq) - 1].A)
        np.testing.assert_array_equal(other.state, seq.states[-1])


def test_the_batch_replay_equals_the_sample_by_sample_replay(constant_record, monkeypatch):
    # a rebuild replays its record's head in batch (each group's RLS in one compiled
    # loop) and its tail in stretches between exports (the filter, then the learning
    # in batch); through _sample, one sample at a time, every number is the same
    _, u, _, y = constant_record
    u, y = u[:700], y[:700]                 # the warm-up's rebuild and 200 live samples
    batch = default_identifier()
    batch_seq = batch.fit(u, y)

    def one_by_one(self, phis, y_fs, use, sensitivities):
        for j in range(len(use)):
            sens = None if sensitivities is None else (sensitivities[0][j], sensitivities[1][j])
            self._sample(None, None, bool(use[j]), True, replay_k=0, filtering=False,
                         signals=(phis[j], y_fs[j], sens))

    def tail_one_by_one(self, samples, first, start_k, phis, y_fs, use, sensitivities):
        for j in range(first, len(samples)):
            uk, yk, learn, real = samples[j]
            sens = None if sensitivities is None else (sensitivities[0][j],
                                                       sensitivities[1][j])
            self._sample(uk, yk, learn, real, replay_k=start_k + j, filtering=True,
                         signals=(phis[j], y_fs[j], sens))

    monkeypatch.setattr(RigidFlexibleIdentifier, "_replay_learning", one_by_one)
    monkeypatch.setattr(RigidFlexibleIdentifier, "_replay_tail", tail_one_by_one)
    loop = default_identifier()
    loop_seq = loop.fit(u, y)
    np.testing.assert_array_equal(batch_seq.A[-1], loop_seq.A[-1])
    np.testing.assert_array_equal(batch_seq.states, loop_seq.states)
    for name in ("_resvar", "_sigvar", "_r"):
        np.testing.assert_array_equal(getattr(batch, name), getattr(loop, name))
    for (_, _, a), (_, _, b) in zip(batch._fits, loop._fits, strict=True):
        np.testing.assert_array_equal(a.theta, b.theta)
        np.testing.assert_array_equal(a.P, b.P)
    for a, b in zip(batch._tracker._s, loop._tracker._s, strict=True):
        np.testing.assert_array_equal(a, b)


def test_no_model_until_warm_up_then_a_full_state_space_model(constant_record):
    _, u, _, y = constant_record
    ident = default_identifier()
    for k in range(499):
        ident.update(u[k], y[k])
    assert ident.model is None and ident.state is None
    ident.update(u[499], y[499])
    model = ident.model
    assert model.A.shape == (22, 22) and model.B.shape == (22, 3)
    assert model.C.shape == (10, 22) and model.K.shape == (22, 10)
    assert ident.state.shape == (22,)


def test_corrupt_samples_are_skipped_and_the_estimate_stays_finite(constant_record):
    _, u, _, y = constant_record
    y = y.copy()
    y[[100, 550, 700], 3] = np.nan
    y[650, 6] = 1e12
    ident = default_identifier()
    seq = ident.fit(u, y)
    assert ident.n_skipped == 4
    assert np.all(np.isfinite(seq.states[seq.valid]))


def test_reset_starts_over(constant_record):
    _, u, _, y = constant_record
    ident = default_identifier()
    first = ident.fit(u[:600], y[:600])
    ident.reset()
    again = ident.fit(u[:600], y[:600])
    np.testing.assert_array_equal(first.A[-1], again.A[-1])


def test_restart_carries_the_model_into_a_new_record_of_the_same_plant(constant_record):
    truth, u, _, y = constant_record
    ident = default_identifier()
    ident.fit(u, y)
    before = ident.model
    gain = rigid_body_gain(before, RATE)
    ident.restart()
    # the model is kept, the state estimate starts afresh
    np.testing.assert_array_equal(ident.model.A, before.A)
    np.testing.assert_array_equal(rigid_body_gain(ident.model, RATE), gain)
    np.testing.assert_array_equal(ident.state, np.zeros(22))
    # a new record (other inputs, other noise) is predicted from its first seconds
    _, u2, _, y2 = _spacecraft("constant", 1, n_samples=400)
    seq = ident.fit(u2, y2)
    assert seq.valid.all()
    h = 30
    pred = h_step_predictions(seq, u2, (h,))[h]
    pers = persistence_predictions(y2, (h,))[h]
    rows = STANDARD_OUTPUTS.indices("rate")
    window = slice(50, 400 - h)
    model_mse = np.nanmean((pred[window, rows] - y2[window, rows]) ** 2)
    persistence_mse = np.nanmean((pers[window, rows] - y2[window, rows]) ** 2)
    assert model_mse < 0.2 * persistence_mse
    assert relative_gain_error(rigid_body_gain(ident.model, RATE),
                               np.linalg.inv(truth.inertia(0.0))) < 0.1


def test_restart_before_the_warm_up_ends_keeps_collecting(constant_record):
    truth, u, _, y = constant_record
    ident = default_identifier()
    for k in range(300):
        ident.update(u[k], y[k])
    ident.restart()
    for k in range(300, 499):
        ident.update(u[k], y[k])
    assert ident.model is None                    # 499 samples: still warming up
    ident.update(u[499], y[499])
    # the warm-up's 500 samples span both records: a model at the 500th, already good
    assert ident.model is not None
    assert relative_gain_error(rigid_body_gain(ident.model, RATE),
                               np.linalg.inv(truth.inertia(0.0))) < 0.1


def test_the_default_restart_of_a_past_window_method_starts_afresh(constant_record):
    _, u, _, y = constant_record
    ident = ImprovedRPBSID(n=22, p=15)
    ident.fit(u, y)
    assert ident.model is not None
    ident.restart()
    assert ident.model is None and ident.n_samples == 0


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"n": 7}, ValueError, "even order"),
    ({"n": 4}, ValueError, "even order"),
    ({"layout": OutputLayout.of(("attitude",), n_sensors=0)}, ValueError, "rate"),
    ({"layout": "standard"}, TypeError, "OutputLayout"),
    ({"prior": [0.1]}, TypeError, "Resonator"),
    ({"rigid_drift": -1.0}, ValueError, "rigid_drift"),
    ({"tracking_memory": 1.0}, ValueError, "tracking_memory"),
    ({"highpass": 1.0}, ValueError, "highpass"),
    ({"rediscover": 0}, ValueError, "rediscover"),
    ({"drift_reference": 0.0}, ValueError, "drift_reference"),
])
def test_bad_constructor_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        RigidFlexibleIdentifier(**kwargs)


def test_wrong_sample_sizes_raise():
    ident = default_identifier()
    with pytest.raises(ValueError, match="3 body torques"):
        ident.update(np.zeros(2), np.zeros(10))
    with pytest.raises(ValueError, match="10 entries"):
        ident.update(np.zeros(3), np.zeros(9))


# --------------------------------------------------------------------- on the spacecraft
@pytest.fixture(scope="module")
def docking_run():
    truth, u, y0, y = _spacecraft("docking", 1)
    ident = default_identifier()
    return truth, u, y0, ident, ident.fit(u, y)


def test_docking_is_detected_within_ten_seconds(docking_run):
    truth, *_, ident, _ = docking_run
    first_docking = truth.scenario.event_times()[0]
    assert any(0 <= e.time - first_docking <= 10.0 for e in ident.events)
    assert all(e.time >= 50.0 for e in ident.events)       # nothing during warm-up


def test_no_identified_model_has_an_unstable_pole(docking_run):
    *_, seq = docking_run
    assert unstable_share(seq, seq.first_valid(), bound=1.001) == 0.0


def test_ten_second_predictions_beat_persistence_by_far(docking_run):
    _truth, u, y0, _, seq = docking_run
    start = 1500                                            # t >= 150 s
    ours = prediction_vaf(y0, h_step_predictions(seq, u, (100,)), start)[100]
    pers = prediction_vaf(y0, persistence_predictions(y0, (100,)), start)[100]
    for group, rows in STANDARD_OUTPUTS:
        assert ours[rows].mean() > (98.0 if group != "deflection" else 60.0)
        # at most half of persistence's unexplained variance
        assert 100.0 - ours[rows].mean() < (100.0 - pers[rows].mean()) * 0.5


def test_rigid_gain_before_the_docking_within_three_percent(docking_run):
    truth, *_, seq = docking_run
    errors = [relative_gain_error(rigid_body_gain(seq[k], RATE),
                                  np.linalg.inv(truth.inertia(k * truth.dt)))
              for k in range(800, 1000, 20)]
    assert max(errors) < 0.03


def test_noise_free_data_are_no_harder_than_noisy_data():
    """On exact data the change test has nothing to mistake for a change."""
    _truth, u, y0, _ = _spacecraft("constant", 0, snr_db=None)
    ident = default_identifier()
    seq = ident.fit(u, y0)
    vaf = prediction_vaf(y0, h_step_predictions(seq, u, (100,)), 1500)[100]
    assert vaf[:6].min() > 99.9 and vaf[6:].mean() > 90.0


def test_a_drift_reference_speeds_the_walk_up_only_where_the_data_are_cleaner():
    """Drifts stated at 40 dB of the nominal levels: noisier data keep them, noise-free
    data walk faster (at most 100x); without a reference the drifts are never scaled."""
    scales = {}
    for snr in (20.0, None):
        _, u, _, y = _spacecraft("constant", 0, n_samples=900, snr_db=snr)
        for reference in (1e-4, None):
            ident = default_identifier(drift_reference=reference)
            ident.fit(u, y)
            scales[snr, reference] = ident.drift_scales
            for (_, _, rls), stated, group in zip(ident._fits, ident._stated_drifts,
                                                  STANDARD_OUTPUTS.names, strict=True):
                np.testing.assert_allclose(rls.drift, stated * ident.drift_scales[group])
    assert set(scales[20.0, 1e-4]) == {"attitude", "rate", "deflection"}
    assert all(s == 1.0 for key in [(20.0, 1e-4), (20.0, None), (None, None)]
               for s in scales[key].values())
    clean = scales[None, 1e-4]
    assert clean["attitude"] > 10 and clean["rate"] > 10, clean
    assert max(clean.values()) <= 100.0 + 1e-9, clean
    assert default_identifier().drift_scales == {}           # before the warm-up


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "not met: on paddle rotation the 10 s deflection VAF noise-free is below that at "
    "40 dB, median over seeds 0-9 66.6 against 72.6 % (before the rebuild replayed its "
    "whole record: 69.3 against 71.6 %; seeds 10-19 37.8 against 79.7 %); single records "
    "swing by tens of points with which mode searches are kept "
    "(docs/results/identification.md)"))
def test_deflection_prediction_does_not_fall_as_the_noise_falls():
    """Cleaner data must not make the model worse: the 10 s-ahead deflection VAF on
    paddle rotation noise-free is at least that at 40 dB (median over ten seeds of
    the tracking benchmark's env records)."""
    deflection = STANDARD_OUTPUTS.slice("deflection")
    median = {}
    for snr in (40.0, None):
        vafs = []
        for seed in range(10):
            u, y, y0, _ = env_record("paddle_rotation", seed, snr)
            seq = default_identifier().fit(u, y)
            vafs.append(prediction_vaf(y0, h_step_predictions(seq, u, (100,)), 1500)[100]
                        [deflection].mean())
        median[snr] = np.median(vafs)
    assert median[None] >= median[40.0], median


@pytest.mark.parametrize("error", [-0.05, 0.10])
def test_a_prior_off_by_five_to_ten_percent_still_predicts_well(error):
    """The user's nominal model may be off; the data correct it."""
    truth, u, y0, y = _spacecraft("constant", 2)
    f, z = truth.modal(0.0)
    prior = [Resonator((1 + error) * fi, zi) for fi, zi in zip(f, z, strict=True)]
    seq = default_identifier(prior=prior).fit(u, y)
    vaf = prediction_vaf(y0, h_step_predictions(seq, u, (100,)), 1500)[100]
    assert vaf[STANDARD_OUTPUTS.slice("attitude")].mean() > 99.0
    assert vaf[RATE].mean() > 99.0


def test_horizon_errors_are_zero_for_the_true_model_and_grow_with_a_wrong_one():
    """The search's judge: noise-free data of an oscillator are predicted 10 steps
    ahead exactly by its own model, and not by one 5 % off in frequency."""
    def oscillator(f_hz):
        w = 2 * np.pi * f_hz * 0.1
        a = 0.999 * np.array([[np.cos(w), np.sin(w)], [-np.sin(w), np.cos(w)]])
        return a, np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]), np.array([[1.0, 0.0]])

    a, b, c = oscillator(0.2)
    u = np.random.default_rng(0).standard_normal((600, 3))
    x, y = np.zeros(2), np.empty((600, 1))
    for k in range(600):
        y[k] = c @ x
        x = a @ x + b @ u[k]
    mats = (a, b, c, np.zeros((1, 3)), np.zeros((2, 1)))     # data from rest: K = 0
    exact = horizon_errors(mats, u, y, first=300, horizon=10)
    assert exact.shape == (29,) and exact.max() < 1e-20       # starts 300, 310, ..., 580
    wrong = (*oscillator(0.21), np.zeros((1, 3)), np.zeros((2, 1)))
    assert horizon_errors(wrong, u, y, first=300, horizon=10).mean() > 1e-2
    observer = (*oscillator(0.21), np.zeros((1, 3)), np.array([[0.5], [0.0]]))
    assert horizon_errors(observer, u, y, first=300, horizon=10).mean() > 1e-2
    assert horizon_errors(mats, u, y, first=600).size == 0     # no starting point


def test_a_candidate_is_clearly_worse_only_beyond_the_spread_of_the_difference():
    rng = np.random.default_rng(1)
    in_use = 1.0 + 0.1 * rng.standard_normal(40)
    assert not clearly_worse(in_use + 0.01 * rng.standard_normal(40), in_use)
    assert clearly_worse(in_use + 0.5, in_use)
    assert not clearly_worse(in_use - 0.5, in_use)
    noisy = in_use + 0.05 + rng.standard_normal(40)             # worse on average, by noise
    assert not clearly_worse(noisy, in_use)
    assert clearly_worse(np.where(np.arange(40) == 3, np.inf, in_use), in_use)
    assert not clearly_worse(in_use, np.full(40, np.inf))
    assert clearly_worse(in_use + 0.5, in_use, no_skill=2.0)
    assert not clearly_worse(in_use + 0.5, in_use, no_skill=0.5)    # in use: no skill


def test_a_search_that_predicts_worse_is_undone_exactly():
    """Modes a search proposes do not replace the tracked ones if they predict the
    last 50 s clearly worse; a rejected rebuild leaves no trace: the identifier goes
    on exactly as one whose search found nothing new."""
    _, u, _, y = _spacecraft("constant", 0, n_samples=1300)
    found = []
    original = RigidFlexibleIdentifier._find_resonators

    def proposing(wrong):
        def find(self):
            if self._bank is None:                           # the warm-up's search
                return original(self)
            found.append(wrong)
            return [Resonator(0.5, 0.01)] if wrong else list(self.resonators)
        return find

    idents = {}
    for wrong in (False, True):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(RigidFlexibleIdentifier, "_find_resonators", proposing(wrong))
            ident = default_identifier()
            idents[wrong] = (ident, ident.fit(u, y))
    (kept, kept_seq), (undone, undone_seq) = idents[False], idents[True]
    assert found == [False, True]                     # one search each, at sample 1000
    assert (undone.n_searches_rejected, undone.n_rediscoveries) == (1, 0)
    assert kept.n_searches_rejected == 0
    assert undone.resonators == kept.resonators
    np.testing.assert_array_equal(undone_seq.A, kept_seq.A)
    np.testing.assert_array_equal(undone_seq.states, kept_seq.states)


def test_modes_are_searched_again_and_move_toward_the_truth():
    truth, u, _, y = _spacecraft("constant", 0)
    ident = default_identifier()
    ident.fit(u[:500], y[:500])
    first = ident.resonators
    ident.fit(u[500:], y[500:])          # fit() continues where the first call stopped
    assert ident.n_rediscoveries >= 1 and ident.resonators != first
    true_f = truth.modal(0.0)[0][:4]           # the paddle and antenna modes near 0.08-0.09 Hz
    found = np.array([r.frequency_hz for r in ident.resonators])
    assert max(np.abs(found / f - 1).min() for f in true_f[1:]) < 0.02
