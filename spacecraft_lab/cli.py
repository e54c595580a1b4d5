"""The project's command line: ``spacecraft <command>``.

Commands
--------
``demo``
    Rendered rollout of a scenario (:func:`spacecraft_lab.demo.run_demo`).
``identify``
    The paper's identification experiment for every method
    (:func:`spacecraft_lab.identification.run_identification`).
``control``
    Fixed LQR, PD, adaptive LQR and oracle LQR compared in closed loop
    (:func:`spacecraft_lab.control.run_control`).
``train``
    stable-baselines3 agents with or without identified-model features
    (:func:`spacecraft_lab.training.run_training`); ``rl-table`` tabulates runs.
``sweep``
    A grid of identify/control tasks from a TOML/YAML file, on this
    machine's cores or a Ray cluster, resumable
    (:func:`spacecraft_lab.sweeps.run_sweep`); ``sweep-summary``
    re-tabulates a sweep directory.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from controllers import LQRWeights
from spacecraft_env import SCENARIOS
from spacecraft_lab.control import run_control, scenario_override
from spacecraft_lab.demo import run_demo
from spacecraft_lab.identification import METHODS, run_identification
from spacecraft_lab.reporting import rl_table
from spacecraft_lab.sweeps import ResultStore, load_config, pending_tasks, run_sweep, summarize
from spacecraft_lab.training import run_training

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with one sub-parser per command."""
    parser = argparse.ArgumentParser(prog="spacecraft", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="rendered rollout of a scenario")
    demo.add_argument("--scenario", choices=sorted(SCENARIOS), default="docking")
    demo.add_argument("--out", default="results/demo", help="output directory")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--steps", type=int, default=2500)

    ident = sub.add_parser("identify", help="the paper's identification experiment")
    ident.add_argument("--scenario", choices=sorted(SCENARIOS), default="docking")
    ident.add_argument("--seeds", type=int, default=10, help="noise seeds 0..N-1")
    ident.add_argument("--out", default="results/identify", help="output directory")
    ident.add_argument("--methods", nargs="+", default=None, choices=sorted(METHODS),
                       help="methods to run (default: all)")
    ident.add_argument("--snr-db", type=_snr, default=40.0,
                       help="measurement SNR per channel in dB, or 'none' (paper: 40)")
    ident.add_argument("--modes", type=int, default=2, help="modes per appendage (n = 6 + 8 k)")
    ident.add_argument("--p", type=int, default=15, help="past window (paper: 15)")
    ident.add_argument("--forgetting", type=float, default=0.98, help="paper: 0.98")
    ident.add_argument("--regularization", type=float, default=0.0,
                       help="VARX Tikhonov floor, fraction of the effective memory (paper: 0)")
    ident.add_argument("--convergence", type=float, default=50.0,
                       help="start of the held-out VAF window, s (default 50)")
    ident.add_argument("--warmup", type=int, default=None,
                       help="warm-up samples of the recursive methods (default: theirs)")

    ctl = sub.add_parser("control", help="closed-loop comparison of the controllers")
    ctl.add_argument("--scenario", choices=["constant", "docking", "solar_rotation"],
                     default="docking")
    ctl.add_argument("--seeds", type=int, default=10)
    ctl.add_argument("--out", default="results/control")
    ctl.add_argument("--module-mass", type=float, default=None,
                     help="mass of each docking module, kg (paper: 600)")
    ctl.add_argument("--rotation-rate", type=float, default=None,
                     help="paddle rotation rate, deg/s (paper: 0.2)")
    ctl.add_argument("--torque-weight", type=float, default=None,
                     help="LQR torque weight per (N m)^2; smaller = more aggressive (0.3)")
    ctl.add_argument("--max-torque", type=float, default=None, help="N m per unit action (10)")

    train = sub.add_parser("train", help="train SB3 agents (PPO/SAC)")
    train.add_argument("--algo", choices=["ppo", "sac"], default="ppo")
    train.add_argument("--features", choices=["none", "identified"], default="none")
    train.add_argument("--timesteps", type=int, default=100_000)
    train.add_argument("--seeds", type=int, default=1)
    train.add_argument("--scenario", choices=["constant", "docking", "solar_rotation"],
                       default="docking")
    train.add_argument("--eval-every", type=int, default=20_000)
    train.add_argument("--out", default="results/train")
    train.add_argument("--tensorboard", default=None, help="TensorBoard log directory")

    table = sub.add_parser("rl-table", help="comparison table of 'train' output directories")
    table.add_argument("dirs", nargs="+")

    sweep = sub.add_parser("sweep", help="Monte-Carlo grid of identify/control tasks")
    sweep.add_argument("--config", required=True, help="sweep file (.toml, .yaml, .json)")
    sweep.add_argument("--backend", choices=["local", "ray", "serial"], default="local")
    sweep.add_argument("--out", required=True,
                       help="output directory; an existing one is resumed")
    sweep.add_argument("--workers", type=int, default=None,
                       help="local processes, or CPUs of a new local Ray instance "
                            "(default: all cores)")
    sweep.add_argument("--address", default=None,
                       help="Ray cluster address (default: start a local instance)")
    sweep.add_argument("--ship-code", action="store_true",
                       help="upload this package to the Ray cluster with the job")
    sweep.add_argument("--timeout", type=float, default=None,
                       help="per-task wall-clock limit, s (overrides the file's timeout_s)")
    sweep.add_argument("--retry-errors", action="store_true",
                       help="run again the tasks recorded as failed")
    sweep.add_argument("--dry-run", action="store_true",
                       help="list the tasks (and how many are done) without running")

    summ = sub.add_parser("sweep-summary", help="tables and plots of a sweep directory")
    summ.add_argument("dir")
    return parser


