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


def test_training_logs_monitor_and_evaluation_metrics_to_tensorboard(tmp_path):
    pytest.importorskip("stable_baselines3")
    event_accumulator = pytest.importorskip(
        "tensorboard.backend.event_processing.event_accumulator")
    # randomized docking with the oracle features: short episodes so Monitor closes some
    m = run_training("ppo", "oracle", 2048, 1, tmp_path / "out", eval_every=2048,
                     progress=False, randomize=True, tensorboard=str(tmp_path / "tb"))
    assert m["randomize"] and np.isfinite(m["final_vibration_rms_mm"])
    assert 0.0 <= m["runs"][0]["final"]["stable_share"] <= 1.0
    (run,) = (tmp_path / "tb").iterdir()
    acc = event_accumulator.EventAccumulator(str(run))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    assert {"eval/attitude_rms_deg", "eval/vibration_rms_mm", "eval/return",
            "eval/stable_share"} <= tags
    assert "time/fps" in tags
    # the comparison table and figure read the run back
    from spacecraft_lab.plots import plot_rl_comparison
    from spacecraft_lab.reporting import rl_table

    table = rl_table([tmp_path / "out"])
    assert "| PPO | oracle | randomized docking | 2,048 | 1 |" in table
    assert "| fixed LQG |" in table and "| adaptive LQG |" in table
    assert "| zero torque |" in table
    plot_rl_comparison(tmp_path / "cmp.png", [m])
    assert (tmp_path / "cmp.png").stat().st_size > 10_000
