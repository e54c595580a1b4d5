"""The control job's scenario options (CLI -> env keywords)."""

from __future__ import annotations

import argparse
import json

import pytest

from spacecraft_env import DockingScenario
from spacecraft_lab.cli import build_parser, main
from spacecraft_lab.control import (
    CONTROLLER_KEYS,
    CONTROLLER_NAMES,
    PHYSICAL,
    SCENARIO_NAMES,
    STRUCTURED_RPBSID,
    env_kwargs_for,
)


def test_capture_and_mass_centre_options_build_the_docking_scenario():
    kwargs = env_kwargs_for("docking", mass_centre_shift=True, capture_momentum=(0, 0, 50))
    scenario = kwargs["scenario"]
    assert isinstance(scenario, DockingScenario) and scenario.mass_centre_shift
    assert [m.angular_momentum for m in scenario.modules] == [(0.0, 0.0, 50.0)] * 2
    assert "scenario" not in env_kwargs_for("docking")        # the registered default
    with pytest.raises(ValueError, match="docking scenario"):
        env_kwargs_for("paddle_rotation", capture_momentum=(0, 0, 1))


@pytest.mark.parametrize("scenario", SCENARIO_NAMES)
def test_every_scenario_help_offers_runs_from_the_cli(scenario, tmp_path):
    """``spacecraft control --scenario S`` for every S that ``--help`` offers (the task
    family failed with KeyError: 'family')."""
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    offered = next(a for a in commands.choices["control"]._actions if a.dest == "scenario")
    assert scenario in offered.choices
    main(["control", "--scenario", scenario, "--seeds", "1", "--steps", "100",
          "--controllers", "robust-lqg", "--out", str(tmp_path / scenario)])
    assert (tmp_path / scenario / "metrics.json").exists()


def test_the_family_takes_no_scenario_variants():
    assert "scenario" not in env_kwargs_for("family")
    with pytest.raises(ValueError, match="module_mass does not apply"):
        env_kwargs_for("family", module_mass=900.0)


def test_a_refused_workers_value_writes_nothing(tmp_path):
    from spacecraft_lab.control import run_control

    with pytest.raises(ValueError, match="workers must be a positive integer"):
        run_control("docking", 1, tmp_path / "out", workers=0)
    assert not (tmp_path / "out").exists()


def test_the_physical_fit_option_flies_and_stays_out_of_the_default_comparison(tmp_path):
    assert PHYSICAL not in CONTROLLER_NAMES
    main(["control", "--scenario", "constant", "--seeds", "1", "--steps", "400",
          "--controllers", "adaptive-lqg-physical", "--workers", "1",
          "--out", str(tmp_path / "physical")])
    table = json.loads((tmp_path / "physical" / "metrics.json").read_text())
    assert PHYSICAL in json.dumps(table)


def test_the_adaptive_lqg_flies_the_scheduled_fit_on_the_envs_appendages():
    """``--controllers adaptive-lqg`` builds the adaptive LQG on the drive-scheduled
    physical fit that knows the env's appendages, under one name only; ``adaptive-lqg-fast``
    is the same law on the rigid-flexible identifier."""
    import gymnasium as gym

    from controllers import AdaptiveLQG, LQRWeights, scheduled_identifier
    from identifiers import ScheduledPhysicalIdentifier
    from spacecraft_lab.control import CONTROLLERS, env_id, env_kwargs_for

    env = gym.make(env_id("paddle_rotation"), **env_kwargs_for("paddle_rotation"))
    ctrl = CONTROLLERS(LQRWeights())[CONTROLLER_KEYS["adaptive-lqg"]](env)
    assert isinstance(ctrl, AdaptiveLQG)
    assert isinstance(ctrl.identifier, ScheduledPhysicalIdentifier)
    model = env.unwrapped.model
    assert ctrl.identifier.turning == tuple(model.appendage_turns)
    assert ctrl.identifier.sensor_appendage == tuple(model.sensor_appendage)
    assert any(ctrl.identifier.turning) and not all(ctrl.identifier.turning)
    # the warm-up excites at the amplitude the identifier asks for (0.5 N m), the
    # fast identifier's loop at 1 N m
    assert ctrl.excitation.warmup_amplitude == ctrl.identifier.warmup_amplitude == 0.5
    # one key per controller: no other name builds the same loop
    assert sorted(CONTROLLER_KEYS.values()) == sorted(set(CONTROLLER_KEYS.values()))
    assert "adaptive-lqg-scheduled" not in CONTROLLER_KEYS
    fast = CONTROLLERS(LQRWeights())[CONTROLLER_KEYS["adaptive-lqg-fast"]](env)
    assert fast.name == "adaptive LQG" and fast.excitation.warmup_amplitude == 1.0
    assert type(fast.identifier).__name__ == "RigidFlexibleIdentifier"
    assert CONTROLLER_KEYS["adaptive-lqg-fast"] in CONTROLLER_NAMES
    # its fit accumulates by default; the factory passes the identifier's options on
    assert ctrl.identifier.accumulate
    held = scheduled_identifier(env, accumulate=False, max_record=600)
    assert not held.accumulate and held.max_record == 600
    assert held.turning == ctrl.identifier.turning


