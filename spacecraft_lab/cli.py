"""The project's command line: ``spacecraft <command>``.

Commands
--------
``demo``
    Rendered rollout of a scenario (:func:`spacecraft_lab.demo.run_demo`).
``identify``
    The paper's identification experiment for every method
    (:func:`spacecraft_lab.identification.run_identification`).
``control``
    Fixed, robust and scheduled LQG, PD, adaptive LQG and the oracles
    compared in closed loop (:func:`spacecraft_lab.control.run_control`).
``train``
    stable-baselines3 agents with or without identified-model features
    (:func:`spacecraft_lab.training.run_training`); ``rl-table`` tabulates runs.
``evaluate``
    A saved agent (or one the repository ships) beside the LQGs on any
    episodes (:func:`spacecraft_lab.agents.evaluate_agent`).
``adapt``
    What the identifier is worth to an agent: a policy trained on the true
    plant's parameters flown with them, with their estimate from the
    identifier and with the nominal ones
    (:func:`spacecraft_lab.adaptation.run_adaptation`).
``sweep``
    A grid of identify/control tasks from a TOML/YAML file, on this
    machine's cores or a Ray cluster, resumable
    (:func:`spacecraft_lab.sweeps.run_sweep`); ``sweep-summary``
    re-tabulates a sweep directory.

Every option is checked when the command line is parsed: a bad value ends
with a one-line ``spacecraft <command>: error: ...`` message and exit status
2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from controllers import LQRWeights
from spacecraft_conventions import __version__, exit_now, sigterm_as_interrupt
from spacecraft_env import (
    DEFAULT_SNR_DB,
    FAULT_KINDS,
    PARAMETER_LIMITS,
    REWARDS,
    SCENARIOS,
    Fault,
    parse_fault,
)
from spacecraft_lab.adaptation import adaptation_table, run_adaptation
from spacecraft_lab.agents import HELD_OUT_SEEDS, SHIPPED_AGENTS, evaluate_agent, evaluation_table
from spacecraft_lab.control import CONTROLLER_KEYS, SCENARIO_NAMES, env_kwargs_for, run_control
from spacecraft_lab.demo import MAX_DEMO_STEPS, demo_summary, run_demo
from spacecraft_lab.identification import METHODS, PRESETS, run_identification
from spacecraft_lab.paper import PAPER_SNR_DB
from spacecraft_lab.plots import plot_adaptation, plot_performance_profiles, plot_rl_comparison
from spacecraft_lab.reporting import (
    COMPARATOR_NAMES,
    FAST_ADAPTIVE_LQG,
    control_brief,
    control_summary,
    identification_brief,
    pooled_training_runs,
    rl_protocol_report,
    rl_table,
)
from spacecraft_lab.rl_protocol import performance_profiles
from spacecraft_lab.sweeps import (
    BACKENDS,
    MAX_TASKS,
    ResultStore,
    SweepLockedError,
    load_config,
    pending_tasks,
    run_sweep,
    summarize,
)
from spacecraft_lab.training import (
    ACTION_REPEAT,
    ALGORITHMS,
    EVAL_SEEDS,
    FEATURES,
    RESIDUAL_REPEAT,
    run_training,
)

__all__ = ["build_parser", "main", "synopsis"]


# ----------------------------------------------------------------- value checks
def _integer(low: int, high: int | None = None) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(
                f"must be >= {low}, got {value}" if high is None
                else f"must be an integer in [{low}, {high}], got {value}")
        return value

    parse.__name__ = f"integer >= {low}"
    return parse


def _number(low: float, high: float = math.inf, *, low_open: bool = False,
            unit: str = "") -> Callable[[str], float]:
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        ok = (value > low if low_open else value >= low) and value <= high
        if not (math.isfinite(value) and ok):
            bracket = "(" if low_open else "["
            raise argparse.ArgumentTypeError(
                f"must be in {bracket}{low:g}, {high:g}]{unit}, got {text}")
        return value

    parse.__name__ = "number"
    return parse


def _limited(key: str) -> Callable[[str], float | int]:
    """A physical parameter, checked against its one range
    (:data:`spacecraft_env.PARAMETER_LIMITS`)."""
    limit = PARAMETER_LIMITS[key]

    def parse(text: str) -> float | int:
        try:
            value = int(text) if limit.integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {limit.describe().split(' in ')[0]}, got {text!r}") from None
        try:
            return limit.check(key, value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {limit.describe()}, got {text}") from None

    parse.__name__ = key
    return parse


#: Longest episode or record, steps.
_MAX_STEPS = int(PARAMETER_LIMITS["max_steps"].high)


def _fault(text: str) -> Fault:
    """``--fault``: a :class:`spacecraft_env.Fault` from its command-line form."""
    try:
        return parse_fault(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _snr(text: str) -> float | None:
    if text.lower() == "none":
        return None
    return _limited("snr_db")(text)


def _forgetting(text: str) -> float:
    return _number(0.0, 1.0, low_open=True)(text)


def _existing_file(text: str) -> Path:
    path = Path(text)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"no such file: {text}")
    return path


def _run_directory(text: str) -> Path:
    """A directory holding the ``metrics.json`` of a ``spacecraft train`` run."""
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"no such directory: {text}")
    if not (path / "metrics.json").is_file():
        raise argparse.ArgumentTypeError(f"{text} holds no metrics.json of a 'train' run")
    return path


def _sweep_directory(text: str) -> Path:
    path = Path(text)
    if not (path / "results.jsonl").is_file():
        raise argparse.ArgumentTypeError(f"{text} holds no results.jsonl of a sweep")
    return path


def _output_directory(text: str) -> Path:
    """A directory that exists and is writable, or can be created."""
    path = Path(text)
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise argparse.ArgumentTypeError(f"cannot create {text}: {probe} is not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"cannot write to {probe}")
    return path


def _probe_outputs(args: argparse.Namespace) -> None:
    """Check, before any work and without creating anything, that every output of the
    command can be written: a probe file is made and removed in the output directory,
    or in its nearest existing parent when it does not exist yet (the command creates
    it when it writes). A sweep's ``results.jsonl``, if present, must be a writable file.

    Raises
    ------
    ValueError
        If an output cannot be written, with the option and the reason.
    """
    for key in ("out", "tensorboard"):
        path = getattr(args, key, None)
        if path is None or (key == "out" and args.command in ("rl-table", "sweep-summary")):
            continue
        path = Path(path)
        option = f"--{key.replace('_', '-')} {path}"
        existing = path
        while not existing.exists() and existing.parent != existing:
            existing = existing.parent
        if not existing.is_dir():
            raise ValueError(f"cannot write to {option}: {existing} is not a directory")
        try:
            fd, probe = tempfile.mkstemp(prefix=".write-probe-", dir=existing)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise ValueError(f"cannot write to {option}: {exc.strerror or exc}") from None
        if args.command == "sweep":
            ResultStore(path / "results.jsonl").check_writable()


# ----------------------------------------------------------------- the parser
class _HelpFormatter(argparse.HelpFormatter):
    """Help that names each option's default once: appended when the help text does not
    already say it, left out when there is none (None, False)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.choices is not None and action.option_strings and "|" not in str(
                action.metavar):
            text = f"{text}; one of: {', '.join(map(str, action.choices))}"
        default = action.default
        if ("default" in text or default in (None, False, argparse.SUPPRESS)
                or not action.option_strings):
            return text
        shown = " ".join(map(str, default)) if isinstance(default, list | tuple) else default
        return f"{text} (default: {shown})"


