"""The shared RLS primitive against exponentially weighted least squares in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from identifiers import RecursiveLeastSquares

LAM = 0.98


def _data(n: int = 20_000, d: int = 12, q: int = 2, seed: int = 0):
    rng = np.random.default_rng(seed)
    phi = rng.normal(size=(n, d)) * np.linspace(0.1, 3.0, d)   # unevenly excited
    theta = rng.normal(size=(q, d))
    y = phi @ theta.T + 0.01 * rng.normal(size=(n, q))
    return phi, theta, y


def _closed_form(phi, y, k, p0, extra=None):
    """EWLS estimate after k samples: (lam^k / p0 I + sum lam^(k-i) phi phi^T (+ extra))^-1 r."""
    w = LAM ** np.arange(k - 1, -1, -1)
    info = LAM**k / p0 * np.eye(phi.shape[1]) + (phi[:k] * w[:, None]).T @ phi[:k]
    if extra is not None:
        info = info + extra
    return np.linalg.solve(info, (phi[:k] * w[:, None]).T @ y[:k]).T


def test_scalar_closed_form():
    """One step from theta = 0, P = p0, phi = 3, y = 6, lambda = 0.9."""
    plain = RecursiveLeastSquares(1, 1, forgetting=0.9, initial_covariance=2.0,
                                  regularization=0.0)
    plain.update(np.array([3.0]), np.array([6.0]))
    assert plain.theta[0, 0] == pytest.approx(2.0 * 3 * 6 / (0.9 + 2.0 * 9))
    # with the default floor 1 / p0 the pseudo-row w^2 = (1 - 0.9) / 2 joins the
    # information lambda / p0 + phi^2 = 0.45 + 9
    rls = RecursiveLeastSquares(1, 1, forgetting=0.9, initial_covariance=2.0)
    rls.update(np.array([3.0]), np.array([6.0]))
    info = 0.9 / 2.0 + 9.0 + 0.1 / 2.0
    assert rls.P[0, 0] == pytest.approx(1.0 / info)
    assert rls.theta[0, 0] == pytest.approx(3.0 * 6.0 / info)


def test_plain_forgetting_equals_weighted_least_squares_over_20000_samples():
    phi, _, y = _data()
    rls = RecursiveLeastSquares(2, 12, LAM, 1.0, regularization=0.0)
    for k in range(len(phi)):
        rls.update(phi[k], y[k])
        if k + 1 in (1000, 5000, 20_000):
            ref = _closed_form(phi, y, k + 1, 1.0)
            assert np.linalg.norm(rls.theta - ref) / np.linalg.norm(ref) < 1e-8
    np.testing.assert_array_equal(rls.P, rls.P.T)
    assert np.linalg.eigvalsh(rls.P).min() > 0


def test_regularized_forgetting_equals_its_closed_form():
    """The floor is Tikhonov pseudo-rows w e_i (one coordinate per step): the
    closed form with those rows, over 20,000 samples."""
    phi, _, y = _data()
    d, p0 = 12, 0.5
    rls = RecursiveLeastSquares(2, d, LAM, p0)                 # default floor: 1 / p0
    w2 = d * (1 - LAM) / p0
    extra = np.zeros((d, d))
    for k in range(len(phi)):
        rls.update(phi[k], y[k])
        extra *= LAM
        extra[k % d, k % d] += w2
    ref = _closed_form(phi, y, len(phi), p0, extra)
    assert np.linalg.norm(rls.theta - ref) / np.linalg.norm(ref) < 1e-8


def test_reconverges_after_a_parameter_jump_within_a_few_memories():
    phi, theta, y = _data(n=6000)
    rng = np.random.default_rng(7)
    jumped = theta + rng.normal(size=theta.shape)
    y = y.copy()
    y[3000:] = phi[3000:] @ jumped.T + 0.01 * rng.normal(size=(3000, 2))
    rls = RecursiveLeastSquares(2, 12, LAM, 1.0)
    for k in range(3000 + 5 * 50):                    # five memories of 1 / (1 - 0.98)
        rls.update(phi[k], y[k])
    # judged where the data carry information: the prediction error on fresh regressors
    excited = np.linspace(0.1, 3.0, 12)
    assert np.linalg.norm((rls.theta - jumped) * excited) \
        / np.linalg.norm(jumped * excited) < 0.02


def test_covariance_stays_bounded_without_excitation():
    rls = RecursiveLeastSquares(3, 20, forgetting=LAM, initial_covariance=1.0)
    phi, _, y = _data(n=500, d=20, q=3)
    for k in range(500):
        rls.update(phi[k], y[k])
    for _ in range(10_000):
        rls.update(np.zeros(20), np.zeros(3))
    eig = np.linalg.eigvalsh(rls.P)
    # pulled back toward P0 = I; the one-coordinate-per-step floor keeps every
    # direction within (1 - lam^d) / (d (1 - lam) lam^d) of it
    bound = (1 - LAM**20) / (20 * (1 - LAM) * LAM**20)
    assert eig.max() <= bound * 1.0001 and eig.min() > 0


def test_plain_forgetting_winds_up_without_excitation():
    """The floor is what bounds P: without it P grows as lambda^-k (documented)."""
    rls = RecursiveLeastSquares(1, 4, LAM, 1.0, regularization=0.0)
    for _ in range(500):
        rls.update(np.zeros(4), np.zeros(1))
    assert np.linalg.eigvalsh(rls.P).max() == pytest.approx(LAM**-500, rel=1e-9)


def test_non_finite_or_overflowing_updates_change_nothing():
    rls = RecursiveLeastSquares(2, 3, LAM, 1.0)
    rls.update(np.ones(3), np.ones(2))
    before = rls.theta.copy(), rls.P
    assert rls.update(np.array([np.nan, 0, 0]), np.ones(2)) is None
    assert rls.update(np.ones(3), np.array([1e300, 0.0])) is None
    assert rls.n_rejected == 2
    np.testing.assert_array_equal(rls.theta, before[0])
    np.testing.assert_array_equal(rls.P, before[1])


# ------------------------------------------------------------------ vector forgetting
def test_vector_forgetting_with_equal_entries_is_the_scalar_recursion():
    phi, _, y = _data(n=3000)
    scalar = RecursiveLeastSquares(2, 12, LAM, 1.0)
    vector = RecursiveLeastSquares(2, 12, np.full(12, LAM), 1.0)
    for k in range(len(phi)):
        scalar.update(phi[k], y[k])
        vector.update(phi[k], y[k])
    np.testing.assert_array_equal(vector.theta, scalar.theta)
    assert vector.forgetting == LAM


def test_vector_forgetting_follows_its_information_recursion():
    """R_k = L R_{k-1} L + phi phi^T and R_k theta_k = L R_{k-1} L theta_{k-1} + phi y^T,
    with L = diag(lambda)^(1/2): checked against the recursion on R run alongside."""
    phi, _, y = _data(n=3000)
    lam = np.where(np.arange(12) < 4, 0.95, 0.999)
    rls = RecursiveLeastSquares(2, 12, lam, 1.0, regularization=0.0)
    assert rls.forgetting is None
    root = np.sqrt(lam)
    info = np.eye(12)
    theta = np.zeros((2, 12))
    for k in range(len(phi)):
        rls.update(phi[k], y[k])
        prior = root[:, None] * info * root[None, :]
        info = prior + np.outer(phi[k], phi[k])
        theta = np.linalg.solve(info, prior @ theta.T + np.outer(phi[k], y[k])).T
    np.testing.assert_allclose(rls.P @ info, np.eye(12), atol=1e-8)
    np.testing.assert_allclose(rls.theta, theta, rtol=1e-8, atol=1e-10)
    np.testing.assert_array_equal(rls.P, rls.P.T)


def test_fast_forgetting_parameters_track_a_jump_the_slow_ones_do_not_lose():
    """The four best-excited parameters jump at sample 3000. With forgetting 0.95
    there and 0.999 elsewhere the model re-converges within five short memories
    (judged by the prediction error on fresh regressors, where the data carry
    information), which a long memory everywhere does not, and is more accurate
    than a short memory everywhere."""
    phi, theta, y = _data(n=4000)
    rng = np.random.default_rng(3)
    jumped = theta.copy()
    jumped[:, 8:] += rng.normal(size=(2, 4))
    y = y.copy()
    y[3000:] = phi[3000:] @ jumped.T + 0.01 * rng.normal(size=(1000, 2))
    runs = {"vector": np.where(np.arange(12) >= 8, 0.95, 0.999), "slow": 0.999, "fast": 0.95}
    runs = {name: RecursiveLeastSquares(2, 12, lam, 1.0) for name, lam in runs.items()}
    for k in range(3000 + 5 * 20):                    # five memories of 1 / (1 - 0.95)
        for rls in runs.values():
            rls.update(phi[k], y[k])
    excited = np.linspace(0.1, 3.0, 12)
    err = {name: np.linalg.norm((rls.theta - jumped) * excited)
           / np.linalg.norm(jumped * excited) for name, rls in runs.items()}
    assert err["vector"] < 0.02 and err["slow"] > 0.3 and err["fast"] > 1.5 * err["vector"]


@pytest.mark.parametrize("lam", [np.full(3, 0.9), [0.9, 1.1, 0.9, 0.9], [0.0, 0.5, 0.5, 0.5]])
def test_bad_vector_forgetting(lam):
    with pytest.raises(ValueError, match="forgetting"):
        RecursiveLeastSquares(1, 4, lam)


# ------------------------------------------------------------------ the compiled kernel
def _dense_reference(phi, y, lam, p0, delta, hold, gate):
    """The documented recursion on a dense P, in plain NumPy: excitation gate,
    vector forgetting, gain, rank-1 correction and the floor's pseudo-row."""
    n, d = phi.shape
    theta, p = np.zeros((y.shape[1], d)), p0 * np.eye(d)
    weights = np.sqrt(d * (1.0 - lam) * delta)
    gate_level = gate * d * float((1.0 - lam).max())
    cycle = 0
    for k in range(n):
        share = min(1.0, float(phi[k] @ p @ phi[k]) / gate_level)
        lam_eff = 1.0 - (1.0 - lam) * share
        lam_max = lam_eff.max()
        r = np.sqrt(lam_max / lam_eff)
        p = p * np.outer(r, r)
        p_phi = p @ phi[k]
        denom = lam_max + phi[k] @ p_phi
        theta = theta + np.outer(y[k] - theta @ phi[k], p_phi / denom)
        p = (p - np.outer(p_phi, p_phi) / denom) / lam_max
        i, cycle = cycle, (cycle + 1) % d
        w = weights[i] * np.sqrt(share)
        p_e = p[:, i] * w
        denom = 1.0 + w * p_e[i]
        if not hold[i]:
            theta = theta + np.outer(-w * theta[:, i], p_e / denom)
        p = p - np.outer(p_e, p_e) / denom
    return theta, p


