"""Identifier checks: closed forms, equivalences, streaming API, robustness."""

from __future__ import annotations

import itertools
import pickle

import numpy as np
import pytest

from identifiers import (
    ClassicalRPBSID,
    ImprovedRPBSID,
    ModelSequence,
    MomentRefitRPBSID,
    PredictorRPBSID,
    StateSpaceModel,
    WindowedPBSID,
    normalized_error,
    pbsid,
    vaf,
)
from identifiers.subspace.varx import (
    free_response,
    predictor_product,
    regressor_gram,
    regressor_matrix,
)


def _innovation_system(seed: int = 0, n_samples: int = 3000, noise: float = 0.1):
    """A well-posed 4-state, 2-input, 3-output innovation-form system and data."""
    rng = np.random.default_rng(seed)
    a = np.diag([0.9, 0.8, 0.7, 0.5])
    a[0, 1] = 0.3
    n, r, m = 4, 2, 3
    b = rng.normal(size=(n, r))
    c = rng.normal(size=(m, n))
    k = rng.normal(size=(n, m)) * 0.1
    u = rng.normal(size=(n_samples, r))
    e = rng.normal(size=(n_samples, m)) * noise
    x = np.zeros(n)
    y = np.empty((n_samples, m))
    for t in range(n_samples):
        y[t] = c @ x + e[t]
        x = a @ x + b @ u[t] + k @ e[t]
    return StateSpaceModel(a, b, c, np.zeros((m, r)), k), u, y


TRUE_POLES = np.array([0.5, 0.7, 0.8, 0.9])


# ------------------------------------------------------------------ VARX algebra
def test_free_response_equals_weighted_predictor_product():
    rng = np.random.default_rng(0)
    m, r, p = 4, 2, 6
    xi = rng.normal(size=(m, p * (r + m))) * 0.3
    phi = rng.normal(size=p * (r + m))
    for f in (1, 3, 8):
        np.testing.assert_allclose(predictor_product(xi, r, f) @ phi,
                                   free_response(xi, phi, r, f), atol=1e-12)


def test_regressor_matrix_is_newest_first():
    z = np.arange(40.0).reshape(20, 2)
    phi = regressor_matrix(z, 3)
    np.testing.assert_array_equal(phi[0], np.concatenate([z[2], z[1], z[0]]))
    assert phi.shape == (17, 6)


@pytest.mark.parametrize(("n_samples", "p"), [(12, 1), (20, 2), (60, 7), (400, 25)])
def test_regressor_gram_equals_the_direct_product(n_samples, p):
    # the block-Toeplitz recursion against Phi^T Phi, channels 1e-3 to 1e2 in scale
    rng = np.random.default_rng(p)
    z = rng.normal(size=(n_samples, 5)) * np.array([1e-3, 1e-1, 1.0, 10.0, 100.0])
    phi = regressor_matrix(z, p)
    direct = phi.T @ phi
    for gram in (regressor_gram(z, p), regressor_gram(z, p, phi)):
        assert gram.shape == direct.shape
        np.testing.assert_array_equal(gram, gram.T)
        np.testing.assert_allclose(gram, direct, rtol=1e-12, atol=1e-12 * np.abs(direct).max())


# ------------------------------------------------------------------ batch PBSID
def test_pbsid_leading_eigenpairs_give_the_full_decomposition_s_model():
    # the plain call solves for the n leading eigenpairs only, full_output for all of
    # them: the same model up to the states' signs (poles and Markov parameters agree)
    _, u, y = _innovation_system()
    plain = pbsid(u, y, 4, 10)
    full = pbsid(u, y, 4, 10, full_output=True)
    assert full.singular_values.shape == (10 * y.shape[1],)
    np.testing.assert_allclose(np.sort_complex(plain.poles()), np.sort_complex(full.model.poles()),
                               atol=1e-9)
    for k in range(5):
        markov = plain.C @ np.linalg.matrix_power(plain.A, k) @ plain.B
        np.testing.assert_allclose(markov, full.model.C @ np.linalg.matrix_power(full.model.A, k)
                                   @ full.model.B, atol=1e-9)


def test_pbsid_recovers_poles():
    true, u, y = _innovation_system()
    model = pbsid(u, y, 4, 10)
    np.testing.assert_allclose(np.sort(np.abs(model.poles())), TRUE_POLES, atol=0.02)
    u_test = np.random.default_rng(5).normal(size=(300, 2))
    assert normalized_error(model.simulate(u_test), true.simulate(u_test)).max() < 2.0


