"""The RL training job (stable-baselines3)."""

from __future__ import annotations

import numpy as np
import pytest

from spacecraft_lab.training import run_training


def test_training_job_writes_model_curves_and_metrics(tmp_path):
    pytest.importorskip("stable_baselines3")
    m = run_training("ppo", "none", 2048, 1, tmp_path, eval_every=2048, progress=False)
    assert (tmp_path / "ppo-none-seed0.zip").exists()
    assert (tmp_path / "learning_curves.png").exists()
    assert m["runs"][0]["curve"] and np.isfinite(m["final_attitude_rms_deg"])
    with pytest.raises(ValueError):
        run_training("dqn", "none", 10, 1, tmp_path)