def test_compiled_update_equals_the_dense_recursion_with_gate_floor_and_hold():
    phi, _, y = _data(n=600, d=9, q=3)
    phi[300:] *= 0.05                       # a quiet stretch: the gate and the floor act
    lam = np.linspace(0.97, 0.995, 9)
    delta = np.linspace(1e-3, 1e-1, 9)
    hold = np.arange(9) < 3
    rls = RecursiveLeastSquares(3, 9, lam, 10.0, regularization=delta, hold=hold, gate=0.25)
    for k in range(len(phi)):
        rls.update(phi[k], y[k])
    theta, p = _dense_reference(phi, y, lam, 10.0, delta, hold, 0.25)
    np.testing.assert_allclose(rls.theta, theta, rtol=1e-9, atol=1e-12 * np.abs(theta).max())
    np.testing.assert_allclose(rls.P, p, rtol=1e-9, atol=1e-12 * np.abs(p).max())


def test_update_many_is_the_update_loop_bit_for_bit_with_skipped_and_refused_rows():
    phi, _, y = _data(n=300, d=7, q=2)
    phi[120] = np.inf                       # refused by both (nothing changes)
    use = np.ones(300, dtype=bool)
    use[50:60] = False                      # not applied
    kwargs = dict(regularization=np.linspace(1e-3, 1e-1, 7), hold=np.arange(7) < 2,
                  gate=0.25, drift=1e-6)
    loop = RecursiveLeastSquares(2, 7, np.linspace(0.97, 0.995, 7), 10.0, **kwargs)
    batch = RecursiveLeastSquares(2, 7, np.linspace(0.97, 0.995, 7), 10.0, **kwargs)
    expected = np.full((300, 2), np.nan)
    for k in range(300):
        if use[k]:
            err = loop.update(phi[k], y[k])
            if err is not None:
                expected[k] = err
    errors, accepted = batch.update_many(phi, y, use=use)
    np.testing.assert_array_equal(errors, expected)
    np.testing.assert_array_equal(accepted, ~np.isnan(expected[:, 0]))
    assert not accepted[120] and not accepted[50:60].any() and accepted.sum() == 289
    np.testing.assert_array_equal(batch.theta, loop.theta)
    np.testing.assert_array_equal(batch.P, loop.P)
    assert batch.n_rejected == loop.n_rejected == 1