#: Metavariables of the options whose values are not self-explaining (an option with
#: at most :data:`_SPELLED_CHOICES` choices shows them instead, ``a|b|c``).
_METAVARS = {"scenario": "S", "reward_from": "S", "seeds": "N", "seed": "N", "steps": "N",
             "out": "DIR",
             "methods": "M", "controllers": "C", "preset": "P", "snr_db": "DB|none",
             "modes": "K", "samples": "N", "convergence": "S", "task": "T",
             "module_mass": "KG", "rotation_rate": "DEG_S", "paddle_angle": "DEG",
             "torque_weight": "R", "max_torque": "NM", "actuator_delay": "N",
             "torque_rate_limit": "NM_S", "disturbance_torque": "NM",
             "features": "F", "timesteps": "N", "first_seed": "N", "repeat": "N",
             "eval_every": "N", "eval_episodes": "N", "tensorboard": "DIR", "config": "FILE",
             "workers": "N", "address": "ADDR", "timeout": "S", "max_tasks": "N",
             "integral_settle": "S"}
_SPELLED_CHOICES = 3


def _metavar(action: argparse.Action) -> str:
    """The metavariable of an option: its choices when few, else :data:`_METAVARS`."""
    if action.dest not in _METAVARS and action.choices is not None \
            and len(action.choices) <= _SPELLED_CHOICES:
        return "|".join(map(str, action.choices))
    return _METAVARS.get(action.dest, action.dest.upper())