def test_the_structured_rpbsid_option_flies_its_identified_design(tmp_path):
    """The paper's algorithm with an exact rigid block in the loop: an option, whose
    identified gains fly for most of the episode after its 30 s warm-up (not only the
    fallback; seed 0 flies the fallback until about 100 s, 27 % of the steps from 60 s
    over the whole episode)."""
    assert STRUCTURED_RPBSID not in CONTROLLER_NAMES
    main(["control", "--scenario", "docking", "--seeds", "1", "--steps", "2500",
          "--controllers", "adaptive-lqg-structured-rpbsid", "--workers", "1",
          "--out", str(tmp_path / "structured")])
    table = json.loads((tmp_path / "structured" / "metrics.json").read_text())
    (seed,) = table["controllers"][STRUCTURED_RPBSID]["per_seed"]
    assert seed["fallback_share_after_60s"] < 0.5 and seed["stable"]


def test_the_integral_settle_option_reaches_every_design_and_is_recorded(tmp_path):
    """``--integral-settle 0`` flies the LQGs with the integral at once (the law before
    its 50 s rule): the cost differs from the default's, and the metrics say which ran;
    a negative time is refused before anything is written."""
    from controllers.lqg import INTEGRAL_SETTLE_S
    from spacecraft_lab.control import run_control

    def cost(settle, name):
        metrics = run_control("docking", 1, tmp_path / name, controllers=["oracle-lqg"],
                              steps=1500, progress=False, workers=1,
                              integral_settle_s=settle)
        return metrics["integral_settle_s"], \
            metrics["controllers"]["oracle LQG"]["per_seed"][0]["cost_after_100s"]

    default_settle, default_cost = cost(None, "default")
    at_once_settle, at_once_cost = cost(0.0, "at-once")
    assert default_settle == INTEGRAL_SETTLE_S and at_once_settle == 0.0
    assert at_once_cost != pytest.approx(default_cost, rel=1e-3)
    with pytest.raises(ValueError, match="settle_s"):
        run_control("docking", 1, tmp_path / "bad", integral_settle_s=-1.0)
    assert not (tmp_path / "bad").exists()
    with pytest.raises(SystemExit):
        build_parser().parse_args(["control", "--integral-settle", "-1"])


#: One of every fault kind, each after the adaptive loop's first model (40 s), on its own
#: axis or sensor group, in the command line's form.
EVERY_FAULT = ("loss_of_effectiveness,onset=41,axis=0,value=0.1",
               "stuck_actuator,onset=42,axis=1,value=0.2",
               "actuator_bias,onset=43,axis=2,value=0.05",
               "sensor_dropout,onset=44,duration=2,group=attitude",
               "stuck_sensor,onset=46,duration=2,group=deflection,axis=1",
               "sensor_bias,onset=48,group=rate,axis=2,value=1.75e-4",
               "noise_burst,onset=49,duration=3,group=rate,value=1e-4")


def test_every_fault_flies_from_the_command_without_a_crash(tmp_path, capsys):
    """``spacecraft control --fault ...`` with every kind at once: the adaptive loop, the
    oracle and the ceiling fly through them to the end, and metrics.json records them."""
    out = tmp_path / "faults"
    args = ["control", "--scenario", "paddle_rotation", "--seeds", "1", "--steps", "560",
            "--workers", "1", "--controllers", "adaptive-lqg", "oracle-lqg", "ceiling",
            "--out", str(out)]
    for fault in EVERY_FAULT:
        args += ["--fault", fault]
    assert main(args) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert [f["kind"] for f in metrics["faults"]] == [f.split(",")[0] for f in EVERY_FAULT]
    for name, row in metrics["controllers"].items():
        assert row["verdicts"].get("diverged", 0) == 0, name
        assert row["per_seed"][0]["cost"] > 0, name
    assert "ceiling" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        build_parser().parse_args(["control", "--fault", "gremlin,onset=3"])


def test_process_noise_and_the_resting_start_reach_the_env():
    kwargs = env_kwargs_for("constant", task="regulation", initial_attitude=0.0,
                            disturbance_std=0.01)
    assert kwargs["disturbance_std"] == 0.01 and kwargs["initial_attitude_deg"] == 0.0
    assert "disturbance_std" not in env_kwargs_for("constant")
    with pytest.raises(ValueError, match="regulation task"):
        env_kwargs_for("constant", task="slew", initial_attitude=1.0)


def test_the_terminal_table_fits_in_100_columns():
    """The brief of the default comparison (its longest names, ten seeds' verdicts) within
    100 columns; the full table goes to table.md."""
    from functools import partial

    import gymnasium as gym

    from controllers import PD, compare
    from spacecraft_env import env_id
    from spacecraft_lab.reporting import control_brief

    table, _ = compare({name: PD for name in CONTROLLER_NAMES},
                       partial(gym.make, env_id("constant"), max_episode_steps=30),
                       list(range(10)), progress=False)
    lines = control_brief(table).splitlines()
    assert len(lines) == 1 + len(CONTROLLER_NAMES) and max(map(len, lines)) <= 100
