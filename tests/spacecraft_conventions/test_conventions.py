"""The shared conventions: one definition of each fact, consistent everywhere."""

from __future__ import annotations

import numpy as np
import pytest

from spacecraft_conventions import (
    DEG_PER_RAD,
    NOMINAL_SCALE,
    OUTPUT_GROUPS,
    RAD_PER_DEG,
    STANDARD_OUTPUTS,
    OutputLayout,
    match_groups,
    nominal_scale,
)


def test_units_are_inverse_and_named_by_direction():
    assert RAD_PER_DEG * 180.0 == pytest.approx(np.pi, rel=1e-15)
    assert RAD_PER_DEG * DEG_PER_RAD == pytest.approx(1.0, rel=1e-15)


def test_nominal_levels_are_one_degree_a_tenth_per_second_and_a_centimetre():
    assert NOMINAL_SCALE["attitude"] == pytest.approx(np.deg2rad(1.0))
    assert NOMINAL_SCALE["rate"] == pytest.approx(np.deg2rad(0.1))
    assert NOMINAL_SCALE["deflection"] == 0.01
    with pytest.raises(ValueError, match="unknown group"):
        nominal_scale("gps")


def test_layout_slices_by_name():
    layout = OutputLayout.of(("rate", "deflection", "reference"), n_sensors=2)
    assert layout.slice("rate") == slice(0, 3)
    assert layout.slice("deflection") == slice(3, 5)
    np.testing.assert_array_equal(layout.indices("reference"), [5, 6, 7])
    np.testing.assert_array_equal(layout.sensor_indices(), [0, 1, 2, 3, 4])
    assert layout.size == 8 and "attitude" not in layout
    with pytest.raises(KeyError, match="no 'attitude' channels"):
        layout.slice("attitude")
    np.testing.assert_allclose(layout.scales()[3:5], 0.01)


def test_standard_outputs_are_the_env_default():
    assert STANDARD_OUTPUTS.names == OUTPUT_GROUPS and STANDARD_OUTPUTS.size == 10


def test_match_groups_maps_observation_rows_to_plant_rows():
    obs = OutputLayout.of(("attitude_error", "deflection", "attitude"), n_sensors=4)
    plant = STANDARD_OUTPUTS
    i, j = match_groups(obs, plant)
    np.testing.assert_array_equal(i, [3, 4, 5, 6, 7, 8, 9])
    np.testing.assert_array_equal(j, [6, 7, 8, 9, 0, 1, 2])
    with pytest.raises(ValueError, match="channels"):
        match_groups(OutputLayout.of(("deflection",), 2), plant)


@pytest.mark.parametrize("groups", [
    (("attitude", 2),), (("gps", 3),), (("rate", 3), ("rate", 3)), (), (("deflection", 0),)])
def test_bad_layouts_raise(groups):
    with pytest.raises(ValueError):
        OutputLayout(groups)