def test_update_many_refuses_mismatched_shapes():
    rls = RecursiveLeastSquares(2, 3, 0.99, 1.0)
    with pytest.raises(ValueError, match=r"phis must be \(J, 3\), ys \(J, 2\)"):
        rls.update_many(np.zeros((5, 4)), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="use"):
        rls.update_many(np.zeros((5, 3)), np.zeros((5, 2)), use=np.ones(4, dtype=bool))


def test_set_drift_continues_as_an_rls_built_with_that_drift():
    """Changing the walk mid-run: from then on the recursion (floor's pseudo-rows
    included) is that of an RLS constructed with the new drift and the same state."""
    phi, _, y = _data(n=400, d=6, q=2)
    kwargs = dict(regularization=np.linspace(1e-3, 1e-1, 6), hold=np.arange(6) < 2, gate=0.25)
    changed = RecursiveLeastSquares(2, 6, 1.0, 10.0, drift=1e-6, **kwargs)
    for k in range(200):
        changed.update(phi[k], y[k])
    built = RecursiveLeastSquares(2, 6, 1.0, 10.0, drift=np.full(6, 3e-4), **kwargs)
    built.theta[:] = changed.theta
    built.set_covariance(changed.P)
    changed.set_covariance(changed.P)           # the same normalization of P on both
    built._cycle = changed._cycle               # and the floor's pseudo-row in turn
    changed.set_drift(3e-4)
    for k in range(200, 400):
        changed.update(phi[k], y[k])
        built.update(phi[k], y[k])
    np.testing.assert_array_equal(changed.drift, built.drift)
    np.testing.assert_allclose(changed.theta, built.theta, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(changed.P, built.P, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize(("drift", "match"), [(-1e-6, ">= 0"), (np.nan, ">= 0"),
                                              (np.ones(5), "shape")])
def test_set_drift_refuses_bad_values_and_keeps_the_old_one(drift, match):
    rls = RecursiveLeastSquares(1, 6, 1.0, 1.0, drift=1e-5)
    with pytest.raises(ValueError, match=match):
        rls.set_drift(drift)
    np.testing.assert_array_equal(rls.drift, np.full(6, 1e-5))
