"""Third-party use: rl-zoo3 trains on our registered ids with the shipped hyperparameters,
through the user guide's own command (docs/guide.md)."""

from __future__ import annotations

import ast
import json
import re
import shlex
import subprocess
import sys
import zipfile
from pathlib import Path

import gymnasium as gym
import pytest

import spacecraft_env  # noqa: F401  (registers the environments)

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs" / "rl_zoo3"


def readme_command() -> list[str]:
    """The rl-zoo3 command of the user guide's 'Third-party agents' section, as argv."""
    text = (ROOT / "docs" / "guide.md").read_text()
    section = text[text.index("## Third-party agents (rl-zoo3)"):]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return shlex.split(block.replace("\\\n", " "))


def env_kwargs(argv: list[str]) -> dict:
    """``--env-kwargs key:value ...`` parsed as rl-zoo3 does (values are Python literals)."""
    start = argv.index("--env-kwargs") + 1
    values = {}
    for item in argv[start:]:
        if item.startswith("-"):
            break
        key, value = item.split(":", 1)
        values[key] = ast.literal_eval(value)
    return values


def test_the_readme_command_trains_on_the_documented_task():
    """The README's command passes the env the docs' task: the family, the slew task and
    the bounded reward, with the identifier's physical estimates appended."""
    from spacecraft_lab.training import ACTION_REPEAT, HYPERPARAMETERS

    argv = readme_command()
    assert argv[:3] == ["python", "-m", "rl_zoo3.train"]
    assert argv[argv.index("--env") + 1] == "FlexibleSpacecraftFamily-v2"
    assert env_kwargs(argv) == {"task": "slew", "reward": "bounded"}
    env = gym.make("FlexibleSpacecraftFamily-v2", **env_kwargs(argv))
    assert env.unwrapped.task == "slew" and env.unwrapped.reward == "bounded"
    assert "inertia_scale" in env.reset(seed=0)[1]["plant"]        # a drawn plant
    config = (CONFIGS / "ppo.yml").read_text()
    assert "controllers.features.PhysicalFeatures" in config
    assert f"repeat: {ACTION_REPEAT}" in config
    assert str(HYPERPARAMETERS["ppo"]["policy_kwargs"]["log_std_init"]) in config


# SAC (19 s) runs with -m slow: PPO checks the same hyperparameter files and registration
@pytest.mark.parametrize(("algo", "steps"),
                         [("ppo", 2000), pytest.param("sac", 300, marks=pytest.mark.slow)])
def test_rl_zoo3_trains_with_the_shipped_hyperparameters(tmp_path, algo, steps):
    pytest.importorskip("rl_zoo3")
    env_id = "FlexibleSpacecraftFamily-v2"
    argv = readme_command()
    argv[argv.index("--algo") + 1] = algo
    argv[argv.index("-conf") + 1] = str(CONFIGS / f"{algo}.yml")
    cmd = [sys.executable, *argv[1:], "-n", str(steps), "-f", str(tmp_path),
           "--eval-freq", "-1", "--seed", "0"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    run = tmp_path / algo / f"{env_id}_1"
    assert (run / f"{env_id}.zip").is_file()
    assert (run / env_id / "vecnormalize.pkl").is_file()          # normalization is on
    # the policy saw the physical features: its input is wider than the raw env's
    with zipfile.ZipFile(run / f"{env_id}.zip") as archive:
        data = json.loads(archive.read("data"))
    raw = gym.make(f"spacecraft_env:{env_id}", task="slew").observation_space.shape[0]
    from controllers.features import PHYSICAL_FEATURE_NAMES

    assert data["observation_space"]["_shape"][0] == raw + len(PHYSICAL_FEATURE_NAMES)
    # the run used the shipped decision period and the README's env arguments
    assert "ActionRepeat" in (run / env_id / "config.yml").read_text()
    args = (run / env_id / "args.yml").read_text()
    assert "bounded" in args and "slew" in args
