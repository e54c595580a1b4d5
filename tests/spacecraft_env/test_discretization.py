"""The fast zero-order hold agrees with the per-step exact exponential."""

import math
import pickle

import numpy as np
import pytest
from scipy.linalg import expm

from spacecraft_env import FlexibleSpacecraftModel, ets8_parameters
from spacecraft_env.discretization import PANEL_WIDTH_DEG, AnglePanels
from spacecraft_env.scenarios import (
    CombinedScenario,
    Configuration,
    PaddleRotationScenario,
    SolarRotationScenario,
)


def _exact(model, t):
    """The per-step exact ZOH, straight from scipy (no caches)."""
    aug = model._van_loan(model.configuration(t), t)
    phi = expm(aug)
    return phi[:model.n, :model.n], phi[:model.n, model.n:]


def _relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("n_modes", [2, 5])
@pytest.mark.parametrize("scenario", [
    SolarRotationScenario(),
    PaddleRotationScenario(initial_angle_deg=-170.0, rate_deg_s=1.7),
    CombinedScenario(rotation=SolarRotationScenario(rate_deg_s=0.9, initial_angle_deg=33.0)),
])
def test_rotation_matches_exact_zoh_to_1e12(scenario, n_modes):
    model = FlexibleSpacecraftModel(ets8_parameters(n_modes=n_modes), scenario=scenario)
    assert model.n == 2 * (3 + 4 * n_modes)
    # 200 s at up to 1.7 deg/s crosses many panels, and panel boundaries
    ts = np.concatenate([np.arange(0, 2000, 37) * model.dt, [0.1, 99.9, 100.0, 180.0]])
    worst_a = worst_b = 0.0
    for t in ts:
        ad, bd = model._discrete_ab(t)
        ea, eb = _exact(model, t)
        worst_a = max(worst_a, _relative(ad, ea))
        worst_b = max(worst_b, _relative(bd, eb))
    assert worst_a < 1e-12
    assert worst_b < 1e-12


def test_at_a_node_the_interpolant_is_the_exponential():
    model = FlexibleSpacecraftModel(scenario=SolarRotationScenario(rate_deg_s=0.5))
    theta = math.radians(2 * PANEL_WIDTH_DEG)   # a panel edge is a node
    phi = model._shared.panels(Configuration(), theta)
    exact = expm(model._van_loan(Configuration(paddle_angle=theta), math.nan))[:model.n]
    # the library's exponential runs with single-threaded BLAS, scipy's here with the
    # caller's threads: equal to rounding, not bit for bit
    np.testing.assert_allclose(phi, exact, rtol=1e-12, atol=1e-12 * np.abs(exact).max())


def test_matrices_do_not_depend_on_query_order_or_cache_state():
    scenario = SolarRotationScenario(rate_deg_s=0.4, initial_angle_deg=10.0)
    forward = FlexibleSpacecraftModel(scenario=scenario)
    backward = FlexibleSpacecraftModel(scenario=scenario, cache_size=16)
    ts = np.arange(0, 600) * 0.1
    ref = [forward._discrete_ab(t)[0].copy() for t in ts]
    got = [backward._discrete_ab(t)[0].copy() for t in ts[::-1]][::-1]
    backward.clear_cache()
    again = backward._discrete_ab(ts[123])[0]
    for a, b in zip(ref, got, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(again, ref[123])


def test_episodes_with_other_rates_reuse_the_panels():
    base = FlexibleSpacecraftModel(scenario=PaddleRotationScenario())
    base.clear_cache()                  # the panels are process-wide: start from none
    for k in range(2500):
        base._discrete_ab(k * base.dt)
    built = len(base._shared.panels)
    assert built == 4   # 90 -> 182 deg (to the last 64-step block): panels at 90..180 deg
    rng = np.random.default_rng(0)
    for _ in range(3):
        other = base.with_scenario(PaddleRotationScenario(
            rate_deg_s=float(rng.uniform(0.2, 0.36))))
        assert other._shared is base._shared
        for k in range(0, 2500, 7):
            other._discrete_ab(k * other.dt)
    assert len(base._shared.panels) == built
    # a new model (a new env) of the same physics finds them too; other physics does not
    assert FlexibleSpacecraftModel(scenario="solar_rotation")._shared is base._shared
    other = FlexibleSpacecraftModel(ets8_parameters(n_modes=3), scenario="solar_rotation")
    assert other._shared is not base._shared


def test_panel_cache_is_bounded():
    n = 22
    calls = []

    def build(key, thetas):
        calls.append(key)
        return np.zeros((len(thetas), n + 3, n + 3))

    panels = AnglePanels(build, n, max_bytes=1)
    for i in range(10):
        panels((), math.radians(PANEL_WIDTH_DEG) * (i + 0.5))
    assert len(panels) == 4
    panels((), math.radians(PANEL_WIDTH_DEG) * 9.5)   # most recent: still cached
    assert len(calls) == 10


def test_pickled_model_rebuilds_its_caches():
    model = FlexibleSpacecraftModel(scenario="solar_rotation")
    a = model._discrete_ab(12.3)[0].copy()
    model.clear_cache()
    clone = pickle.loads(pickle.dumps(model))
    assert len(clone._cache) == 0 and clone._shared is model._shared
    np.testing.assert_array_equal(clone._discrete_ab(12.3)[0], a)


def test_one_configuration_along_many_angles_is_the_general_evaluation():
    """``evaluate_along`` (the rotation blocks' path) gives the general path's rows, bit
    for bit (the same panel groups, so the same products), across a panel edge."""
    model = FlexibleSpacecraftModel(scenario=SolarRotationScenario(rate_deg_s=0.5))
    panels = model._shared.panels
    edge = math.radians(PANEL_WIDTH_DEG)
    thetas = np.concatenate([edge + np.linspace(-0.01, 0.01, 63), [edge]])
    key = Configuration()
    along = panels.evaluate_along(key, thetas)
    general = panels.evaluate([key] * thetas.size, thetas)
    assert along.shape == (64, model.n, model.n + 3)
    assert np.array_equal(along, general)
    # a query of its own is another product shape: equal to rounding only
    np.testing.assert_allclose(along[0], panels(key, thetas[0]), rtol=0,
                               atol=1e-14 * np.abs(along[0]).max())
