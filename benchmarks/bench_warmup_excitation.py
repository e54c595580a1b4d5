"""What the warm-up excitation buys and what it costs after 100 s.

The adaptive LQG excites the plant with a random binary torque during its
identifier's 30 s warm-up (``BinaryExcitation.warmup_amplitude``: the
identifier's ``warmup_amplitude``, 0.5 N m per axis for the drive-scheduled
fit, 1 N m for an identifier without one). The fit needs that information;
the lightly damped modes keep ringing from it long after the warm-up, into
the scored window from 100 s. This prints, for each warm-up amplitude, the
paired-seed ratio of the common cost from 100 s to the oracle LQG's (median
[worst seed]), the split of that cost (attitude / rate / deflection /
torque, each over the oracle's whole cost, median), and the identified
rigid gain's median error from 60 s, for three identifiers side by side:

* ``truth``: the same law handed the true model after the warm-up (the
  ceiling of any identifier behind this warm-up);
* ``scheduled``: the drive-scheduled physical fit
  (``controllers.scheduled_identifier``, the adaptive LQG's default since
  2026-11-28);
* ``scheduled-held``: the same fit held after the warm-up
  (``accumulate=False``; the default refits as its record doubles);
* ``fast``: the structured recursive identifier (``controllers.fast_identifier``,
  the adaptive LQG's default before; ``default`` in the commands printed before).

Usage: ``python benchmarks/bench_warmup_excitation.py [--scenario paddle_rotation]
[--task regulation] [--snr-db 40] [--seeds 10] [--amplitudes 1.0 0.5]
[--identifiers truth scheduled fast] [--workers 2]``
"""

from __future__ import annotations

import argparse
import collections
from concurrent.futures import ProcessPoolExecutor

import gymnasium as gym
import numpy as np
from bench_adaptive_ablation import CLOSED_LOOP_SETTINGS, LateTruth

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import (
    AdaptiveLQG,
    LQRWeights,
    OracleLQG,
    episode_metrics,
    fast_identifier,
    run_episode,
    scheduled_identifier,
)
from controllers.excitation import BinaryExcitation
from spacecraft_lab.control import env_id, env_kwargs_for

PARTS = ("attitude", "rate", "deflection", "torque")


def _controller(env: gym.Env, identifier: str, amplitude: float):
    if identifier == "oracle":
        return OracleLQG(env, LQRWeights())
    if identifier == "truth":
        ident = LateTruth(env)
        ident.warmup = CLOSED_LOOP_SETTINGS["warmup"]
    elif identifier == "scheduled":
        ident = scheduled_identifier(env)
    elif identifier == "scheduled-held":
        ident = scheduled_identifier(env, accumulate=False)
    else:
        ident = fast_identifier(env)
    ctrl = AdaptiveLQG(env, weights=LQRWeights(), identifier=ident)
    # the default's excitation with another warm-up amplitude
    ctrl.excitation = BinaryExcitation(warmup_amplitude=amplitude, amplitude=0.0,
                                       warmup_steps=ctrl.excitation.warmup_steps)
    return ctrl


def _episode(job: tuple) -> dict:
    scenario, task, snr_db, seed, identifier, amplitude = job
    env = gym.make(env_id(scenario), **env_kwargs_for(scenario, task=task, snr_db=snr_db))
    ctrl = _controller(env, identifier, amplitude)
    m = episode_metrics(run_episode(env, ctrl, seed=seed), env.unwrapped.model)
    return {"seed": seed, "identifier": identifier, "amplitude": amplitude,
            "cost": m["cost_after_100s"],
            "split": [m[f"cost_{part}_after_100s"] for part in PARTS],
            "gain_error": m["gain_error_after_60s"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paddle_rotation")
    parser.add_argument("--task", default="regulation", choices=("slew", "regulation"))
    parser.add_argument("--snr-db", type=float, default=40.0,
                        help="measurement SNR per channel, dB (negative: noise-free)")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--amplitudes", type=float, nargs="+", default=[1.0, 0.5],
                        help="warm-up amplitudes to compare, N m per axis")
    parser.add_argument("--identifiers", nargs="+", default=["truth", "scheduled", "fast"],
                        choices=("truth", "scheduled", "scheduled-held", "fast"))
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    snr = None if args.snr_db < 0 else args.snr_db
    seeds = range(args.seeds)
    jobs = [(args.scenario, args.task, snr, s, "oracle", 0.0) for s in seeds]
    jobs += [(args.scenario, args.task, snr, s, ident, amp) for ident in args.identifiers
             for amp in args.amplitudes for s in seeds]
    rows = collections.defaultdict(dict)
    with ProcessPoolExecutor(args.workers) as pool:
        for done, row in enumerate(pool.map(_episode, jobs), 1):
            rows[(row["identifier"], row["amplitude"])][row["seed"]] = row
            print(f"\r{done}/{len(jobs)} episodes", end="", flush=True)
    print(f"\n{args.scenario}, {args.task}, SNR {snr} dB, {args.seeds} seeds; cost from 100 s "
          "/ oracle LQG, paired: median [worst]; split over the oracle's cost (median)")
    oracle = rows[("oracle", 0.0)]
    print(f"{'identifier':>14} {'warm-up N m':>11} {'cost/oracle':>18} "
          f"{'att / rate / defl / torque':>28} {'gain error from 60 s':>21}")
    for ident in args.identifiers:
        for amp in args.amplitudes:
            per = rows[(ident, amp)]
            ratio = [per[s]["cost"] / oracle[s]["cost"] for s in seeds]
            split = np.median([np.array(per[s]["split"]) / oracle[s]["cost"] for s in seeds],
                              axis=0)
            errors = [per[s]["gain_error"] for s in seeds if per[s]["gain_error"] is not None]
            error = f"{np.median(errors):.0%}" if errors else "-"
            print(f"{ident:>14} {amp:>11.2f} {np.median(ratio):>9.2f} [{np.max(ratio):>5.2f}] "
                  f"{' / '.join(f'{v:.2f}' for v in split):>28} {error:>21}")


if __name__ == "__main__":
    main()
