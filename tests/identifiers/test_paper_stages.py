"""The source paper's improved RPBSID checked stage by stage against its equations,
and the recursive RPBSIDs' convergence on an LTI system against batch PBSID.

Stages (Ni et al. 2019): the recursive VARX (Eq. 20-24), the affine projection
sign state step (Eq. 41-42), the RLS on the observability matrix (Eq. 43-46)
and the RLS for the system matrices on a state sequence (Eq. 47-55)."""

from __future__ import annotations

import numpy as np
import pytest

from identifiers import ClassicalRPBSID, ImprovedRPBSID, pbsid
from identifiers.core.rls import RecursiveLeastSquares
from identifiers.subspace.recursive import SystemRLSIdentifier
from identifiers.subspace.varx import regressor_matrix

ONES = {"input_scale": np.ones(1), "output_scale": np.ones(2)}


@pytest.fixture(scope="module")
def pole_jump(load_benchmark):
    """``benchmarks/bench_pole_jump.py``: its closed loop and eigenvalue error."""
    return load_benchmark("bench_pole_jump")


@pytest.fixture(scope="module")
def lti(pole_jump):
    """The pole-jump benchmark's closed loop before its jump: 3rd order, 1 input, 2 outputs."""
    u, y = pole_jump.closed_loop_record(0, n_samples=pole_jump.JUMP)
    return u, y


def test_varx_stage_is_exponentially_weighted_least_squares(lti):
    """Eq. 20-24 with forgetting b1 and Z_0 = I / a1, in two steps: the identifier feeds
    its VARX exactly the past windows phi_k = [z_{k-1}; ...; z_{k-p}] and targets y_k
    (the same estimate as the recursion run on those rows), and the recursion on those
    rows is the closed-form weighted least squares with the prior decaying as b1^N."""
    u, y = lti
    lam, a1, p = 0.98, 0.9, 5
    ident = ImprovedRPBSID.paper(3, p=p, **ONES)
    for k in range(400):
        ident.update(u[k], y[k])
    z = np.hstack([u[:400], y[:400]])
    phi = regressor_matrix(z, p)                   # rows k = p .. 399
    target = y[p:400]
    same = RecursiveLeastSquares(2, phi.shape[1], lam, 1.0 / a1)   # the preset's VARX
    for row, yk in zip(phi, target, strict=True):
        same.update(row, yk)
    np.testing.assert_array_equal(ident.xi, same.theta)
    plain = RecursiveLeastSquares(2, phi.shape[1], lam, 1.0 / a1, regularization=0.0)
    for row, yk in zip(phi, target, strict=True):
        plain.update(row, yk)
    w = lam ** np.arange(len(phi))[::-1]
    info = (phi * w[:, None]).T @ phi + lam ** len(phi) * a1 * np.eye(phi.shape[1])
    theta = np.linalg.solve(info, (phi * w[:, None]).T @ target).T
    np.testing.assert_allclose(plain.theta, theta, rtol=1e-8, atol=1e-10)


def test_apsa_state_step_is_equation_42(lti):
    # x_k = x_{k-1} + mu g / sqrt(g^T g + nu),  g = Gamma^T sign(tau_{k-1} - Gamma x_{k-1})
    u, y = lti
    ident = ImprovedRPBSID.paper(3, p=5, **ONES)
    for k in range(300):
        ident.update(u[k], y[k])
    x_prev, tau_prev = ident._x.copy(), ident._tau.copy()
    gamma = ident._gamma.theta.copy()
    ident.update(u[300], y[300])
    g = gamma.T @ np.sign(tau_prev - gamma @ x_prev)
    expected = x_prev + 0.01 * g / np.sqrt(g @ g + 1.0)
    np.testing.assert_allclose(ident._x, expected, rtol=1e-12, atol=1e-15)


