"""The control job's scenario options (CLI -> env keywords)."""

from __future__ import annotations

import pytest

from spacecraft_env import DockingScenario
from spacecraft_lab.control import env_kwargs_for


def test_capture_and_mass_centre_options_build_the_docking_scenario():
    kwargs = env_kwargs_for("docking", mass_centre_shift=True, capture_momentum=(0, 0, 50))
    scenario = kwargs["scenario"]
    assert isinstance(scenario, DockingScenario) and scenario.mass_centre_shift
    assert [m.angular_momentum for m in scenario.modules] == [(0.0, 0.0, 50.0)] * 2
    assert "scenario" not in env_kwargs_for("docking")        # the registered default
    with pytest.raises(ValueError, match="docking scenario"):
        env_kwargs_for("paddle_rotation", capture_momentum=(0, 0, 1))