def test_pbsid_exact_on_noise_free_spacecraft():
    from identifiers import identification_inputs, paper_test_inputs
    from spacecraft_env import FlexibleSpacecraftModel

    truth = FlexibleSpacecraftModel(scenario="constant")
    u = identification_inputs(1500, np.random.default_rng(0))
    _, y = truth.simulate(u)
    model = pbsid(u, y, truth.n, 15, regularization=0.0)   # noise-free: no ridge needed
    u_test = paper_test_inputs(1500)
    _, y_test = truth.simulate(u_test)
    assert normalized_error(model.simulate(u_test), y_test).max() < 0.5


# ------------------------------------------------------------------ recursive identifiers
@pytest.mark.parametrize("make", [
    lambda: MomentRefitRPBSID(4, 8, 0.999),
    lambda: PredictorRPBSID(4, 8, 0.999),
    lambda: ClassicalRPBSID(4, 8, 0.999),
    lambda: WindowedPBSID(4, 8, window=600, refit_every=100),
])
def test_online_identifiers_converge_on_well_posed_system(make):
    true, u, y = _innovation_system()
    seq = make().fit(u, y)
    final = seq[len(seq) - 1]
    # forgetting 0.999 keeps ~1000 of the 3000 samples: a looser pole band than batch
    np.testing.assert_allclose(np.sort(np.abs(final.poles())), TRUE_POLES, atol=0.03)
    u_test = np.random.default_rng(5).normal(size=(300, 2))
    assert normalized_error(final.simulate(u_test), true.simulate(u_test)).max() < 3.0


