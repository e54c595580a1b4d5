"""The parts of the rigid-flexible identifier that track change: the closed-form
oscillator ZOH and its sensitivities, the filter bank's re-centring, the modal
tracker, the random-walk RLS and the rigid-gain estimate with its covariance."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from identifiers import default_identifier
from identifiers.core.modal_basis import ModalFilterBank, Resonator, mode_zoh
from identifiers.core.modal_kernels import oscillator_zoh, oscillator_zoh_derivatives
from identifiers.core.residual_statistics import (
    MAX_CORRELATION,
    correlation_time,
    lag_product_step,
    mean_square_step,
)
from identifiers.core.rigid_gain import RigidGainEstimate
from identifiers.core.rls import RecursiveLeastSquares
from identifiers.modal.modal_tracker import ModalTracker, TrackerGroup
from spacecraft_env import FlexibleSpacecraftModel

DT = 0.1


@pytest.mark.parametrize(("f", "zeta"), [(0.0874, 0.01), (0.5, 0.1), (1.2, 0.0), (0.02, 0.3)])
def test_closed_form_zoh_is_the_matrix_exponential(f, zeta):
    a, b = mode_zoh(f, zeta, DT)
    a2, b2 = oscillator_zoh(f, zeta, DT)
    np.testing.assert_allclose(a2, a, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(b2, b, rtol=1e-10, atol=1e-16)


def test_zoh_derivatives_match_finite_differences_of_the_exponential():
    f, zeta, h = 0.2365, 0.02, 1e-6
    _, _, da, db = oscillator_zoh_derivatives(f, zeta, DT)
    for p, (fp, zp, fm, zm) in enumerate([(f * np.exp(h), zeta, f * np.exp(-h), zeta),
                                          (f, zeta + h, f, zeta - h)]):
        ap, bp = mode_zoh(fp, zp, DT)
        am, bm = mode_zoh(fm, zm, DT)
        np.testing.assert_allclose(da[p], (ap - am) / (2 * h), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(db[p], (bp - bm) / (2 * h), rtol=1e-6, atol=1e-11)


def _run(bank: ModalFilterBank, u: np.ndarray) -> ModalFilterBank:
    for uk in u:
        bank.step(uk)
    return bank


def test_bank_sensitivities_are_the_derivatives_of_its_states():
    rng = np.random.default_rng(0)
    u = rng.normal(size=(300, 3))
    res = [Resonator(0.0874, 0.01), Resonator(0.3, 0.02)]
    h = 1e-6
    base = _run(ModalFilterBank(res, DT, sensitivities=True), u)
    dq, dfree = base.sensitivity()
    for p in range(2):
        banks = []
        for sign in (1.0, -1.0):
            moved = [Resonator(r.frequency_hz * np.exp(sign * h * (p == 0)),
                               r.damping + sign * h * (p == 1)) for r in res]
            banks.append(_run(ModalFilterBank(moved, DT), u))
        fd = (banks[0]._q - banks[1]._q) / (2 * h)
        np.testing.assert_allclose(dq[:, p], fd, rtol=1e-5, atol=1e-8 * np.abs(fd).max())
        fd_free = (banks[0]._free[:, 0, :] - banks[1]._free[:, 0, :]) / (2 * h)
        np.testing.assert_allclose(dfree[:, p], fd_free, rtol=1e-5,
                                   atol=1e-8 * np.abs(fd_free).max())


def test_recentring_moves_the_bank_to_first_order_without_a_restart():
    rng = np.random.default_rng(1)
    u = rng.normal(size=(300, 3))
    res = [Resonator(0.0874, 0.01), Resonator(0.3, 0.02)]
    step = np.array([5e-4, -1e-3]), np.array([2e-4, 0.0])
    moved = _run(ModalFilterBank(res, DT, sensitivities=True), u)
    moved.recenter(*step)
    target = _run(ModalFilterBank([Resonator(r.frequency_hz * np.exp(dl), r.damping + dz)
                                   for r, dl, dz in zip(res, *step, strict=True)], DT), u)
    unmoved = _run(ModalFilterBank(res, DT), u)
    scale = np.abs(target._q).max()
    # second order in the step: a few percent of the first-order move it corrects
    assert np.abs(moved._q - target._q).max() < 0.05 * np.abs(unmoved._q - target._q).max()
    assert np.abs(moved._q - target._q).max() < 1e-3 * scale
    np.testing.assert_allclose(moved.mode_matrices[0], target.mode_matrices[0], rtol=1e-12)
    with pytest.raises(RuntimeError, match="sensitivities"):
        ModalFilterBank(res, DT).recenter(*step)


def _two_mode_record(noise: float, n: int = 4000, seed: int = 0):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    truth = _run(ModalFilterBank([Resonator(0.0874, 0.01), Resonator(0.2365, 0.01)], DT), [])
    coupling = rng.normal(size=(2, 3, 4))
    y = np.empty((n, 4))
    for k in range(n):
        y[k] = np.einsum("ia,iao->o", truth._q[:, :, 0], coupling)
        truth.step(u[k])
    return u, y + noise * y.std(0) * rng.normal(size=y.shape)


def _track(u, y, start, refine=True):
    bank = ModalFilterBank(start, DT, sensitivities=True)
    idx = np.arange(bank.size)
    cols = np.concatenate([idx[bank.slices["flexible"]].reshape(2, 3, 2)[:, :, 0].ravel(),
                           idx[bank.slices["free"]]])
    group = TrackerGroup(np.arange(4), cols, np.arange(6).reshape(2, 3),
                         np.arange(6, 10).reshape(2, 2), 0)
    tracker = ModalTracker([group], 2, forgetting=0.999)
    for k in range(len(u)):
        dq, dfree = bank.sensitivity()
        tracker.update(bank.regressor(), dq, dfree, y[k])
        bank.step(u[k])
        if refine and k % 10 == 9:
            delta = tracker.refine()
            if delta is not None:
                bank.recenter(delta[:, 0], delta[:, 1])
                tracker.recenter(delta)
    return bank, tracker


@pytest.mark.parametrize("noise", [0.0, 0.1])
def test_tracker_finds_the_modes_from_a_percent_off(noise):
    u, y = _two_mode_record(noise)
    start = [Resonator(0.0874 * 1.01, 0.015), Resonator(0.2365 * 0.99, 0.005)]
    bank, tracker = _track(u, y, start)
    freq = np.array([r.frequency_hz for r in bank.resonators])
    zeta = np.array([r.damping for r in bank.resonators])
    np.testing.assert_allclose(freq, [0.0874, 0.2365], rtol=2e-4 if noise else 5e-5)
    np.testing.assert_allclose(zeta, [0.01, 0.01], atol=5e-4 if noise else 5e-5)
    assert tracker.n_steps > 10 and tracker.covariance is not None
    if noise:                                # the reported band holds the truth
        std = np.sqrt(np.diag(tracker.covariance))[::2]      # log-frequency std
        assert np.all(np.abs(np.log(freq / [0.0874, 0.2365])) < 3 * std)


def test_tracker_holds_still_on_data_its_model_explains():
    u, y = _two_mode_record(0.0)
    bank, _ = _track(u, y, [Resonator(0.0874, 0.01), Resonator(0.2365, 0.01)])
    np.testing.assert_allclose([r.frequency_hz for r in bank.resonators], [0.0874, 0.2365],
                               rtol=1e-9)


def test_random_walk_rls_is_the_scalar_kalman_filter():
    rng = np.random.default_rng(2)
    q, r0 = 1e-3, 5.0
    rls = RecursiveLeastSquares(1, 1, 1.0, r0, regularization=0.0, drift=q)
    theta, p = 0.0, r0
    for _ in range(500):
        phi, y = rng.normal(), rng.normal()
        g = p * phi / (1.0 + phi * p * phi)
        theta += g * (y - phi * theta)
        p = p - g * phi * p + q
        rls.update(np.array([phi]), np.array([y]))
    assert rls.theta[0, 0] == pytest.approx(theta, rel=1e-10)
    assert rls.P[0, 0] == pytest.approx(p, rel=1e-10)


def test_random_walk_floor_bounds_an_unexcited_coordinate():
    # coordinate 1 is never excited: its variance settles at 1 / delta, not drift * k
    rls = RecursiveLeastSquares(1, 2, 1.0, 1.0, regularization=0.01, drift=1e-2)
    rng = np.random.default_rng(3)
    for _ in range(30_000):
        rls.update(np.array([rng.normal(), 0.0]), np.array([rng.normal()]))
    assert rls.P[1, 1] == pytest.approx(100.0, rel=0.05)


def test_rigid_gain_estimate_in_closed_form():
    theta = np.array([[2.0, 0.1, 0.0], [0.1, 3.0, 0.0], [0.0, 0.0, 4.0]])
    p = np.diag([0.01, 0.04, 0.09])
    est = RigidGainEstimate.from_regression(theta, p, np.array([1.0, 2.0, 3.0]),
                                            np.array([10.0, 10.0, 10.0]),
                                            np.array([2.0, 2.0, 2.0]))
    np.testing.assert_allclose(est.gain, 5.0 * theta)
    # var(G[r, a]) = rows_r^2 var_r P[a, a] / cols_a^2
    np.testing.assert_allclose(est.std[1, 2], np.sqrt(100 * 2.0 * 0.09 / 4))
    assert est.covers(est.gain) and est.mahalanobis(est.gain) == 0.0
    far = est.gain + 10 * est.std
    assert not est.covers(far) and est.mahalanobis(far) > 10
    with pytest.raises(ValueError, match="covariance"):
        RigidGainEstimate(np.eye(3), np.eye(4))


def _symmetric_factor(rng: np.random.Generator) -> np.ndarray:
    """(9, 6): a symmetric gain's six free entries into its nine, times a random factor."""
    dup = np.zeros((9, 6))
    for j, (r, c) in enumerate(zip(*np.triu_indices(3), strict=True)):
        dup[3 * r + c, j] = dup[3 * c + r, j] = 1.0
    return dup @ rng.normal(size=(6, 6))


