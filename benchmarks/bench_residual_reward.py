"""Does subtracting the base's own reward help a residual agent learn? Side by side.

A PPO residual on a base controller (``--features``, default the fixed LQG) is
trained on the task family with the common cost as reward (``reward="cost"``),
once with that reward ("plain") and once with the base's reward on the same
episode subtracted ("base-relative", ``spacecraft train --relative-to-base``:
:class:`controllers.BaseRelativeReward`, a twin of the env with the same draw and
the same sensor noise, flown by the base alone). Both arms are
:func:`spacecraft_lab.training.run_training` runs of the residual setting (the
residual scaled by ``RESIDUAL_SCALE``, a decision every ``RESIDUAL_REPEAT``
samples, the last layer zeroed so an untrained agent flies its base,
``VecNormalize``), scored on its ten held-out episodes beside the base, which
is one of its comparators.

Usage: ``python benchmarks/bench_residual_reward.py [--timesteps 800000] [--seed 1]
[--log-std-init -2] [--arms plain base-relative] [--features residual-fixed]
[--out results/bench_residual_reward]`` (about 17 and 24 minutes for the two arms
at 800k env steps on one core, plus the comparators' first scoring).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from spacecraft_lab.training import FEATURES, run_training

SCENARIO = "family"


def train_and_score(features: str, relative: bool, timesteps: int, seed: int,
                    log_std_init: float, out: Path) -> dict:
    """One arm: a ``run_training`` run of one seed, evaluated once at the end; its final
    scores, its base's on the same episodes, the exploration's end and the time."""
    from stable_baselines3 import PPO  # the rl extra

    m = run_training("ppo", features, timesteps, seeds=1, first_seed=seed, out=out,
                     scenario=SCENARIO, eval_every=timesteps, reward="cost",
                     log_std_init=log_std_init, relative_to_base=relative, progress=True)
    run = m["runs"][0]
    model = PPO.load(out / f"ppo-{features}-seed{seed}.zip", device="cpu")
    return {"minutes": run["env_steps"] / run["env_steps_per_s"] / 60,
            "median": run["final"]["cost_after_100s"],
            "mean": run["final"]["cost_after_100s_mean"],
            "per_episode": run["final"]["cost_after_100s_per_seed"],
            "base": m[m["base_comparator"]],
            "log_std_end": float(model.policy.log_std.mean().detach())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=800_000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--log-std-init", type=float, default=-2.0)
    parser.add_argument("--features", default="residual-fixed",
                        choices=[f for f in FEATURES if f.startswith("residual-")])
    parser.add_argument("--arms", nargs="+", default=["plain", "base-relative"],
                        choices=["plain", "base-relative"])
    parser.add_argument("--out", type=Path, default=Path("results/bench_residual_reward"))
    args = parser.parse_args()
    for arm in args.arms:
        r = train_and_score(args.features, arm == "base-relative", args.timesteps, args.seed,
                            args.log_std_init, args.out / arm)
        base = r["base"]
        print(f"base ({args.features}): median {base['cost_after_100s']:.5f}, "
              f"mean {base['cost_after_100s_mean']:.4g}", flush=True)
        print(f"{arm:14s} median {r['median']:.5f} ({r['median'] / base['cost_after_100s']:.2f}x "
              f"base), mean {r['mean']:.4g} ({r['mean'] / base['cost_after_100s_mean']:.2f}x), "
              f"log std {args.log_std_init:g} -> {r['log_std_end']:.2f}, "
              f"{r['minutes']:.1f} min", flush=True)
        print(json.dumps({"arm": arm, **{k: v for k, v in r.items() if k != "base"}}),
              flush=True)


if __name__ == "__main__":
    main()
