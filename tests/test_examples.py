"""Every script in examples/ runs, at a small budget (so the examples cannot rot)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Script -> arguments that keep its run short.
SMALL = {
    "env_rollout.py": [],
    "identifiability_study.py": [],
    "streaming_identification.py": ["--steps", "800"],
    "custom_controller.py": ["--seeds", "1", "--steps", "1100"],
    "render_video.py": ["--steps", "60", "--every", "20", "--out", "video.gif"],
    "sweep.py": ["--seeds", "1", "--steps", "1100", "--out", "sweep", "--backend", "serial"],
    "train_ppo_family.py": ["--timesteps", "2000", "--episodes", "1"],
    "residual_rl.py": ["--timesteps", "2000"],
    "rigid_gain_tolerance.py": ["--samples", "600"],
}


def test_every_example_is_listed():
    assert {p.name for p in (ROOT / "examples").glob("*.py")} == set(SMALL)


@pytest.mark.parametrize("script", sorted(SMALL))
def test_example_runs(script, tmp_path):
    if script in ("train_ppo_family.py", "residual_rl.py"):
        pytest.importorskip("stable_baselines3")
    done = subprocess.run([sys.executable, str(ROOT / "examples" / script), *SMALL[script]],
                          capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip()
