"""Metrics of identified models: closed forms, the truth as its own ceiling."""

from __future__ import annotations

import numpy as np
import pytest

from identifiers import (
    ModelSequence,
    StateSpaceModel,
    h_step_predictions,
    modal_errors,
    persistence_predictions,
    prediction_vaf,
    relative_gain_error,
    rigid_body_gain,
    unstable_share,
)
from spacecraft_conventions import STANDARD_OUTPUTS
from spacecraft_env import FlexibleSpacecraftModel


def _sequence(model: StateSpaceModel, n: int, states: np.ndarray) -> ModelSequence:
    rep = lambda m: np.repeat(m[None], n, axis=0)  # noqa: E731
    return ModelSequence(rep(model.A), rep(model.B), rep(model.C), rep(model.D), rep(model.K),
                         np.ones(n, dtype=bool), model.dt, states=states)


def test_h_step_predictions_of_the_true_model_are_exact():
    rng = np.random.default_rng(0)
    a = np.array([[0.9, 0.2], [-0.2, 0.9]])
    model = StateSpaceModel(a, np.array([[1.0], [0.5]]), np.array([[1.0, 0.0]]),
                            np.zeros((1, 1)), np.zeros((2, 1)), 0.1)
    u = rng.normal(size=(300, 1))
    x = np.zeros((301, 2))
    for k in range(300):
        x[k + 1] = a @ x[k] + model.B @ u[k]
    y = x[:300] @ model.C.T
    # states[k] is x_{k+1|k}: the state after sample k
    pred = h_step_predictions(_sequence(model, 300, x[1:]), u, (1, 7, 40))
    for h, p in pred.items():
        np.testing.assert_allclose(p[h:], y[h:], atol=1e-12)
        assert np.isnan(p[:h]).all()
    assert prediction_vaf(y, pred, start=50)[40] == pytest.approx([100.0])


def test_persistence_is_the_delayed_output():
    y = np.arange(20.0)[:, None]
    pred = persistence_predictions(y, (1, 5))
    np.testing.assert_array_equal(pred[5][5:, 0], np.arange(15.0))
    # a ramp: persistence misses by h at every sample; VAF = 1 - var(h) / var(y) = 100 %
    assert prediction_vaf(y, pred, start=5)[5][0] == pytest.approx(100.0)


def test_h_step_predictions_need_states_and_positive_horizons():
    m = StateSpaceModel(np.eye(1), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)),
                        np.zeros((1, 1)), 0.1)
    seq = _sequence(m, 5, np.zeros((5, 1)))
    with pytest.raises(ValueError, match=">= 1"):
        h_step_predictions(seq, np.zeros((5, 1)), (0,))
    seq.states = None
    with pytest.raises(ValueError, match="no states"):
        h_step_predictions(seq, np.zeros((5, 1)), (1,))


@pytest.mark.parametrize("scenario", ["constant", "docking"])
def test_rigid_body_gain_of_the_truth_is_the_inverse_inertia(scenario):
    truth = FlexibleSpacecraftModel(scenario=scenario)
    for t in (0.0, 150.0, 240.0):
        d = truth.discrete(t)
        model = StateSpaceModel(d.A, d.B, truth.C, np.zeros((truth.n_outputs, 3)),
                                np.zeros((truth.n, truth.n_outputs)), truth.dt)
        gain = rigid_body_gain(model, STANDARD_OUTPUTS.slice("rate"))
        assert relative_gain_error(gain, np.linalg.inv(truth.inertia(t))) < 1e-9


def test_modal_errors_match_the_nearest_mode():
    wn = 2 * np.pi * np.array([0.1, 0.5])
    zeta = np.array([0.02, 0.01])
    poles = np.exp(0.1 * (-zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)))
    a = np.zeros((4, 4))
    for i, p in enumerate(poles):
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[p.real, -p.imag], [p.imag, p.real]]
    model = StateSpaceModel(a, np.ones((4, 1)), np.ones((1, 4)), np.zeros((1, 1)),
                            np.zeros((4, 1)), 0.1)
    freq_err, damp_err = modal_errors(model, [0.102, 0.5], [0.02, 0.01])
    np.testing.assert_allclose(freq_err, [abs(0.1 / 0.102 - 1), 0.0], atol=1e-9)
    np.testing.assert_allclose(damp_err, [0.0, 0.0], atol=1e-9)


def test_unstable_share_counts_models_beyond_the_bound():
    n = 10
    a = np.repeat(np.eye(1)[None], n, axis=0) * 0.99
    a[[2, 5, 7]] = 1.01
    seq = ModelSequence(a, np.ones((n, 1, 1)), np.ones((n, 1, 1)), np.zeros((n, 1, 1)),
                        np.zeros((n, 1, 1)), np.ones(n, dtype=bool), 0.1)
    assert unstable_share(seq) == pytest.approx(0.3)
    assert unstable_share(seq, start=6) == pytest.approx(0.25)