def _snr(text: str) -> float | None:
    return None if text.lower() == "none" else float(text)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``spacecraft`` console script."""
    args = build_parser().parse_args(argv)
    if args.command == "demo":
        summary = run_demo(args.scenario, args.out, seed=args.seed, steps=args.steps)
        print(json.dumps(summary, indent=2))
        print(f"wrote {args.out}/summary.json, response.png, rollout.gif, frame.png")
    elif args.command == "control":
        env_kwargs = scenario_override(args.module_mass, args.rotation_rate)
        if args.max_torque is not None:
            env_kwargs["max_torque"] = args.max_torque
        weights = (LQRWeights(torque=args.torque_weight) if args.torque_weight is not None
                   else None)
        run_control(args.scenario, args.seeds, args.out, env_kwargs=env_kwargs,
                    weights=weights)
        print((Path(args.out) / "table.md").read_text())
        print(f"wrote {args.out}/metrics.json, results.csv, table.md, comparison.png")
    elif args.command == "train":
        m = run_training(args.algo, args.features, args.timesteps, args.seeds, args.out,
                         scenario=args.scenario, eval_every=args.eval_every,
                         tensorboard=args.tensorboard)
        print(json.dumps({k: m[k] for k in ("algo", "features", "timesteps",
                                           "final_attitude_rms_deg", "final_return",
                                           "adaptive_lqr")}, indent=2))
        print("steps to 2x adaptive LQR RMS:",
              [r["steps_to_2x_adaptive"] for r in m["runs"]])
        print(f"wrote {args.out}/metrics.json, learning_curves.png and the models")
    elif args.command == "rl-table":
        print(rl_table(args.dirs))
    elif args.command == "sweep":
        return _sweep(args)
    elif args.command == "sweep-summary":
        summarize(args.dir)
        print((Path(args.dir) / "summary.md").read_text())
        print(f"wrote {args.dir}/summary.md, summary.csv, summary.json, summary.png")
    elif args.command == "identify":
        metrics = run_identification(args.scenario, args.seeds, args.out, methods=args.methods,
                                     snr_db=args.snr_db, n_modes=args.modes, p=args.p,
                                     forgetting=args.forgetting,
                                     regularization=args.regularization,
                                     warmup=args.warmup, convergence_s=args.convergence)
        print((Path(args.out) / "table.md").read_text())
        print(f"wrote {args.out}/metrics.json, table.md, responses.png, modal.png "
              f"({len(metrics['methods'])} methods, {args.seeds} seeds)")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    config = load_config(args.config)
    if args.timeout is not None:
        if not args.timeout > 0:
            raise SystemExit(f"--timeout must be positive, got {args.timeout}")
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


if __name__ == "__main__":
    sys.exit(main())