@pytest.mark.parametrize("shape", ["nine equal variances", "anisotropic", "rank 6", "rank 1",
                                   "symmetric gain, rounding noise"])
def test_two_sigma_region_covers_a_calibrated_estimate_95_percent_of_the_time(shape):
    # errors drawn from the reported covariance: the 2-sigma region must hold
    # erf(2 / sqrt 2) = 95.45 % of them whatever the covariance's shape (the former
    # test ||d|| <= 2 sqrt(trace C) held about 100 % of the nine-equal-variance draws)
    rng = np.random.default_rng(11)
    factor = {"nine equal variances": 1e-2 * np.eye(9),
              "anisotropic": rng.normal(size=(9, 9)) * np.exp(1.5 * rng.normal(size=9)),
              "rank 6": rng.normal(size=(9, 6)),
              "rank 1": rng.normal(size=(9, 1)),
              "symmetric gain, rounding noise": _symmetric_factor(rng)}[shape]
    cov = factor @ factor.T
    if shape.endswith("rounding noise"):       # as a covariance mapped through inv() has
        noise = 1e-15 * np.abs(cov).max() * rng.normal(size=(9, 9))
        cov = cov + 0.5 * (noise + noise.T)
    est = RigidGainEstimate(np.eye(3), cov)
    errors = rng.standard_normal((4000, factor.shape[1])) @ factor.T
    share = np.mean([est.covers(np.eye(3) + e.reshape(3, 3)) for e in errors])
    assert share == pytest.approx(0.9545, abs=0.015)