def test_improved_state_equals_classical_state():
    """The forward-prediction state is the classical W LK phi without LK."""
    _, u, y = _innovation_system(n_samples=400)
    imp = PredictorRPBSID(4, 8, 0.99, f=8, warmup=100)
    cls = ClassicalRPBSID(4, 8, 0.99, f=8, warmup=100)
    for k in range(400):
        imp.update(u[k], y[k])
        cls.update(u[k], y[k])
    np.testing.assert_allclose(imp.state, cls.state, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(imp.model.A, cls.model.A, rtol=1e-7, atol=1e-10)


@pytest.mark.parametrize("make", [
    lambda: PredictorRPBSID(4, 8, 0.999, warmup=500),
    lambda: ClassicalRPBSID(4, 8, 0.999, warmup=500),
])
def test_the_system_stage_learns_from_the_warm_up(make):
    """A quiet stretch after an excited warm-up (a closed loop after its excitation):
    the model given then has the input response the warm-up showed, since the warm-up's
    states went through the system stage when the basis was fixed."""
    true, u, y = _innovation_system(n_samples=700)
    quiet = u.copy()
    quiet[500:] *= 1e-3                           # the loop's torques, near the noise
    x, e = np.zeros(4), np.random.default_rng(1).normal(size=(700, 3)) * 0.1
    for t in range(700):
        y[t] = true.C @ x + e[t]
        x = true.A @ x + true.B @ quiet[t] + true.K @ e[t]
    ident = make()
    for t in range(700):
        ident.update(quiet[t], y[t])
    u_test = np.random.default_rng(5).normal(size=(300, 2))
    err = normalized_error(ident.model.simulate(u_test), true.simulate(u_test))
    assert err.max() < 3.0, err                  # % (without the replay: 100 %)


def test_paper_apsa_algorithm_lags_as_designed():
    """The paper's APSA form is kept as a preset; measured, it does not track."""
    true, u, y = _innovation_system()
    seq = ImprovedRPBSID.paper(4, p=8, forgetting=0.999).fit(u, y)
    u_test = np.random.default_rng(5).normal(size=(300, 2))
    err = normalized_error(seq[len(seq) - 1].simulate(u_test), true.simulate(u_test))
    assert np.all(np.isfinite(err))
    assert err.min() > 20.0   # if this starts passing the docs must change


def test_fit_equals_update_loop():
    _, u, y = _innovation_system(n_samples=300)
    seq = MomentRefitRPBSID(4, 8, 0.99, warmup=100).fit(u, y)
    ident = MomentRefitRPBSID(4, 8, 0.99, warmup=100)
    for k in range(300):
        ident.update(u[k], y[k])
        model = ident.model
        if model is None:
            assert not seq.valid[k]
        else:
            np.testing.assert_array_equal(seq.A[k], model.A)
            np.testing.assert_array_equal(seq.K[k], model.K)
    assert isinstance(seq, ModelSequence) and len(seq) == 300 and seq.valid.sum() > 100


def test_model_none_until_warmed_up():
    ident = MomentRefitRPBSID(4, 8, 0.99, warmup=40)
    _, u, y = _innovation_system(n_samples=60)
    for k in range(39):
        ident.update(u[k], y[k])
        assert ident.model is None and ident.state is None
    ident.update(u[39], y[39])
    assert ident.model is not None and ident.state.shape == (4,)


def test_nan_samples_skipped_and_counted():
    _, u, y = _innovation_system(n_samples=500)
    y = y.copy()
    y[200, 1] = np.nan
    u = u.copy()
    u[300, 0] = np.inf
    ident = MomentRefitRPBSID(4, 8, 0.99)
    for k in range(500):
        ident.update(u[k], y[k])
    assert ident.n_skipped == 2 and ident.n_samples == 500
    assert np.all(np.isfinite(ident.model.A)) and np.all(np.isfinite(ident.state))


def test_zero_excitation_keeps_everything_bounded():
    # zero torque and outputs at the 1e-12 level: the regressors carry no excitation,
    # and the covariances must stay bounded (no wind-up) over 10,000 samples
    _, u, y = _innovation_system(n_samples=300)
    quiet = np.random.default_rng(1).normal(scale=1e-12, size=(10_000, 3))
    zero_u = np.zeros(2)
    ident = MomentRefitRPBSID(4, 8, 0.98)
    for k in range(300):
        ident.update(u[k], y[k])
    for q in quiet:
        ident.update(zero_u, q)
    assert np.all(np.isfinite(ident._varx.P)) and np.trace(ident._varx.P) < 1e6
    assert np.all(np.isfinite(ident.model.A))
    rls_ident = PredictorRPBSID(4, 8, 0.98)
    for k in range(300):
        rls_ident.update(u[k], y[k])
    for q in quiet:
        rls_ident.update(zero_u, q)
    for rls in (rls_ident._varx, rls_ident._output_rls, rls_ident._system_rls):
        assert np.all(np.isfinite(rls.P)) and np.trace(rls.P) < 1e6


def test_samples_at_rest_are_passed_over_without_moving_anything():
    # zero input and the output unchanged bit for bit: no information, so nothing
    # learnt is forgotten and the sample clock does not move
    _, u, y = _innovation_system(n_samples=400)
    ident = MomentRefitRPBSID(4, 8, 0.98, warmup=100)
    for k in range(300):
        ident.update(u[k], y[k])
    before = (ident.model.A.copy(), ident._varx.P.copy(), ident._k)
    for _ in range(1000):
        ident.update(np.zeros(2), y[299])
    assert ident.n_idle == 1000 and ident.n_samples == 1300 and ident._k == before[2]
    np.testing.assert_array_equal(ident.model.A, before[0])
    np.testing.assert_array_equal(ident._varx.P, before[1])


def test_pickle_mid_run_continues_bit_identically():
    _, u, y = _innovation_system(n_samples=400)
    ident = MomentRefitRPBSID(4, 8, 0.99, warmup=100)
    for k in range(200):
        ident.update(u[k], y[k])
    clone = pickle.loads(pickle.dumps(ident))
    for k in range(200, 400):
        ident.update(u[k], y[k])
        clone.update(u[k], y[k])
    np.testing.assert_array_equal(ident.model.A, clone.model.A)
    np.testing.assert_array_equal(ident.state, clone.state)


def test_the_model_is_one_read_only_object_while_its_matrices_hold():
    """Reading ``model`` twice without a sample gives the same object (the adaptive
    loop reads it every step); a sample that moves the estimate gives a new one, and
    the idle samples that leave it unchanged keep the object."""
    _, u, y = _innovation_system(n_samples=300)
    ident = MomentRefitRPBSID(4, 8, 0.99, warmup=100)
    for k in range(200):
        ident.update(u[k], y[k])
    first = ident.model
    assert ident.model is first and not first.A.flags.writeable
    models = []
    for k in range(200, 300):
        ident.update(u[k], y[k])
        models.append(ident.model)
    for before, after in itertools.pairwise(models):
        same_bits = all(np.array_equal(getattr(before, m), getattr(after, m)) for m in "ABCDK")
        assert (after is before) == same_bits              # a new object exactly when moved
    moved = models[-1]
    assert moved is not first and not np.array_equal(moved.A, first.A)
    for _ in range(5):
        ident.update(np.zeros(2), y[299])                  # idle: nothing learnt
    assert ident.model is moved
    ident.reset()
    assert ident.model is None


def test_reset_forgets_sizes():
    ident = MomentRefitRPBSID(4, 8, 0.99)
    ident.update(np.zeros(2), np.zeros(3))
    ident.reset()
    ident.update(np.zeros(1), np.zeros(5))   # new sizes accepted after reset
    assert (ident.n_inputs, ident.n_outputs) == (1, 5)


@pytest.mark.parametrize(
    ("call", "error"),
    [
        (lambda i: i.update(np.zeros((2, 1)), np.zeros(3)), ValueError),
        (lambda i: i.update(np.zeros(2), np.zeros(4)), ValueError),   # changed size
        (lambda i: i.update(np.array(["a", "b"]), np.zeros(3)), TypeError),
        (lambda i: i.fit(np.zeros((5, 2)), np.zeros((4, 3))), ValueError),
    ],
)
def test_bad_input(call, error):
    ident = MomentRefitRPBSID(4, 8, 0.99)
    ident.update(np.zeros(2), np.zeros(3))
    with pytest.raises(error):
        call(ident)


@pytest.mark.parametrize(
    "make",
    [
        lambda: ImprovedRPBSID(0, 8),
        lambda: ImprovedRPBSID(4, 8, 1.5),
        lambda: ImprovedRPBSID(4, 8, mu=0.0),
        lambda: MomentRefitRPBSID(4, 8, refit_every=0),
        lambda: MomentRefitRPBSID(4.5, 8),
        lambda: ClassicalRPBSID(4, 8, basis="random"),
        lambda: WindowedPBSID(4, 8, window=0),
    ],
)
def test_bad_constructor_arguments(make):
    with pytest.raises((ValueError, TypeError)):
        make()


def test_order_too_large_for_window_raises():
    ident = MomentRefitRPBSID(20, 2, 0.99, warmup=40)
    with pytest.raises(ValueError, match="p \\* m"):
        ident.update(np.zeros(2), np.zeros(3))


def test_state_space_model_tools():
    true, u, y = _innovation_system(n_samples=200)
    sys_c = true.to_control()
    assert sys_c.dt == pytest.approx(0.1)
    freq, damping = StateSpaceModel(
        np.array([[np.cos(0.5), -np.sin(0.5)], [np.sin(0.5), np.cos(0.5)]]) * np.exp(-0.01),
        np.ones((2, 1)), np.ones((1, 2)), np.zeros((1, 1)), np.zeros((2, 1)), dt=0.1).modal()
    wn = np.hypot(0.5, 0.01) / 0.1
    assert freq[0] == pytest.approx(wn / (2 * np.pi))
    assert damping[0] == pytest.approx(0.01 / np.hypot(0.5, 0.01))
    # the one-step predictor with the true K beats open-loop simulation
    pred = true.predict(u, y)
    assert vaf(y, pred).min() > vaf(y, true.simulate(u)).min()
    with pytest.raises(ValueError):
        StateSpaceModel(np.eye(2), np.ones((3, 1)), np.ones((1, 2)), np.zeros((1, 1)),
                        np.zeros((2, 1)))


@pytest.mark.parametrize("n_steps", [20_000, pytest.param(100_000, marks=pytest.mark.slow)])
def test_long_run_stays_finite(n_steps):
    rng = np.random.default_rng(2)
    true, _, _ = _innovation_system()
    ident = MomentRefitRPBSID(4, 8, 0.98)
    x = np.zeros(4)
    for _ in range(n_steps):
        u = rng.normal(size=2)
        e = 0.1 * rng.normal(size=3)
        ident.update(u, true.C @ x + e)
        x = true.A @ x + true.B @ u + true.K @ e
    assert np.all(np.isfinite(ident.model.A)) and np.all(np.isfinite(ident.state))


# ------------------------------------------------------------------ tracking a pole jump
def test_recursive_rpbsids_track_a_pole_jump(load_benchmark):
    """benchmarks/bench_pole_jump.py on 3 seeds: 300+ samples after the jump both
    recursive methods are far closer to the new poles than a model that stopped
    learning (0.2); the batch PBSID on the new data is the ceiling. The issue's
    bar (0.02) is not met (docs/results/identification.md)."""
    bench = load_benchmark("bench_pole_jump")
    res = bench.run(seeds=3, noise=0.1)
    frozen = np.median(res["frozen"]["after"])
    assert frozen == pytest.approx(0.2, abs=1e-3)
    assert np.median(res["batch"]["after"]) < 0.02
    assert np.median(res["classical"]["after"]) < 0.3 * frozen
    assert np.median(res["improved"]["after"]) < 0.75 * frozen