def synopsis(parser: argparse.ArgumentParser | None = None, width: int = 100) -> str:
    """One usage block per command, as the README shows it (generated, so it cannot
    drift from the parser; ``tests/test_docs.py`` compares them).

    Returns
    -------
    str
        The usage blocks, one per command.
    """
    parser = parser or build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    names = list(sub.choices)
    pad = max(map(len, names)) + len("spacecraft ") + 1
    lines = []
    for name, command in sub.choices.items():
        items = []
        for action in command._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if not action.option_strings:
                items.append(f"{action.metavar or action.dest.upper()} "
                             f"[{action.metavar or action.dest.upper()} ...]"
                             if action.nargs == "+" else action.metavar or action.dest.upper())
                continue
            flag = action.option_strings[-1]
            if action.nargs == 0:
                text = flag
            else:
                meta = action.metavar
                meta = " ".join(meta) if isinstance(meta, tuple) else meta
                text = f"{flag} {meta}" + (" ..." if action.nargs == "+" else "")
            items.append(text if action.required else f"[{text}]")
        line = f"spacecraft {name}".ljust(pad)
        for item in items:
            if len(line) + 1 + len(item) > width and line.strip():
                lines.append(line.rstrip())
                line = " " * pad
            line += item + " "
        lines.append(line.rstrip())
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with one sub-parser per command.

    Returns
    -------
    argparse.ArgumentParser
        The parser.
    """
    fmt = _HelpFormatter
    description = ("The flexible-spacecraft lab: rendered demo, identification, closed-loop "
                   "control, RL training and Monte-Carlo sweeps. 'spacecraft COMMAND --help' "
                   "describes a command.")
    parser = argparse.ArgumentParser(prog="spacecraft", description=description,
                                     formatter_class=fmt, allow_abbrev=False)
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, **kwargs: Any) -> argparse.ArgumentParser:
        # no abbreviations: `--p` must not silently mean `--preset`
        return sub.add_parser(name, formatter_class=fmt, allow_abbrev=False, **kwargs)

    demo = command("demo", help="rendered rollout of a scenario")
    demo.add_argument("--scenario", choices=sorted(SCENARIOS), default="docking",
                      help="time-varying scenario")
    demo.add_argument("--out", type=_output_directory, default="results/demo",
                      help="output directory")
    demo.add_argument("--seed", type=_integer(0), default=0, help="environment seed")
    demo.add_argument("--steps", type=_integer(1, MAX_DEMO_STEPS), default=2500,
                      help="episode length, steps of 0.1 s")
    demo.add_argument("--save-trajectories", action="store_true",
                      help="also write the rollout as trajectory.npz")

    ident = command("identify", help="the paper's identification experiment")
    ident.add_argument("--scenario", choices=sorted(SCENARIOS), default="docking",
                       help="truth-model scenario")
    ident.add_argument("--seeds", type=_integer(1), default=10,
                       help="number of input/noise seeds, 0..N-1")
    ident.add_argument("--out", type=_output_directory, default="results/identify",
                       help="output directory")
    ident.add_argument("--methods", nargs="+", default=None, choices=sorted(METHODS),
                       help="methods to run (default: all but the slow windowed-pbsid)")
    ident.add_argument("--preset", choices=PRESETS, default="recommended",
                       help="the methods' settings: the package's defaults, or the source "
                            "paper's constants (p = 15, forgetting 0.98, ...)")
    ident.add_argument("--snr-db", type=_snr, default=PAPER_SNR_DB,
                       help="measurement SNR per channel in dB, or 'none' (paper: 40)")
    ident.add_argument("--modes", type=_integer(1), default=2,
                       help="modes per appendage, 1..8 (order n = 6 + 8 k)")
    ident.add_argument("--samples", type=_integer(200, _MAX_STEPS), default=2500,
                       help="record length, samples of 0.1 s (paper: 2500)")
    ident.add_argument("--convergence", type=_number(0.0), default=150.0,
                       help="start of the scored window, s")
    ident.add_argument("--workers", type=_integer(1), default=None,
                       help="processes running the seeds side by side; the numbers do not "
                            "depend on it (default: all cores)")

    ctl = command("control", help="closed-loop comparison of the controllers")
    ctl.add_argument("--scenario", choices=sorted(SCENARIO_NAMES), default="paddle_rotation",
                     help="registered scenario")
    ctl.add_argument("--seeds", type=_integer(1), default=10,
                     help="number of episode seeds, 0..N-1")
    ctl.add_argument("--out", type=_output_directory, default="results/control",
                     help="output directory")
    ctl.add_argument("--controllers", nargs="+", choices=sorted(CONTROLLER_KEYS), default=None,
                     help="controllers to run (default: all but the two options "
                          "adaptive-lqg-physical, the adaptive LQG on a physical model "
                          "fitted to its warm-up and held, and adaptive-lqg-structured-rpbsid, "
                          "on a recursive PBSID with an exact rigid block (StructuredRPBSID); "
                          "adaptive-lqg flies the drive-scheduled physical fit, "
                          "adaptive-lqg-fast the rigid-flexible identifier with closed-loop "
                          "settings)")
    ctl.add_argument("--task", choices=("slew", "regulation"), default="slew",
                     help="slew to a random reference within +-10 deg, or regulate from "
                          "+-2 deg")
    ctl.add_argument("--steps", type=_integer(100, _MAX_STEPS), default=None,
                     help="episode length, steps of 0.1 s (default: the registered 2500)")
    ctl.add_argument("--module-mass", type=_limited("module_mass"),
                     default=None, help="mass of each docking module, kg (paper: 600)")
    ctl.add_argument("--mass-centre-shift", action="store_true",
                     help="docking: the modules move the system mass centre (the paper "
                          "keeps it fixed)")
    ctl.add_argument("--capture-momentum", type=_limited("capture_momentum"), nargs=3,
                     default=None, metavar=("HX", "HY", "HZ"),
                     help="docking: angular momentum each module brings at capture, N m s "
                          "(conserved; default: modules arrive co-rotating)")
    ctl.add_argument("--rotation-rate", type=_limited("rotation_rate"), default=None,
                     help="paddle rotation rate, deg/s (solar_rotation: 0.2, "
                          "paddle_rotation: 0.36)")
    ctl.add_argument("--paddle-angle", type=_limited("paddle_angle"), default=None,
                     help="paddle angle at t = 0, deg (constant and rotation scenarios)")
    ctl.add_argument("--snr-db", type=_snr, default=DEFAULT_SNR_DB,
                     help="measurement SNR per channel in dB, or 'none'")
    ctl.add_argument("--torque-weight", type=_limited("torque_weight"), default=None,
                     help="LQR torque weight per (N m)^2; smaller = more aggressive "
                          "(default: LQRWeights')")
    ctl.add_argument("--max-torque", type=_limited("max_torque"),
                     default=None, help="N m per unit action (default: the env's 10)")
    ctl.add_argument("--actuator-delay", type=_limited("actuator_delay_steps"), default=0,
                     help="actuator transport delay, steps of 0.1 s")
    ctl.add_argument("--torque-rate-limit", type=_limited("torque_rate_limit"),
                     default=None, help="actuator slew-rate limit, N m/s (default: none)")
    ctl.add_argument("--disturbance-torque", type=_limited("disturbance_torque"),
                     default=0.0, help="constant external torque on every axis, N m")
    ctl.add_argument("--disturbance-std", type=_limited("disturbance_std"), default=0.0,
                     metavar="NM", help="white external torque on every axis, N m "
                                        "(process noise; default 0)")
    ctl.add_argument("--initial-attitude", type=_limited("initial_attitude_deg"), default=None,
                     metavar="DEG",
                     help="regulation: each initial attitude angle drawn in +-this, deg "
                          "(default: the env's 2; 0: held at rest from zero attitude and rate)")
    ctl.add_argument("--integral-settle", type=_number(0.0, 1e4, unit=" s"), default=None,
                     help="seconds every attitude error must stay in the LQG integral's "
                          "band before it integrates (default: INTEGRAL_SETTLE_S, 50; 0: "
                          "at once, as before 2026-11-26)")
    ctl.add_argument("--fault", type=_fault, action="append", default=None,
                     metavar="SPEC",
                     help="inject a fault (repeatable), SPEC "
                          "'KIND,onset=S[,duration=S][,axis=I][,group=G][,value=V]', KIND "
                          "one of " + ", ".join(FAULT_KINDS) + "; e.g. "
                          "loss_of_effectiveness,onset=120,axis=0,value=0.1 or "
                          "sensor_bias,onset=120,group=rate,axis=2,value=1.75e-4 (SI units; "
                          "spacecraft_env.FaultInjection). The ceilings do not know it")
    ctl.add_argument("--save-trajectories", action="store_true",
                     help="also write every episode to OUT/trajectories/ (npz)")
    ctl.add_argument("--workers", type=_integer(1), default=None,
                     help="processes running the seeds side by side; the numbers do not "
                          "depend on it (default: all cores)")

    train = command("train", help="train SB3 agents (PPO/SAC, ARS)")
    train.add_argument("--algo", choices=ALGORITHMS, default="ppo",
                       help="SB3 algorithm: ppo, sac, or ars (sb3-contrib's augmented random "
                            "search on a linear policy, each antithetic pair on one episode)")
    train.add_argument("--features", choices=FEATURES, default="none",
                       help="observation features appended for the agent, the attitude error "
                       "and rate alone in nominal units (attitude-error), or (residual-*) "
                       "the controller whose action the agent corrects")
    train.add_argument("--timesteps", type=_integer(1), default=100_000,
                       help="training env steps per seed")
    train.add_argument("--seeds", type=_integer(1), default=1,
                       help="number of training seeds: first-seed .. first-seed + N - 1")
    train.add_argument("--first-seed", type=_integer(0), default=0,
                       help="first training seed (to split seeds over processes)")
    train.add_argument("--scenario", choices=sorted(SCENARIO_NAMES), default="docking",
                       help="registered scenario")
    train.add_argument("--randomize", action="store_true",
                       help="draw a new scenario every episode (docking: masses, times, "
                            "off-axis offsets; rotation: rate); the task where model "
                            "knowledge matters")
    train.add_argument("--repeat", type=_integer(1), default=None,
                       help=f"env steps each agent action is held for (ActionRepeat; "
                            f"default {ACTION_REPEAT} = one decision per second, "
                            f"{RESIDUAL_REPEAT} for the residual-* settings but the "
                            f"*-averaged ones, which decide once per averaged second)")
    train.add_argument("--reward", choices=REWARDS, default="bounded",
                       help="env reward form: 'bounded' (1 - min(cost / saturation, 1) "
                            "per step alive), 'log' (the same on a log scale of the cost, "
                            "which resolves precision near the target) or 'cost' (negative "
                            "stage cost and a termination penalty)")
    train.add_argument("--reward-from", type=float, default=0.0,
                       help="train on the reward of the steps from this time on, s, and the "
                            "termination penalty whenever it comes (100: the window the "
                            "evaluations score; controllers.ScoredWindowReward); default 0")
    train.add_argument("--relative-to-base", action="store_true",
                       help="residual-* settings: train on the reward minus what the base "
                            "alone earns on a twin of the same episode (same plant draw and "
                            "sensor noise; controllers.BaseRelativeReward)")
    train.add_argument("--eval-every", type=_integer(1), default=20_000,
                       help="env steps between evaluations")
    train.add_argument("--eval-episodes", type=_integer(1), default=len(EVAL_SEEDS),
                       help="evaluation episodes (seeds 1000, 1001, ...), the same for the "
                            "LQG comparators, every curve point and the final result")
    train.add_argument("--workers", type=_integer(1), default=None,
                       help="processes scoring the LQG comparators side by side before "
                            "training; the scores do not depend on it (default: all cores)")
    train.add_argument("--log-std", type=_number(-10.0, 2.0), default=None,
                       help="PPO's initial log std of the action noise, normalized action "
                            "units (default -1; -3 for the residual-* settings, whose "
                            "action is scaled by 0.05)")
    train.add_argument("--envs", type=_integer(1, 64), default=None,
                       help="environments stepped side by side while training (above 1: "
                            "one process each; PPO collects a rollout from every env, so "
                            "it is a different run, not the same one faster; default: one "
                            "per core for PPO and SAC, 1 for ARS)")
    train.add_argument("--out", type=_output_directory, default="results/train",
                       help="output directory")
    train.add_argument("--tensorboard", type=_output_directory, default=None,
                       help="TensorBoard log directory (default: none)")

    evaluate = command("evaluate", help="a saved agent beside the LQGs on any episodes")
    evaluate.add_argument("agent", metavar="AGENT", nargs="+",
                          help=f"a model saved by 'train' (.zip, with its _vecnormalize.pkl "
                               f"and the run's metrics.json beside it) or a shipped agent: "
                               f"{', '.join(sorted(SHIPPED_AGENTS))}; several: the training "
                               f"seeds of one setting, scored together")
    evaluate.add_argument("--episodes", type=_integer(1), default=len(HELD_OUT_SEEDS), metavar="N",
                          help="episodes, seeds first-seed, first-seed + 1, ...")
    evaluate.add_argument("--first-seed", type=_integer(0), default=HELD_OUT_SEEDS[0],
                          help="first episode seed (default: held out from training and "
                               "from its checkpoint selection)")
    evaluate.add_argument("--workers", type=_integer(1), default=None,
                          help="processes scoring the LQG comparators side by side; the "
                               "scores do not depend on it (default: all cores)")
    evaluate.add_argument("--out", type=_output_directory, default="results/evaluate",
                          help="output directory (evaluation.json, table.md)")

    adapt = command("adapt", help="a policy trained on the true parameters, flown with "
                                  "them, their estimate from the identifier and the nominal "
                                  "ones (RMA-style)")
    adapt.add_argument("agents", nargs="+", metavar="AGENT",
                       help="models saved by 'train --features privileged' or "
                            "'residual-*-privileged' (.zip, with their "
                            "_vecnormalize.pkl and the run's metrics.json)")
    adapt.add_argument("--episodes", type=_integer(1), default=20, metavar="N",
                       help="rollouts of each policy that train its adaptation module")
    adapt.add_argument("--scored-episodes", type=_integer(1), default=len(HELD_OUT_SEEDS),
                       metavar="N", help="held-out episodes scored (seeds from "
                                         f"{HELD_OUT_SEEDS[0]})")
    adapt.add_argument("--workers", type=_integer(1), default=None,
                       help="processes scoring the LQG comparators side by side; the "
                            "scores do not depend on it (default: all cores)")
    adapt.add_argument("--out", type=_output_directory, default="results/adapt",
                       help="output directory (adaptation.json, table.md, adaptation.png)")

    for scoring in (train, evaluate, adapt):
        scoring.add_argument("--no-cache", dest="cache", action="store_false",
                             help="score the LQG comparators again instead of reading "
                                  "their scores from the cache (SPACECRAFT_CACHE_DIR, "
                                  "default ~/.cache/flexible-spacecraft; keyed by the "
                                  "settings, the episodes and the code)")

    table = command("rl-table", help="comparison table of 'train' output directories")
    table.add_argument("dirs", nargs="+", type=_run_directory, metavar="DIR",
                       help="output directories of 'spacecraft train'")
    table.add_argument("--plot", type=Path, default=None, metavar="PNG",
                       help="also draw the learning curves of all runs (median and range "
                            "over seeds) to this file")

    sweep = command("sweep", help="Monte-Carlo grid of identify/control tasks")
    sweep.add_argument("--config", required=True, type=_existing_file,
                       help="sweep file (.toml, .yaml, .json); trusted input")
    sweep.add_argument("--backend", choices=sorted(BACKENDS), default="local",
                       help="where tasks run")
    sweep.add_argument("--out", required=True, type=_output_directory,
                       help="output directory; an existing one is resumed")
    sweep.add_argument("--workers", type=_integer(1), default=None,
                       help="local processes, or CPUs of a new local Ray instance "
                            "(default: all cores)")
    sweep.add_argument("--address", default=None,
                       help="Ray cluster address (default: start a local instance)")
    sweep.add_argument("--ship-code", action="store_true",
                       help="upload this package to the Ray cluster with the job")
    sweep.add_argument("--timeout", type=_number(0.0, low_open=True, unit=" s"), default=None,
                       help="per-task wall-clock limit, s (overrides the file's timeout_s)")
    sweep.add_argument("--retry-errors", action="store_true",
                       help="run again the tasks recorded as failed")
    sweep.add_argument("--dry-run", action="store_true",
                       help="list the tasks (and how many are done) without running")
    sweep.add_argument("--max-tasks", type=_integer(1), default=MAX_TASKS,
                       help="refuse a sweep file that declares more tasks (a typo in a seed "
                            "count fails at once)")
    sweep.add_argument("--allow-custom-tasks", action="store_true",
                       help="accept 'module:function' task kinds, which import and run "
                            "code named by the sweep file")

    summ = command("sweep-summary", help="tables and plots of a sweep directory")
    summ.add_argument("dir", type=_sweep_directory, metavar="DIR", help="sweep output directory")
    for command_parser in sub.choices.values():
        for action in command_parser._actions:
            if action.option_strings and action.metavar is None and action.nargs != 0:
                action.metavar = _metavar(action)
    return parser


# ----------------------------------------------------------------- commands
def _demo(args: argparse.Namespace) -> int:
    summary = run_demo(args.scenario, args.out, seed=args.seed, steps=args.steps,
                       save_trajectory=args.save_trajectories)
    print(demo_summary(summary, args.out))
    return 0


def _identify(args: argparse.Namespace) -> int:
    metrics = run_identification(args.scenario, args.seeds, args.out, methods=args.methods,
                                 preset=args.preset, snr_db=args.snr_db, n_modes=args.modes,
                                 n_samples=args.samples, convergence_s=args.convergence,
                                 workers=args.workers)
    print(identification_brief(metrics))
    print(f"wrote {args.out}/metrics.json, table.md (the full tables), prediction.png, "
          f"gain.png, modal.png, responses.png ({len(metrics['methods'])} rows, "
          f"{args.seeds} seeds)")
    return 0


def _control(args: argparse.Namespace) -> int:
    env_kwargs = env_kwargs_for(args.scenario, task=args.task, module_mass=args.module_mass,
                                mass_centre_shift=args.mass_centre_shift,
                                capture_momentum=args.capture_momentum,
                                rotation_rate=args.rotation_rate, paddle_angle=args.paddle_angle,
                                snr_db=args.snr_db, max_torque=args.max_torque,
                                actuator_delay_steps=args.actuator_delay,
                                torque_rate_limit=args.torque_rate_limit,
                                disturbance_torque=args.disturbance_torque,
                                initial_attitude=args.initial_attitude,
                                disturbance_std=args.disturbance_std)
    weights = LQRWeights(torque=args.torque_weight) if args.torque_weight is not None else None
    metrics = run_control(args.scenario, args.seeds, args.out, env_kwargs=env_kwargs,
                          weights=weights, controllers=args.controllers, steps=args.steps,
                          save_trajectories=args.save_trajectories, workers=args.workers,
                          integral_settle_s=args.integral_settle, faults=args.fault or ())
    print(control_brief(metrics["controllers"]))
    print(control_summary(metrics["controllers"], args.scenario, args.out))
    print(f"wrote {args.out}/metrics.json, results.csv, table.md (the full table), "
          "comparison.png")
    return 0


def _training_envs(args: argparse.Namespace) -> int:
    """``--envs``, or its default: every core for PPO and SAC, one env for ARS (which flies
    its candidates one episode at a time)."""
    if args.envs is not None:
        return args.envs
    return 1 if args.algo == "ars" else max(1, min(os.cpu_count() or 1, 64))


def _train(args: argparse.Namespace) -> int:
    m = run_training(args.algo, args.features, args.timesteps, args.seeds, args.out,
                     scenario=args.scenario, eval_every=args.eval_every,
                     tensorboard=None if args.tensorboard is None else str(args.tensorboard),
                     randomize=args.randomize, repeat=args.repeat, reward=args.reward,
                     first_seed=args.first_seed,
                     eval_seeds=tuple(range(EVAL_SEEDS[0], EVAL_SEEDS[0] + args.eval_episodes)),
                     workers=args.workers, envs=_training_envs(args), log_std_init=args.log_std,
                     relative_to_base=args.relative_to_base,
                     reward_from_s=args.reward_from, cache=args.cache)
    brief = {k: m[k] for k in ("algo", "features", "scenario", "timesteps", "randomize",
                               "repeat", "reward", "relative_to_base", "reward_from_s", "envs",
                               "final_cost_after_100s",
                               "final_attitude_rms_deg", "final_vibration_rms_mm",
                               "final_return")}
    for key in ("oracle_lqg", "adaptive_lqg", "fixed_lqg"):
        brief[key] = {k: v for k, v in m[key].items() if not isinstance(v, list)}
    print(json.dumps(brief, indent=2))
    print(f"env steps to 2x the {FAST_ADAPTIVE_LQG}'s cost from 100 s:",
          [r["steps_to_2x_adaptive"] for r in m["runs"]])
    print("training throughput, env steps/s (evaluations included):",
          [round(r["env_steps_per_s"]) for r in m["runs"]])
    print(f"wrote {args.out}/metrics.json, learning_curves.png and the models")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    seeds = tuple(range(args.first_seed, args.first_seed + args.episodes))
    result = evaluate_agent(args.agent, seeds, workers=args.workers, cache=args.cache)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = evaluation_table(result)
    (out / "evaluation.json").write_text(json.dumps(result, indent=2))
    (out / "table.md").write_text(table + "\n")
    costs = {COMPARATOR_NAMES.get(k, k): s["cost_after_100s_per_seed"]
             for k, s in result["scores"].items()}
    if "agent_runs" in result:          # every training seed's run, not their mean
        costs["agent"] = [run["cost_after_100s_per_seed"] for run in result["agent_runs"]]
    finite = np.concatenate([np.asarray(c, dtype=float).ravel() for c in costs.values()])
    finite = finite[np.isfinite(finite) & (finite > 0)]
    if finite.size:
        thresholds = np.geomspace(finite.min() / 2, finite.max() * 2, 60)
        plot_performance_profiles(out / "performance_profiles.png", thresholds,
                                  performance_profiles(costs, thresholds),
                                  title=f"{Path(args.agent[0]).stem} beside the LQGs, "
                                        f"{len(seeds)} held-out draws")
    print(table)
    print(f"wrote {out}/evaluation.json, table.md and performance_profiles.png")
    return 0


def _adapt(args: argparse.Namespace) -> int:
    seeds = tuple(range(HELD_OUT_SEEDS[0], HELD_OUT_SEEDS[0] + args.scored_episodes))
    result = run_adaptation(args.agents, args.episodes, seeds, workers=args.workers,
                            cache=args.cache)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = adaptation_table(result)
    (out / "adaptation.json").write_text(json.dumps(result, indent=2))
    (out / "table.md").write_text(table + "\n")
    plot_adaptation(out / "adaptation.png", result)
    print(table)
    print(f"wrote {out}/adaptation.json, table.md and adaptation.png")
    return 0


def _rl_table(args: argparse.Namespace) -> int:
    print(rl_table(args.dirs))
    print("\nThe evaluation protocol (docs/design/evaluation.md, \"RL agents\"): the cost "
          "from 100 s over training seeds x evaluation draws, 95 % stratified-bootstrap "
          "intervals:\n")
    print(rl_protocol_report(args.dirs))
    if args.plot is not None:
        plot_rl_comparison(args.plot, pooled_training_runs(args.dirs))
        print(f"wrote {args.plot}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    config = load_config(args.config, allow_custom_tasks=args.allow_custom_tasks,
                         max_tasks=args.max_tasks)
    if args.timeout is not None:
        config = dataclasses.replace(config, timeout_s=float(args.timeout))
    if args.dry_run:
        tasks = config.tasks()
        todo = pending_tasks(tasks, ResultStore(Path(args.out) / "results.jsonl"),
                             args.retry_errors)
        for task in todo:
            print(task.task_id, task.kind, task.label or "", json.dumps(task.params))
        print(f"{len(tasks)} tasks, {len(tasks) - len(todo)} done, {len(todo)} to run")
        return 0
    report = run_sweep(config, args.out, args.backend, workers=args.workers,
                       address=args.address, retry_errors=args.retry_errors,
                       ship_code=args.ship_code)
    print((Path(args.out) / "summary.md").read_text())
    print(f"{report.ran} tasks run ({report.ok} ok, {report.errors} failed), {report.skipped} "
          f"already done, {report.wall_s:.1f} s on {report.workers} {report.backend} workers")
    print(f"wrote {args.out}/results.jsonl, summary.md, summary.csv, summary.json, summary.png")
    return 1 if report.errors else 0


def _sweep_summary(args: argparse.Namespace) -> int:
    summarize(args.dir)
    print((Path(args.dir) / "summary.md").read_text())
    print(f"wrote {args.dir}/summary.md, summary.csv, summary.json, summary.png")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "demo": _demo, "identify": _identify, "control": _control, "train": _train,
    "evaluate": _evaluate, "adapt": _adapt, "rl-table": _rl_table, "sweep": _sweep,
    "sweep-summary": _sweep_summary,
}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``spacecraft`` console script.

    Errors of the user's making (a bad value that only the run can detect, a
    locked sweep directory, a missing file, an output directory that cannot
    be written, checked before any work) end with a one-line message and
    exit status 2; Ctrl-C ends with one line and status 130 (``control``
    first writes the table of the seeds it completed); anything else is a
    bug and keeps its traceback.

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        _probe_outputs(args)
        with sigterm_as_interrupt():       # kill / a scheduler's SIGTERM: as Ctrl-C
            return COMMANDS[args.command](args)
    except (ValueError, FileNotFoundError, PermissionError, SweepLockedError,
            ImportError) as exc:
        parser.exit(2, f"spacecraft {args.command}: error: {exc}\n")
    except OSError as exc:        # the machine's, not the user's nor a bug: disk full, I/O
        kept = (f"; the records written so far are kept in {args.out}/results.jsonl: run the "
                "same command again to resume" if args.command == "sweep" else "")
        parser.exit(2, f"spacecraft {args.command}: error: {exc.strerror or exc}"
                       f"{f': {exc.filename}' if exc.filename else ''}{kept}\n")
    except KeyboardInterrupt:
        done = (f"; wrote what the completed seeds give to {args.out}"
                if args.command == "control" and (Path(args.out) / "table.md").exists()
                else "")
        message = f"spacecraft {args.command}: interrupted{done}\n"
        if _threads_left():
            # once its workers are stopped, a process pool's own thread can stay blocked
            # (most likely on a result a worker was stopped while writing), and a normal
            # exit joins it: 1 interrupt in 8 hung for good (tests/test_reliability.py,
            # d12). Leave at once, the line written and the streams flushed
            exit_now(130, message)
        parser.exit(130, message)
    return 2   # not reached: parser.exit raises SystemExit


def _threads_left() -> bool:
    """Whether a thread other than the main one (a process pool's) is still running and
    would be joined at exit."""
    return any(t.is_alive() and not t.daemon and t is not threading.main_thread()
               for t in threading.enumerate())


if __name__ == "__main__":
    sys.exit(main())
