"""Modal building blocks: resonator sampling, the high-pass, the filter bank, mode search."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from identifiers import ModalFilterBank, Resonator, discover_resonators, merge_resonators
from identifiers.core.modal_basis import HighPass, mode_zoh


def test_mode_zoh_is_the_exact_sample_of_the_oscillator():
    f, zeta, dt = 0.3, 0.05, 0.1
    a, b = mode_zoh(f, zeta, dt)
    w = 2 * np.pi * f
    ac = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])
    np.testing.assert_allclose(a, expm(ac * dt), atol=1e-14)
    # b = int_0^dt e^{A s} ds [0; 1] = A^-1 (e^{A dt} - I) [0; 1]
    np.testing.assert_allclose(b, np.linalg.solve(ac, a - np.eye(2))[:, 1], atol=1e-14)


def test_highpass_removes_constants_and_ramps():
    hp = HighPass(2, 0.9)
    t = np.arange(400.0)
    x = np.stack([3.0 + 0.0 * t, -2.0 + 0.5 * t], axis=1)
    out = np.array([hp(row) for row in x])
    assert np.abs(out[200:]).max() < 1e-6


def test_filter_bank_regressors_reproduce_a_rigid_flexible_response_exactly():
    """y = g * (double integral) + sum_i c_i q_i: least squares on the bank's
    regressors recovers g and the couplings to rounding."""
    rng = np.random.default_rng(1)
    res = [Resonator(0.2, 0.02), Resonator(0.7, 0.01)]
    bank = ModalFilterBank(res, 0.1)
    u = rng.normal(size=(800, 3))
    rows = []
    for uk in u:
        rows.append(bank.regressor())
        bank.step(uk)
    x = np.array(rows)
    coef = rng.normal(size=bank.size)
    coef[bank.slices["free"]] = 0.0
    y = x @ coef
    est = np.linalg.lstsq(x[1:], y[1:], rcond=None)[0]
    np.testing.assert_allclose(est[:bank.slices["free"].start],
                               coef[:bank.slices["free"].start], rtol=1e-8, atol=1e-10)


def test_merge_groups_close_modes_and_keeps_the_heaviest_within_budget():
    merged = merge_resonators([0.0874, 0.0894, 0.09, 0.2364, 0.5], [0.01] * 5,
                              weights=[1.0, 0.5, 0.5, 0.01, 0.3], resolution=0.012, budget=3)
    # 0.0894 and 0.09 (0.7 % apart) share a rank-2 resonator; 0.2364 is the lightest
    assert [(round(r.frequency_hz, 4), r.rank) for r in merged] == [(0.0874, 1), (0.0897, 2)]


def test_discovery_finds_two_well_separated_modes():
    rng = np.random.default_rng(2)
    dt = 0.1
    freqs = (0.15, 0.6)
    bank = ModalFilterBank([Resonator(f, 0.02) for f in freqs], dt)
    u = rng.normal(size=(1500, 3))
    y = np.empty((1500, 4))
    mix = rng.normal(size=(bank.size, 4))
    mix[bank.slices["free"]] = mix[bank.slices["step"]] = mix[bank.slices["ramp"]] = 0.0
    mix[:6] = 0.0
    for k, uk in enumerate(u):
        y[k] = bank.regressor() @ mix
        bank.step(uk)
    y += 1e-3 * y.std(0) * rng.normal(size=y.shape)
    found = discover_resonators(u, y, budget=4, dt=dt)
    got = sorted(r.frequency_hz for r in found)
    for f in freqs:
        assert min(abs(g / f - 1) for g in got) < 0.01


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"frequency_hz": 0.0, "damping": 0.1}, "frequency"),
    ({"frequency_hz": 1.0, "damping": 1.0}, "damping"),
    ({"frequency_hz": 1.0, "damping": 0.1, "rank": 4}, "rank"),
])
def test_bad_resonators(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Resonator(**kwargs)
