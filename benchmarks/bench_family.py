"""Does the adaptation task need adaptation? Fixed, robust, adaptive and oracle LQG per draw.

On ``FlexibleSpacecraftFamily-v2`` (slew task), each seed draws one plant
(:class:`spacecraft_env.TaskFamily`); every controller flies the same draw.
Printed: per controller, the share of draws it leaves unstable (verdict not
"stable") and the share where its common cost from 100 s is at least twice
the oracle LQG's; the median cost ratio to the oracle; and, per draw, the
drawn values beside the fixed design's verdict. The family needs adaptation
if the fixed LQG fails (unstable or >= 2x the oracle's cost) on at least 30 %
of the draws while the oracle is stable on all.

Usage: ``python benchmarks/bench_family.py [--draws 30] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json

import gymnasium as gym
import numpy as np

from controllers import AdaptiveLQG, FixedLQG, OracleLQG, RobustLQG, episode_metrics, run_episode
from spacecraft_conventions import single_threaded_blas

CONTROLLERS = {"fixed LQG": FixedLQG, "robust LQG": RobustLQG, "adaptive LQG": AdaptiveLQG,
               "oracle LQG": OracleLQG}


def run(draws: int, controllers: dict = CONTROLLERS) -> dict:
    env = gym.make("spacecraft_env:FlexibleSpacecraftFamily-v2", task="slew")
    out: dict = {"draws": [], "runs": {name: [] for name in controllers}}
    for seed in range(draws):
        for name, make in controllers.items():
            traj = run_episode(env, make(env.unwrapped), seed=seed)
            m = episode_metrics(traj, env.unwrapped.model)
            out["runs"][name].append({"cost": m["cost_after_100s"], "verdict": m["verdict"],
                                      "attitude_rms_deg": m["attitude_rms_after_100s_deg"]})
        out["draws"].append(env.unwrapped.plant.as_dict())
    return out


def summarize(res: dict) -> dict:
    oracle = np.array([r["cost"] for r in res["runs"]["oracle LQG"]])
    table = {}
    for name, runs in res["runs"].items():
        cost = np.array([r["cost"] for r in runs])
        unstable = np.array([r["verdict"] != "stable" for r in runs])
        ratio = cost / oracle
        table[name] = {"unstable_share": float(unstable.mean()),
                       "twice_oracle_share": float(np.mean(ratio >= 2.0)),
                       "failed_share": float(np.mean(unstable | (ratio >= 2.0))),
                       "median_cost_ratio": float(np.nanmedian(ratio))}
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=30)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    with single_threaded_blas:
        res = run(args.draws)
    table = summarize(res)
    print(f"{args.draws} draws of FlexibleSpacecraftFamily-v2 (slew); cost from 100 s")
    print(f"{'controller':<14}{'unstable':>10}{'>= 2x oracle':>14}{'failed':>9}"
          f"{'median cost / oracle':>22}")
    for name, row in table.items():
        print(f"{name:<14}{row['unstable_share']:>10.2f}{row['twice_oracle_share']:>14.2f}"
              f"{row['failed_share']:>9.2f}{row['median_cost_ratio']:>22.2f}")
    print("per draw: paddle angle (deg), rate (deg/s), inertia scale, fixed LQG verdict, "
          "fixed / oracle cost")
    for draw, fixed, oracle in zip(res["draws"], res["runs"]["fixed LQG"],
                                   res["runs"]["oracle LQG"], strict=True):
        print(f"  {draw['paddle_angle_deg']:6.1f} {draw['paddle_rate_deg_s']:+5.2f} "
              f"{draw['inertia_scale']:4.2f}  {fixed['verdict']:<10} "
              f"{fixed['cost'] / oracle['cost']:8.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"table": table, **res}, fh, indent=1)


if __name__ == "__main__":
    main()
