"""Change tests: they fire after a jump and stay quiet without one."""

from __future__ import annotations

import numpy as np
import pytest

from identifiers import InnovationCUSUM, RegressionGLR
from identifiers.core.change_detection import misfit_confirms_change

THETA = np.array([[1.0, 0.5, -0.3], [0.2, -1.0, 0.4], [0.0, 0.3, 0.8]])


def _regression(jump_at: int | None, n: int = 4000, seed: int = 0):
    """Three regressors, three outputs (as the rigid gain: torques to rates)."""
    rng = np.random.default_rng(seed)
    phi = rng.normal(size=(n, 3))
    y = phi @ THETA.T
    if jump_at is not None:
        y[jump_at:] = phi[jump_at:] @ (1.2 * THETA).T
    return phi, y + 0.05 * rng.normal(size=y.shape)


def _run_glr(phi, y):
    """The GLR watching an estimate frozen at the truth before the jump."""
    glr = RegressionGLR(threshold=6.0, dt=0.1)
    for k in range(len(phi)):
        glr.update(phi[k], y[k] - THETA @ phi[k], np.full(3, 0.05**2), sample=k)
    return glr.events


@pytest.mark.parametrize("seed", range(5))
def test_glr_is_quiet_without_a_change(seed):
    assert _run_glr(*_regression(None, seed=seed)) == []


def test_glr_detects_a_twenty_percent_gain_jump_within_a_second():
    events = _run_glr(*_regression(2000))
    assert events and 2000 <= events[0].sample <= 2010
    assert events[0].time == pytest.approx(events[0].sample * 0.1)


def test_cusum_detects_a_growth_of_the_innovations():
    rng = np.random.default_rng(1)
    cusum = InnovationCUSUM(threshold=40.0, dt=0.1)
    s = np.eye(2)
    for k in range(3000):
        e = rng.normal(size=2) * (1.0 if k < 2000 else 2.0)
        cusum.update(e, s)
    assert cusum.events and 2000 <= cusum.events[0].sample < 2100


@pytest.mark.parametrize("make", [lambda: RegressionGLR(window=1.0),
                                  lambda: RegressionGLR(threshold=0.5),
                                  lambda: InnovationCUSUM(threshold=-1.0)])
def test_bad_parameters(make):
    with pytest.raises(ValueError):
        make()


def test_a_refit_confirms_a_change_only_by_a_clear_margin_over_the_floor():
    """Excess misfits (above the floor) of 10 against 4 confirm at the factor 2, 7 against
    4 do not; at a misfit all noise the margin of three standard errors decides."""
    assert misfit_confirms_change(11.0, 5.0, 1.0, 10**8)
    assert not misfit_confirms_change(8.0, 5.0, 1.0, 10**8)
    # all noise: n = 3000 residuals -> margin 3 sqrt(2/3000) = 0.0775 of the floor
    assert not misfit_confirms_change(1.15, 1.0, 1.0, 3000)
    assert misfit_confirms_change(1.16, 1.0, 1.0, 3000)
    assert not misfit_confirms_change(1.0, 0.9, 1.0, 3000)     # a refit below the floor
    # the same verdicts on data with no noise at all, at any scale
    for scale in (1e-9, 1.0, 1e6):
        assert misfit_confirms_change(2.1 * scale, scale, 0.0, 3000)
        assert not misfit_confirms_change(1.9 * scale, scale, 0.0, 3000)
    assert misfit_confirms_change(np.inf, 1.0, 1.0, 3000)        # a held model that broke
    assert not misfit_confirms_change(1.0, np.nan, 1.0, 3000)


@pytest.mark.parametrize("args", [(1.0, 1.0, -1.0, 10), (1.0, 1.0, 1.0, 0),
                                  (1.0, 1.0, 1.0, 10, 1.0)])
def test_confirmation_refuses_bad_arguments(args):
    with pytest.raises(ValueError, match="factor > 1"):
        misfit_confirms_change(*args)
