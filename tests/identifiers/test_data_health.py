"""An identifier never reports healthy while it has stopped learning: each fault of the
reliability issue (auto-scales frozen on the first samples, stuck, clipped and noisier
sensors, most samples skipped, a degenerate model, an input that stopped exciting,
fit louder than update) reproduced, and the clean records that must raise nothing."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from identifiers import (
    ImprovedRPBSID,
    MomentRefitRPBSID,
    PredictorRPBSID,
    RigidFlexibleIdentifier,
    add_measurement_noise,
    default_identifier,
    identification_inputs,
)
from identifiers.core.checks import all_finite
from identifiers.core.data_monitor import WINDOW, DataMonitor
from identifiers.core.health import IdentifierHealthWarning, degenerate, state_problem
from identifiers.core.screening import _idle_and_usable
from spacecraft_conventions import STANDARD_OUTPUTS
from spacecraft_env import FlexibleSpacecraftModel

SCALES = {"input_scale": np.ones(3), "output_scale": STANDARD_OUTPUTS.scales()}


@pytest.fixture(scope="module")
def record():
    """3000 samples of the constant plant under the identification inputs: u, y (40 dB),
    clean y."""
    truth = FlexibleSpacecraftModel(scenario="constant")
    rng = np.random.default_rng(0)
    u = identification_inputs(3000, rng)
    y_clean = truth.simulate(u)[1]
    return u, add_measurement_noise(y_clean, 40, rng), y_clean


def _stream(ident, u, y):
    """Feed the record with update(); return the identifier's health warnings."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for k in range(len(u)):
            ident.update(u[k], y[k])
    return [str(w.message) for w in caught if issubclass(w.category, IdentifierHealthWarning)]


@pytest.mark.parametrize("cls", [ImprovedRPBSID, MomentRefitRPBSID, PredictorRPBSID])
def test_automatic_scales_are_taken_again_when_the_data_leave_their_level(record, cls):
    # the first p = 15 samples carry a 1e-7 N m torque: every later 1 N m sample was
    # beyond max_abs and skipped for good (1184 of 1200) while health said healthy
    u, y, _ = record
    u = u[:1200].copy()
    u[:15] *= 1e-7
    ident = cls(22)
    said = _stream(ident, u, y[:1200])
    assert ident.health.rescales == 1 and ident.n_skipped < 3 * WINDOW
    assert any("rescaled" in s for s in said)
    assert ident.health.healthy and ident.model is not None
    assert np.all(np.isfinite(ident.model.A))


def test_user_scales_that_skip_most_samples_are_reported(record):
    # fixed scales fed 1e6 N m: most samples beyond max_abs, healthy before
    u, y, _ = record
    ident = ImprovedRPBSID(22, **SCALES)
    said = _stream(ident, u[:1000] * 1e6, y[:1000])
    assert not ident.health.healthy
    assert any(f.startswith("skipping") for f in ident.health.faults)
    assert sum("skipping" in s for s in said) == 1          # warned once


@pytest.mark.parametrize(("columns", "names"), [((0,), ["attitude[0]"]),
                                                ((3, 4, 5), ["rate[0]", "rate[1]", "rate[2]"])])
def test_a_stuck_sensor_is_reported(record, columns, names):
    # roll attitude, or all three gyros, frozen from sample 1000
    u, y, _ = record
    y = y.copy()
    y[1000:, columns] = y[1000, columns]
    ident = default_identifier()
    said = _stream(ident, u[:1300], y[:1300])
    assert not ident.health.healthy
    stuck = [f for f in ident.health.faults if f.startswith("stuck")]
    assert len(stuck) == len(columns) and all(any(n in f for f in stuck) for n in names)
    assert sum("stuck" in s for s in said) == len(columns)


def test_clipped_sensors_are_reported(record):
    # every sensor clipped at 30 % of its peak (39-79 % of the samples at the limit)
    u, y, _ = record
    limit = 0.3 * np.abs(y).max(axis=0)
    ident = default_identifier()
    said = _stream(ident, u[:600], np.clip(y[:600], -limit, limit))
    assert not ident.health.healthy
    assert any(f.startswith("clipped") for f in ident.health.faults)
    assert any("clipped" in s for s in said)


def test_a_noise_level_that_jumps_100x_is_reported(record):
    u, y, y_clean = record
    y = y.copy()
    y[1500:] = y_clean[1500:] + 100 * (y[1500:] - y_clean[1500:])
    ident = default_identifier()
    before = _stream(ident, u[:1500], y[:1500])
    assert not before and ident.health.healthy
    after = _stream(ident, u[1500:1500 + 2 * WINDOW], y[1500:1500 + 2 * WINDOW])
    assert not ident.health.healthy
    assert sum("noisier" in s for s in after) >= 5                 # most of the 10 sensors


