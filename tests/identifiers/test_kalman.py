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


def test_split_updates_equal_the_textbook_filter_with_all_or_some_outputs():
    """correct + predict (the controllers' filters; compiled where every output is
    seen) against the equations written out, with a partly missing sample too."""
    rng = np.random.default_rng(3)
    n, m = 4, 3
    a = 0.9 * np.eye(n) + 0.05 * rng.normal(size=(n, n))
    b = rng.normal(size=(n, 2))
    c = rng.normal(size=(m, n))
    q, r = 0.01 * np.eye(n), np.array([0.1, 0.2, 0.3])
    kf = KalmanPredictor(n, initial_covariance=2.0)
    x, p = np.zeros(n), 2.0 * np.eye(n)
    for k in range(30):
        y, u = rng.normal(size=m), rng.normal(size=2)
        if k % 5 == 4:
            y[1] = np.nan                                  # one output missing
        seen = np.isfinite(y)
        cs = c[seen]
        s = cs @ p @ cs.T + np.diag(r[seen])
        gain = p @ cs.T @ np.linalg.inv(s)
        x, p = x + gain @ (y[seen] - cs @ x), p - gain @ cs @ p
        np.testing.assert_allclose(kf.correct(c, r, y, a=a), x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.P, p, rtol=1e-10, atol=1e-12)
        expected_gain = np.zeros((n, m))
        expected_gain[:, seen] = a @ gain
        np.testing.assert_allclose(kf.gain, expected_gain, rtol=1e-10, atol=1e-12)
        assert (kf.innovation_covariance is None) == (not seen.all())
        x, p = a @ x + b @ u, a @ p @ a.T + q
        np.testing.assert_allclose(kf.predict(a, b, q, u), x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.P, p, rtol=1e-10, atol=1e-12)
        assert np.array_equal(kf.P, kf.P.T)              # kept exactly symmetric


def test_a_filter_on_a_model_that_holds_still_becomes_the_steady_state_filter():
    """correct + predict on one model: once the covariance has converged the filter
    holds it (two products a step) and follows the textbook filter to rounding; a
    missing output, another model or an inflation return to the full recursion."""
    rng = np.random.default_rng(4)
    a, b, c, q, r = _system()
    kf = KalmanPredictor(2, initial_covariance=10.0)
    x, p = np.zeros(2), 10.0 * np.eye(2)
    steady = []
    for k in range(400):
        y, u = rng.normal(size=1), rng.normal(size=1)
        if k == 300:
            y = np.array([np.nan])                          # a dropped sample
        if np.isfinite(y).all():
            s = c @ p @ c.T + np.diag(r)
            gain = p @ c.T @ np.linalg.inv(s)
            x, p = x + gain @ (y - c @ x), p - gain @ c @ p
        x, p = a @ x + b @ u, a @ p @ a.T + q
        kf.correct(c, r, y, a=a)
        kf.predict(a, b, q, u)
        steady.append(kf.steady)
        np.testing.assert_allclose(kf.x, x, rtol=0, atol=1e-8 * np.abs(x).max())
        np.testing.assert_allclose(kf.P, p, rtol=1e-8)
    first = steady.index(True)
    assert 2 <= first < 300 and all(steady[first:300])     # held once converged ...
    assert not steady[300]                                  # ... not across a dropped sample
    assert steady[-1] and not kf.P.flags.writeable          # and held again, shared read-only
    kf.predict(a + 1e-3, b, q, np.zeros(1))                 # another model: full recursion
    assert not kf.steady
    kf.reset()
    assert not kf.steady


def test_advance_is_predict_then_correct_to_the_bit():
    """The controllers' filter step in one compiled call: the same numbers as the two
    calls, with every output, with a missing one, and on a model that holds still
    (where both become the steady filter at the same step)."""
    rng = np.random.default_rng(5)
    a, b, c, q, r = _system()
    one, two = KalmanPredictor(2, 10.0), KalmanPredictor(2, 10.0)
    for k in range(300):
        y, u = rng.normal(size=1), rng.normal(size=1)
        if k in (100, 150):
            y = np.array([np.nan])
        x1 = one.advance(a, b, q, u, c, r, y, a_now=a)
        two.predict(a, b, q, u)
        x2 = two.correct(c, r, y, a=a)
        assert np.array_equal(x1, x2) and np.array_equal(one.P, two.P)
        assert np.array_equal(one.gain, two.gain) and one.steady == two.steady
    assert one.steady
