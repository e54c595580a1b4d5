"""The Kalman filter the identifiers share: against the Riccati solution."""

from __future__ import annotations

import numpy as np
import pytest

from identifiers import KalmanPredictor, steady_state_gain


def _system():
    a = np.array([[0.95, 0.1], [0.0, 0.9]])
    b = np.array([[0.0], [1.0]])
    c = np.array([[1.0, 0.0]])
    return a, b, c, np.diag([0.01, 0.02]), np.array([0.1])


def test_time_varying_filter_converges_to_the_steady_state_filter():
    a, b, c, q, r = _system()
    gain, p_prior = steady_state_gain(a, c, q, r)
    kf = KalmanPredictor(2, initial_covariance=10.0)
    for _ in range(500):
        kf.update(a, b, c, q, r, np.zeros(1), np.zeros(1))
    np.testing.assert_allclose(kf.P, p_prior, rtol=1e-9)
    np.testing.assert_allclose(kf.gain, a @ gain, rtol=1e-9)     # predictor gain A L


def test_filter_beats_the_open_loop_prediction_and_skips_missing_outputs():
    rng = np.random.default_rng(0)
    a, b, c, q, r = _system()
    kf = KalmanPredictor(2)
    x = np.zeros(2)
    err_kf, err_ol = [], []
    x_ol = np.zeros(2)
    for k in range(3000):
        u = rng.normal(size=1)
        y = c @ x + np.sqrt(r) * rng.normal(size=1)
        if k % 7 == 0:
            y = np.array([np.nan])                       # a dropped sample
        pred = kf.update(a, b, c, q, r, u, y)
        x = a @ x + b @ u + rng.multivariate_normal(np.zeros(2), q)
        x_ol = a @ x_ol + b @ u
        err_kf.append(x - pred)
        err_ol.append(x - x_ol)
    assert np.all(np.isfinite(kf.x))
    assert np.mean(np.square(err_kf)) < 0.5 * np.mean(np.square(err_ol))


def test_steady_state_gain_rejects_an_undetectable_unstable_model():
    a = np.diag([1.2, 0.5])
    c = np.array([[0.0, 1.0]])          # the unstable mode is not seen
    with pytest.raises(ValueError, match="Riccati"):
        steady_state_gain(a, c, np.zeros((2, 2)), np.array([1.0]))
