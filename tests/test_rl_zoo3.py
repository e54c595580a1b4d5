"""Third-party use: rl-zoo3 trains on our registered ids with the shipped hyperparameters."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import gymnasium as gym
import pytest

pytest.importorskip("rl_zoo3")

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "rl_zoo3"


@pytest.mark.parametrize(("algo", "steps"), [("ppo", 2000), ("sac", 300)])
def test_rl_zoo3_trains_with_the_shipped_hyperparameters(tmp_path, algo, steps):
    env_id = "FlexibleSpacecraftDocking-v1"
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", env_id,
           "--gym-packages", "spacecraft_env", "-conf", str(CONFIGS / f"{algo}.yml"),
           "-n", str(steps), "-f", str(tmp_path), "--eval-freq", "-1", "--seed", "0",
           "--env-kwargs", "reward:'bounded'"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    run = tmp_path / algo / f"{env_id}_1"
    assert (run / f"{env_id}.zip").is_file()
    assert (run / env_id / "vecnormalize.pkl").is_file()          # normalization is on
    # the policy saw the identified-model features: its input is wider than the raw env's
    with zipfile.ZipFile(run / f"{env_id}.zip") as archive:
        data = json.loads(archive.read("data"))
    raw = gym.make(f"spacecraft_env:{env_id}").observation_space.shape[0]
    assert data["observation_space"]["_shape"][0] > raw
    # the run used the shipped decision period and the bounded reward
    assert "ActionRepeat" in (run / env_id / "config.yml").read_text()
    assert "bounded" in (run / env_id / "args.yml").read_text()