def test_two_sigma_region_of_one_uncertain_entry_is_its_scalar_band():
    cov = np.zeros((9, 9))
    cov[4, 4] = 0.25                                   # G[1, 1], standard deviation 0.5
    est = RigidGainEstimate(np.eye(3), cov)
    inside, outside = np.eye(3), np.eye(3)
    inside[1, 1] += 0.99
    outside[1, 1] += 1.01
    assert est.covers(inside) and not est.covers(outside)
    assert est.covers(outside, sigmas=2.1)
    off = inside.copy()
    off[0, 2] = 1e-6                                   # an entry claimed exactly is off
    assert not est.covers(off) and est.mahalanobis(off) == pytest.approx(1.98)
    assert est.mahalanobis(outside) == pytest.approx(2.02)
    with pytest.raises(ValueError, match="sigmas"):
        est.covers(inside, sigmas=0.0)
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        est.covers(np.eye(2))


def test_identifier_reports_its_rigid_gain_with_an_honest_band():
    truth = FlexibleSpacecraftModel(scenario="constant")
    rng = np.random.default_rng(4)
    u = rng.normal(size=(1200, 3))
    y = truth.simulate(u)[1]
    y = y + 0.01 * np.abs(y).max(0) * rng.normal(size=y.shape)
    ident = default_identifier()
    for k in range(len(u)):
        ident.update(u[k], y[k])
    est = ident.rigid_gain
    true = np.linalg.inv(truth.inertia(0.0))
    assert est.covers(true, 2.0) and est.relative_std() < 0.1
    freq, zeta, _ = ident.mode_estimates
    assert freq.shape == zeta.shape and freq.size == len(ident.resonators)
    clone = pickle.loads(pickle.dumps(ident))
    np.testing.assert_array_equal(clone.rigid_gain.gain, est.gain)