def test_the_printed_state_step_cannot_follow_a_moving_state(lti, pole_jump):
    """Why the paper's settings cannot converge: the sign step moves the estimate by at
    most mu = 0.01 per sample (||mu g / sqrt(g^T g + nu)|| < mu), while the state of a
    system with poles 0.8-0.9 moves by about (A - I) x + B u, of the order of the signals
    (here 1); so the estimate stays near its start and every matrix regressed on it
    collapses: the identified A has its poles at 0 (eigenvalue error = the true poles'
    modulus, 0.80, identical on every seed: bench_pole_jump.py)."""
    u, y = lti
    ident = ImprovedRPBSID.paper(3, p=5, **ONES)
    steps = []
    for k in range(len(u)):
        before = None if ident._x is None else ident._x.copy()
        ident.update(u[k], y[k])
        if before is not None and ident._x is not None:
            steps.append(np.linalg.norm(ident._x - before))
    assert max(steps) < 0.01
    assert pole_jump.eigenvalue_error(ident.model.A, pole_jump.BEFORE) == \
        pytest.approx(0.8, abs=0.01)


def test_system_matrix_stage_recovers_a_known_system_from_its_states():
    # Eq. 47-55 on the true state sequence of a noise-free system: C, A and B exactly
    rng = np.random.default_rng(0)
    a = np.array([[0.9, 0.1, 0.0], [0.0, 0.7, 0.2], [0.0, -0.2, 0.7]])
    b = rng.normal(size=(3, 1))
    c = rng.normal(size=(2, 3))
    ident = ClassicalRPBSID(3, p=5, forgetting=1.0, output_init=1e-6, system_init=1e-6, **ONES)
    ident._init_sizes(1, 2)
    x = rng.normal(size=3)
    for _ in range(400):
        u = rng.normal(size=1)
        x_next = a @ x + b @ u
        ident._learn_system(x, u, c @ x, x_next)
        x = x_next
    ident._x = x
    a_id, b_id, c_id, _, _ = SystemRLSIdentifier._matrices(ident)
    np.testing.assert_allclose(c_id, c, atol=1e-6)
    np.testing.assert_allclose(a_id, a, atol=1e-6)
    np.testing.assert_allclose(b_id, b, atol=1e-6)


def _eigen_error(bench, method, u, y) -> float:
    seq = method().fit(u, y)
    return float(np.median([bench.eigenvalue_error(seq[k].A, bench.BEFORE)
                            for k in range(700, bench.JUMP, 10)]))


def test_classical_rpbsid_converges_to_within_2x_batch_pbsid(lti, pole_jump):
    u, y = lti
    batch = pole_jump.eigenvalue_error(pbsid(u[300:], y[300:], 3, 5, regularization=0.0).A,
                                       pole_jump.BEFORE)
    recursive = _eigen_error(pole_jump,
                             lambda: ClassicalRPBSID(3, p=5, forgetting=0.999, warmup=100), u, y)
    assert recursive <= max(2 * batch, 0.02), (recursive, batch)


@pytest.mark.xfail(strict=True, reason=(
    "the improved RPBSID's state comes from its own sign-step recursion and the "
    "observability matrix is regressed on it (an errors-in-variables bootstrap): with the "
    "predict step and any step size or forgetting tried (mu 0.03-1, sign, normalized and "
    "least-squares corrections, forgetting 0.98-0.995) the eigenvalue error stays at "
    "0.05-0.37 before the jump against batch PBSID's 0.008-0.02"))
def test_improved_rpbsid_converges_to_within_2x_batch_pbsid(lti, pole_jump):
    u, y = lti
    batch = pole_jump.eigenvalue_error(pbsid(u[300:], y[300:], 3, 5, regularization=0.0).A,
                                       pole_jump.BEFORE)
    recursive = _eigen_error(pole_jump,
                             lambda: ImprovedRPBSID(3, p=5, forgetting=0.999, warmup=100), u, y)
    assert recursive <= max(2 * batch, 0.02), (recursive, batch)
