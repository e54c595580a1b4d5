"""Stationary regulation: the loop's filter against the tight oracle, over the last 500 s
of a 1000 s run of the constant plant.

The regulation task (from +-2 deg, reference 0) on the constant scenario, 10 000
steps. Flown on the same seeds: the adaptive LQG as it ships (its filter's
process-noise intensity chosen online, :class:`controllers.ProcessNoiseBank`), the
same loop with the 0.05 N m filter every fixed design assumes (the behaviour
before), the oracle LQG with that filter, the tight oracle (the oracle LQG whose
filter assumes the plant's true disturbance, none for the registered ids) and the
ceiling (:class:`controllers.ClairvoyantLQG`). Printed per sensor SNR: each one's
median cost over the whole episode and from 500 s, and the paired median ratio of
each to the tight oracle from 500 s (min-max over the seeds).

Usage: ``python benchmarks/bench_stationary.py [--seeds 3] [--snr-db 40 20] [--workers N]
[--out results/stationary.json] [--markdown results/stationary.json]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np

from controllers import AdaptiveLQG, ClairvoyantLQG, OracleLQG, compare, stage_costs
from controllers.baselines import PROCESS_NOISE
from spacecraft_env import env_id

#: Episode length (steps of 0.1 s) and the start of the stationary window, s.
STEPS, STATIONARY_FROM_S = 10_000, 500.0


def _tight_oracle(env: gym.Env) -> OracleLQG:
    return OracleLQG(env, noise_intensity=float(env.unwrapped.disturbance_std))


def _loop_before(env: gym.Env) -> AdaptiveLQG:
    return AdaptiveLQG(env, noise_intensity=PROCESS_NOISE)


#: Row label -> controller factory (module-level: picklable for the workers).
FLOWN = {"adaptive LQG": AdaptiveLQG,
         f"adaptive LQG, {PROCESS_NOISE:g} N m filter": _loop_before,
         "oracle LQG": OracleLQG,
         "tight oracle LQG": _tight_oracle,
         "ceiling": ClairvoyantLQG}
REFERENCE = "tight oracle LQG"


def _make_env(snr_db: float) -> gym.Env:
    return gym.make(env_id("constant"), task="regulation", snr_db=snr_db,
                    max_episode_steps=STEPS)


def fly(seeds: int, snr_db: float, workers: int) -> dict:
    """Per controller, per seed: the mean stage cost over the episode and from 500 s."""
    make_env = partial(_make_env, snr_db)
    env = make_env()
    model = env.unwrapped.model
    env.close()
    _, runs = compare(FLOWN, make_env, list(range(seeds)), progress=True, workers=workers)
    out = {}
    for name, trajectories in runs.items():
        whole, late = [], []
        for traj in trajectories:
            cost = stage_costs(traj, model)[:, :4].sum(axis=1)
            whole.append(float(cost.mean()))
            late.append(float(cost[traj.time >= STATIONARY_FROM_S].mean()))
        out[name] = {"whole": whole, "stationary": late}
    return out


def markdown(report: dict) -> str:
    """One table per SNR of a :func:`fly` report."""
    lines = []
    for snr, rows in report["runs"].items():
        ref = np.asarray(rows[REFERENCE]["stationary"])
        lines += [f"SNR {snr} dB, {report['seeds']} seeds:", "",
                  "| controller | whole episode | from 500 s | from 500 s / tight oracle "
                  "(min-max) |", "|---|---|---|---|"]
        for name, row in rows.items():
            ratio = np.asarray(row["stationary"]) / ref
            lines.append(f"| {name} | {np.median(row['whole']):.4g} | "
                         f"{np.median(row['stationary']):.3g} | {np.median(ratio):.3g} "
                         f"({ratio.min():.3g}-{ratio.max():.3g}) |")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--snr-db", type=float, nargs="+", default=[40.0, 20.0])
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=None, help="JSON of every figure")
    parser.add_argument("--markdown", type=Path, default=None,
                        help="print the tables of a --out file and stop")
    args = parser.parse_args(argv)
    if args.markdown is not None:
        print(markdown(json.loads(args.markdown.read_text())))
        return 0
    report = {"seeds": args.seeds, "runs": {}}
    for snr in args.snr_db:
        report["runs"][f"{snr:g}"] = fly(args.seeds, snr, args.workers)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))
    print(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