def test_an_input_that_stops_exciting_is_reported(record):
    # 8000 samples without torque: ImprovedRPBSID's yaw 50-step VAF fell from 82 to -254 %
    u, y, _ = record
    truth = FlexibleSpacecraftModel(scenario="constant")
    u = np.vstack([u[:1500], np.zeros((3000, 3))])
    y = add_measurement_noise(truth.simulate(u)[1], 40, np.random.default_rng(1))
    ident = ImprovedRPBSID(22, **SCALES)                 # memory 1 / (1 - 0.9995) = 2000
    said = _stream(ident, u, y)
    assert not ident.health.healthy
    assert any(f.startswith("unexcited") for f in ident.health.faults)
    assert sum("unexcited" in s for s in said) == 1


def test_a_degenerate_model_is_not_exported_and_health_says_so(record):
    # ImprovedRPBSID with fixed scales fed 1e6 N m ended "healthy" with max |A| = 0
    u, y, _ = record
    ident = ImprovedRPBSID(22, **SCALES)
    ident.fit(u[:1000], y[:1000])
    a, b, c, d, k = ident._matrices()
    assert ident.model is not None and ident.health.healthy
    ident._matrices = lambda: (np.zeros_like(a), b, c, d, k)
    assert ident.model is None and not ident.health.healthy
    assert ident.health.faults[0].startswith("degenerate: the model's A is zero")
    assert "C is zero" in degenerate((a, b, np.zeros_like(c), d, k))
    assert state_problem(ident, (a, b, c, d, k), None) is None


def test_fit_is_as_quiet_and_as_honest_as_update(record):
    # fit() raised under -W error (overflow in the exported state) where update was silent,
    # and returned models while model said None
    u, y, _ = record
    big = u[:1000] * 1e6
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        warnings.simplefilter("ignore", IdentifierHealthWarning)
        fitted = ImprovedRPBSID(22, **SCALES).fit(big, y[:1000])
        looped = ImprovedRPBSID(22, **SCALES)
        shown = []
        for k in range(1000):
            looped.update(big[k], y[k])
            shown.append(looped.model is not None)
    np.testing.assert_array_equal(fitted.valid, shown)


@pytest.mark.parametrize("snr", [None, 30, 60])
@pytest.mark.parametrize("scenario", ["constant", "paddle_rotation"])
def test_clean_records_raise_no_fault(scenario, snr):
    truth = FlexibleSpacecraftModel(scenario=scenario)
    rng = np.random.default_rng(2)
    u = identification_inputs(2000, rng)
    y = truth.simulate(u)[1]
    y = y if snr is None else add_measurement_noise(y, snr, rng)
    for ident in (default_identifier(), ImprovedRPBSID(22)):
        assert not _stream(ident, u, y)
        assert ident.health.healthy and not ident.health.faults and not ident.health.rescales


def test_the_monitor_clears_a_fault_when_the_data_recover():
    monitor = DataMonitor(1, 2)
    rng = np.random.default_rng(0)
    for k in range(3 * WINDOW):
        monitor.observe(rng.normal(size=1), np.array([1.0, rng.normal()]) if k >= WINDOW
                        else rng.normal(size=2), skipped=False)
    assert list(monitor.faults) == [("stuck", 0)]
    for _ in range(WINDOW):
        monitor.observe(rng.normal(size=1), rng.normal(size=2), skipped=False)
    assert not monitor.faults


@pytest.mark.parametrize("cls", [RigidFlexibleIdentifier, ImprovedRPBSID])
def test_a_health_warning_points_at_the_callers_line(record, cls):
    # attributed to the user's update(), not to a module inside the package's subpackages
    u, y, _ = record
    frozen = y[:600].copy()
    frozen[100:, 0] = frozen[100, 0]                     # a stuck attitude sensor
    ident = cls() if cls is RigidFlexibleIdentifier else cls(22, **SCALES)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for k in range(600):
            ident.update(u[k], frozen[k])
    health = [w for w in caught if issubclass(w.category, IdentifierHealthWarning)]
    assert health
    assert {w.filename for w in health} == {__file__}


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, None])
def test_all_finite_is_the_numpy_check_for_any_shape_and_layout(bad):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 5)) * 1e300
    if bad is not None:
        a[4, 3] = bad
    for view in (a, a.T, a[::2, 1:], a[4], a[:, 3], a[:0], a.ravel()):
        assert all_finite(view) == bool(np.isfinite(view).all()), view.shape
    assert all_finite(np.array([5e-324, -0.0, np.finfo(float).max]))


def test_the_compiled_screening_is_the_numpy_expressions():
    """Idle (zero input, output equal to the last bit for bit) and usable (finite and
    within max_abs) exactly as the NumPy expressions they replace, NaN, inf, -0.0 and
    the bound itself included."""
    rng = np.random.default_rng(1)
    specials = [np.nan, np.inf, -np.inf, -0.0, 0.0, 10.0, -10.0, 10.000001]
    for _ in range(2000):
        u = rng.choice([0.0, -0.0, 1.0, np.nan, 20.0], size=3)
        last = rng.choice(specials, size=4)
        y = np.where(rng.random(4) < 0.8, last, rng.choice(specials, size=4))
        for has_last in (True, False):
            idle, usable = _idle_and_usable(u, y, last, has_last, 10.0)
            assert idle == (has_last and not u.any() and np.array_equal(y, last))
            assert usable == bool(np.abs(u).max() <= 10.0 and np.abs(y).max() <= 10.0)
