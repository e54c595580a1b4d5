"""Every input bounded before work starts, and storage that fails early and clearly: each
fault of the reliability issue's "unbounded inputs" and "storage faults" reproduced, and
checked to end in one line naming the field (or file) and what is wrong."""

from __future__ import annotations

import errno
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from PIL import Image

from controllers import PD, AdaptiveLQG, FixedLQG, Trajectory, run_episode
from spacecraft_env import (
    PARAMETER_LIMITS,
    DockingModule,
    FlexibleSpacecraftEnv,
    PlantDraw,
    SolarRotationScenario,
    TaskFamily,
    check_parameter,
)
from spacecraft_lab.cli import main
from spacecraft_lab.demo import MAX_GIF_FRAMES, run_demo
from spacecraft_lab.reporting import rl_table
from spacecraft_lab.sweeps import ResultStore, load_config


def _error_line(capsys, argv: list[str]) -> str:
    """Run the CLI in this process; the one stderr line of its exit-2 error."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "Traceback" not in "\n".join(err) and "error:" in err[-1]
    return err[-1]


# ----------------------------------------------------------------- one table of ranges
def test_every_limit_refuses_bools_strings_and_out_of_range_values():
    for key, limit in PARAMETER_LIMITS.items():
        assert check_parameter(key, limit.high) == limit.high
        for bad in (True, "1", limit.high * 10 + 1, float("nan"), [limit.high]):
            with pytest.raises(ValueError, match=rf"^{key} must be "):
                check_parameter(key, bad)
    with pytest.raises(ValueError, match=r"max_steps must be an integer in \[1, 1e\+07\]"):
        check_parameter("max_steps", 150.7)
    assert check_parameter("max_steps", 150.0) == 150


@pytest.mark.parametrize(("argv", "expected"), [
    ("control --actuator-delay 100000000", "must be an integer in [0, 100] steps"),
    ("control --rotation-rate 11", "must be a number in [-10, 10] deg/s"),
    ("control --steps 100000000", "must be an integer in [100, 10000000]"),
    ("demo --steps 10000000", "must be an integer in [1, 100000]"),
    ("control --disturbance-torque 1e9", "[-100, 100] N m"),
    ("train --envs 0", "must be an integer in [1, 64]"),
    ("train --envs 1000", "must be an integer in [1, 64]")])
def test_cli_refuses_unbounded_values(capsys, argv, expected):
    assert expected in _error_line(capsys, argv.split())


def test_env_scenarios_and_family_share_the_ranges():
    with pytest.raises(ValueError, match="actuator_delay_steps must be an integer in"):
        FlexibleSpacecraftEnv("docking", actuator_delay_steps=100_000_000)
    with pytest.raises(ValueError, match="rate_deg_s must be a number in"):
        SolarRotationScenario(rate_deg_s=1e6)
    with pytest.raises(ValueError, match="initial_angle_deg must be a number in"):
        SolarRotationScenario(initial_angle_deg=1e300)
    with pytest.raises(ValueError, match="inertia_scale must be a number in"):
        PlantDraw(inertia_scale=1e300)
    with pytest.raises(ValueError, match="paddle_rate_deg_s must be a number in"):
        PlantDraw(paddle_rate_deg_s=1e6)
    with pytest.raises(ValueError, match="inertia_scale must be a number in"):
        TaskFamily(inertia_scale=(0.5, 1e300))
    with pytest.raises(ValueError, match="mass must be a number in"):
        DockingModule(mass=1e300)


@pytest.mark.parametrize("plant", ["m=2", 3, [1, 2]])
def test_the_family_plant_option_of_the_wrong_type_is_named(plant):
    env = gym.make("FlexibleSpacecraftFamily-v2")
    with pytest.raises(ValueError, match=r"^plant must be a mapping with keys from"):
        env.reset(seed=0, options={"plant": plant})


@pytest.mark.parametrize("obs", ["abc", np.array(["1"] * 10), [str(v) for v in range(10)],
                                 np.zeros(10, dtype=object)])
@pytest.mark.parametrize("controller", [PD, FixedLQG, AdaptiveLQG])
def test_a_controller_refuses_a_non_numeric_observation(obs, controller):
    env = gym.make("FlexibleSpacecraftPaddleRotation-v2")
    _, info = env.reset(seed=0)
    with pytest.raises(TypeError, match="observation must be a real numeric array"):
        controller(env).act(obs, info)


# ----------------------------------------------------------------- sweep files
def _sweep_file(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(("params", "expected"), [
    ("{controller: pd, snr_db: -7000}", "snr_db must be a number in [-40, 300] dB"),
    ("{controller: pd, max_torque: 1.0e300}", "max_torque must be a number in (0, 10000]"),
    ("{controller: pd, scenario: solar_rotation, rotation_rate: 1.0e9}",
     "rotation_rate must be a number in [-10, 10] deg/s, got 1000000000.0"),
    ("{controller: pd, max_steps: true}", "max_steps must be an integer"),
    ("{controller: pd, max_steps: 150.7}", "max_steps must be an integer"),
    ("{controller: pd, actuator_delay_steps: 5}", "takes no parameter")])
def test_a_sweep_file_out_of_range_fails_before_any_task(tmp_path, params, expected):
    path = _sweep_file(tmp_path, "s.yaml", f"task: control\nseeds: [0]\nparams: {params}\n")
    with pytest.raises(ValueError) as exc:
        load_config(path)
    assert expected in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize(("name", "text"), [
    ("d.yaml", "task: control\nseeds: [0]\nseeds: [0, 1, 2]\nparams: {controller: pd}\n"),
    ("d.json", '{"task": "control", "seeds": [0], "seeds": [0, 1], '
               '"params": {"controller": "pd"}}')])
def test_a_duplicate_key_in_a_sweep_file_is_refused(tmp_path, name, text):
    with pytest.raises(ValueError, match="duplicate key") as exc:
        load_config(_sweep_file(tmp_path, name, text))
    assert "seeds" in str(exc.value) and "\n" not in str(exc.value)


# ----------------------------------------------------------------- demo memory
def test_the_demo_keeps_a_bounded_number_of_frames(tmp_path):
    run_demo("constant", tmp_path, steps=2 * MAX_GIF_FRAMES + 40, gif_every=1)
    with Image.open(tmp_path / "rollout.gif") as gif:
        assert gif.n_frames <= MAX_GIF_FRAMES
    with pytest.raises(ValueError, match="steps must be an integer in"):
        run_demo("constant", tmp_path, steps=10**9)


# ----------------------------------------------------------------- storage
SMOKE = "task: control\nseeds: [0]\nparams: {controller: pd, max_steps: 100}\n"


def test_a_dry_run_or_a_refused_file_creates_nothing(tmp_path, capsys):
    good = _sweep_file(tmp_path, "ok.yaml", SMOKE)
    assert main(["sweep", "--config", str(good), "--out", str(tmp_path / "dry"),
                 "--dry-run"]) == 0
    assert not (tmp_path / "dry").exists()
    bad = _sweep_file(tmp_path, "bad.yaml", SMOKE.replace("100}", "150.7}"))
    _error_line(capsys, ["sweep", "--config", str(bad), "--out", str(tmp_path / "refused")])
    assert not (tmp_path / "refused").exists()


def test_a_results_file_that_is_a_directory_fails_before_any_work(tmp_path, capsys):
    (tmp_path / "out" / "results.jsonl").mkdir(parents=True)
    line = _error_line(capsys, ["sweep", "--config", str(_sweep_file(tmp_path, "s.yaml", SMOKE)),
                                "--out", str(tmp_path / "out")])
    assert "results.jsonl is not a file" in line
    assert not (tmp_path / "out" / "sweep.json").exists()


def test_an_unwritable_results_file_is_found_before_any_work(tmp_path):
    store = ResultStore(tmp_path / "results.jsonl")
    (tmp_path / "results.jsonl").symlink_to(tmp_path / "missing" / "results.jsonl")
    with pytest.raises(ValueError, match=r"cannot write to .*results.jsonl"):
        store.check_writable()


def test_a_full_disk_during_a_sweep_is_one_line_and_says_how_to_resume(tmp_path, capsys,
                                                                       monkeypatch):
    def full(self, record):
        raise OSError(errno.ENOSPC, "No space left on device", str(self.path))

    monkeypatch.setattr(ResultStore, "append", full)
    line = _error_line(capsys, ["sweep", "--config", str(_sweep_file(tmp_path, "s.yaml", SMOKE)),
                                "--out", str(tmp_path / "out"), "--backend", "serial"])
    assert "No space left on device" in line and "run the same command again to resume" in line


def _metrics(tmp_path: Path, text: str) -> Path:
    run = tmp_path / "run"
    run.mkdir(exist_ok=True)
    (run / "metrics.json").write_text(text)
    return run


@pytest.mark.parametrize(("text", "expected"), [
    ('{"algo": "ppo", "feat', "cannot read a training run's metrics"),
    ('{"algo": "ppo"}', "'features' missing"),
    ('{"algo": "ppo", "features": "none", "scenario": "docking", "timesteps": "1e5", '
     '"target_attitude_rms_deg": 1.0, "runs": []}', "'timesteps' missing or not an integer"),
    ('[1, 2]', "not a JSON object")])
def test_rl_table_names_the_file_and_what_is_wrong(tmp_path, capsys, text, expected):
    run = _metrics(tmp_path, text)
    with pytest.raises(ValueError) as exc:
        rl_table([run])
    assert str(run / "metrics.json") in str(exc.value) and expected in str(exc.value)
    assert expected in _error_line(capsys, ["rl-table", str(run)])


@pytest.fixture(scope="module")
def saved_trajectory(tmp_path_factory) -> Path:
    env = gym.make("FlexibleSpacecraftPaddleRotation-v2")
    path = tmp_path_factory.mktemp("traj") / "t.npz"
    return run_episode(env, PD(env), seed=0, max_steps=50).save(path)


@pytest.mark.parametrize(("fault", "expected"), [
    ("truncated", "BadZipFile"), ("empty", "EOFError"),
    ("flipped", "not a trajectory written by Trajectory.save"),
    ("foreign", "missing time"), ("npy", "not an .npz archive"),
    ("inconsistent", "arrays of different lengths")])
def test_a_bad_trajectory_file_is_named_with_what_is_wrong(tmp_path, saved_trajectory, fault,
                                                           expected):
    data = saved_trajectory.read_bytes()
    path = tmp_path / "bad.npz"
    if fault == "truncated":
        path.write_bytes(data[:len(data) // 2])
    elif fault == "empty":
        path.write_bytes(b"")
    elif fault == "flipped":
        path.write_bytes(data[:200] + bytes([data[200] ^ 0xFF]) + data[201:])
    elif fault == "foreign":
        np.savez(path, a=np.ones(3))
    elif fault == "npy":
        path = tmp_path / "bad.npy"
        np.save(path, np.ones(3))
    else:
        arrays = dict(np.load(saved_trajectory))
        arrays["actions"] = arrays["actions"][:-5]
        np.savez(path, **arrays)
    with pytest.raises(ValueError) as exc:
        Trajectory.load(path)
    assert str(path) in str(exc.value) and expected in str(exc.value)
    assert len(Trajectory.load(saved_trajectory).time) == 50
    assert json.loads(json.dumps(Trajectory.load(saved_trajectory).controller_stats)) is not None


def test_training_without_the_rl_extra_names_it_before_any_work(tmp_path, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "torch" else real(name, *a))
    line = _error_line(capsys, ["train", "--timesteps", "10", "--out", str(tmp_path / "t")])
    assert "the 'rl' extra (torch not installed)" in line and "make test" in line
    assert not (tmp_path / "t").exists()


@pytest.mark.parametrize(("kwargs", "error", "expected"), [
    ({"max_steps": 0}, ValueError, "max_steps must be an integer >= 1"),
    ({"max_steps": 10.5}, ValueError, "max_steps must be an integer >= 1"),
    ({"radius_every": 0}, ValueError, "radius_every must be an integer >= 1"),
    ({"seed": -1}, ValueError, "seed must be an integer >= 0"),
    ({"seed": "0"}, ValueError, "seed must be an integer >= 0"),
    # an explicit id: an object's default repr (its address) differs between processes,
    # and pytest-xdist's workers must collect the same test ids
    pytest.param({"controller": object()}, TypeError, "controller must have act",
                 id="controller-without-act"),
    ({"env": "FlexibleSpacecraft-v2"}, TypeError, "env must be a gymnasium.Env")])
def test_run_episode_checks_its_arguments(kwargs, error, expected):
    env = gym.make("FlexibleSpacecraft-v2")
    args = {"env": env, "controller": PD(env), **kwargs}
    with pytest.raises(error, match=expected):
        run_episode(**args)


def test_small_api_faults_found_while_documenting():
    from controllers import OracleLQR
    from identifiers import observability_basis, persistence_predictions, prediction_vaf
    from spacecraft_lab.sweeps import execute
    from spacecraft_lab.sweeps.backends import RayBackend

    with pytest.raises(ValueError, match="horizons must be integers >= 1"):
        persistence_predictions(np.zeros((5, 2)), [0])
    y = np.arange(10.0).reshape(5, 2)
    pred = y.copy()
    pred[:2] = np.nan                                   # the model did not exist yet
    assert np.all(prediction_vaf(y, {1: pred})[1] == 100.0)
    pred[3, 0] = np.nan                                 # a broken model's row is kept
    assert prediction_vaf(y, {1: pred})[1][0] == -np.inf
    with pytest.raises(ValueError, match="a task needs 'task_id'"):
        execute({"kind": "control", "params": {}})
    env = gym.make("FlexibleSpacecraft-v2")
    _, info = env.reset(seed=0)
    with pytest.raises(ValueError, match="'state' and 'time'"):
        OracleLQR(env).act(np.zeros(10), {"state": info["state"]})
    with pytest.raises(ValueError, match="num_cpus must be a positive integer"):
        RayBackend(num_cpus=True)
    with pytest.raises(ValueError, match="c \\(m, n\\) with m >= 1"):
        observability_basis(np.eye(2), np.zeros((0, 2)))