def _ar1(phi: float, n: int, rng: np.random.Generator) -> np.ndarray:
    e = rng.normal(size=n)
    out = np.empty(n)
    out[0] = e[0] / np.sqrt(1 - phi**2)
    for k in range(1, n):
        out[k] = phi * out[k - 1] + e[k]
    return out


@pytest.mark.parametrize("phi", [0.0, 0.6, 0.95])
def test_correlation_time_of_a_first_order_autoregression(phi):
    """(1 + phi) / (1 - phi) samples per independent one: 1, 4 and 39."""
    e = _ar1(phi, 400_000, np.random.default_rng(1))
    lag, square = np.mean(e[1:] * e[:-1]), np.mean(e**2)
    expected = (1 + phi) / (1 - phi)
    assert correlation_time(np.array([lag]), np.array([square])) == pytest.approx(
        expected, rel=0.02 if phi < 0.9 else 0.1, abs=0.01)


def test_correlation_time_pools_outputs_by_their_squares_and_is_clipped():
    # a loud white output outweighs a faint correlated one
    assert correlation_time(np.array([0.0, 0.99e-4]), np.array([1.0, 1e-4])) < 1.001
    # anticorrelation credits no more than independence; a sine is near the clip
    assert correlation_time(np.array([-0.5]), np.array([1.0])) == 1.0
    t = np.arange(20_000)
    s = np.sin(2 * np.pi * 0.009 * t)
    slow = correlation_time(np.array([np.mean(s[1:] * s[:-1])]), np.array([np.mean(s**2)]))
    assert 1000 < slow <= (1 + MAX_CORRELATION) / (1 - MAX_CORRELATION)
    for bad in (np.zeros(2), np.full(2, np.nan)):
        assert correlation_time(np.ones(2), bad) == 1.0


def test_running_level_steps_are_the_numpy_expressions():
    rng = np.random.default_rng(2)
    level, x, prev = rng.random(5), rng.normal(size=5), rng.normal(size=5)
    expected = 0.995 * level + 0.005 * x * x
    mean_square_step(out := level.copy(), x, 0.995, 0.005)
    np.testing.assert_allclose(out, expected, rtol=1e-15)
    lag_product_step(out := level.copy(), x, prev, 0.995, 0.005)
    np.testing.assert_allclose(out, 0.995 * level + 0.005 * x * prev, rtol=1e-15)


def test_a_correlated_residual_holds_less_evidence_for_a_step():
    """The same window: its step and the reported variance shrink and grow with the
    residual's correlation time; a bad one raises."""
    u, y = _two_mode_record(0.1, n=1000)
    start = [Resonator(0.0874 * 1.01, 0.015), Resonator(0.2365 * 0.99, 0.005)]
    _, tracker = _track(u, y, start, refine=False)
    steps, variances = [], []
    for c in (1.0, 30.0):
        copy = pickle.loads(pickle.dumps(tracker))
        delta = copy.refine(c)
        steps.append(0.0 if delta is None else np.abs(delta[:, 0]).max())
        variances.append(np.diag(copy.covariance)[0])
    assert steps[0] > 0 and steps[1] < steps[0]
    assert variances[1] > 2 * variances[0]
    for bad in (0.5, np.nan, np.inf):
        with pytest.raises(ValueError, match="correlation_time"):
            tracker.refine(bad)
