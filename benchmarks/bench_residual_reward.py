"""Does subtracting the base's own reward help a residual agent learn? Side by side.

A PPO residual on a base controller (``--features``, default the fixed LQG) is
trained on the task family with the common cost as reward (``reward="cost"``),
once with that reward ("plain") and once with the base's reward on the same
episode subtracted (:class:`controllers.BaseRelativeReward`: a twin of the env,
same draw and same sensor noise, flown by the base alone). Everything else is
the ``spacecraft train`` residual setting: the residual scaled by
``RESIDUAL_SCALE``, a decision every ``RESIDUAL_REPEAT`` samples, the last layer
zeroed (an untrained agent flies its base), ``VecNormalize``. Each arm is scored
on the ten held-out episodes of ``spacecraft train`` beside its base.

Usage: ``python benchmarks/bench_residual_reward.py [--timesteps 800000] [--seed 1]
[--log-std-init -2] [--arms plain base-relative] [--features residual-fixed]``
(about 17 and 24 minutes for the two arms at 800k env steps on one core).
"""

from __future__ import annotations

import argparse
import json
import time
from functools import partial

from controllers import BaseRelativeReward
from spacecraft_env import ActionRepeat
from spacecraft_lab import training as T

SCENARIO = "family"


def _env(features: str, relative: bool):
    from stable_baselines3.common.monitor import Monitor

    env = T._make_env(SCENARIO, features, T._training_env_kwargs(False, "cost"))
    if relative:
        env = BaseRelativeReward(env)
    return Monitor(ActionRepeat(env, T.RESIDUAL_REPEAT))


def train_and_score(features: str, relative: bool, timesteps: int, seed: int,
                    log_std_init: float) -> dict:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    torch.set_num_threads(1)
    venv = VecNormalize(DummyVecEnv([partial(_env, features, relative)]), norm_obs=True,
                        norm_reward=True, clip_obs=10.0)
    venv.seed(seed)
    model = PPO("MlpPolicy", venv, seed=seed, verbose=0,
                policy_kwargs={"log_std_init": log_std_init})
    model.set_logger(Logger(folder=None, output_formats=[]))
    T._start_at_the_base(model)
    tic = time.perf_counter()
    model.learn(total_timesteps=-(-timesteps // T.RESIDUAL_REPEAT))
    venv.training = False
    policy = T.NormalizedPolicy(model, venv, "residual", T.RESIDUAL_REPEAT)
    score = T._evaluate(policy, SCENARIO, features, T._training_env_kwargs(False, "cost"))
    return {"minutes": (time.perf_counter() - tic) / 60, "median": score["cost_after_100s"],
            "mean": score["cost_after_100s_mean"],
            "per_episode": score["cost_after_100s_per_seed"],
            "log_std_end": float(model.policy.log_std.mean().detach())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=800_000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--log-std-init", type=float, default=-2.0)
    parser.add_argument("--features", default="residual-fixed", choices=sorted(T._RESIDUAL))
    parser.add_argument("--arms", nargs="+", default=["plain", "base-relative"],
                        choices=["plain", "base-relative"])
    args = parser.parse_args()
    base = T._evaluate(T._RESIDUAL[args.features], SCENARIO, "none",
                       T._training_env_kwargs(False, "cost"))
    print(f"base ({args.features}): median {base['cost_after_100s']:.5f}, "
          f"mean {base['cost_after_100s_mean']:.4g}", flush=True)
    for arm in args.arms:
        r = train_and_score(args.features, arm == "base-relative", args.timesteps, args.seed,
                            args.log_std_init)
        print(f"{arm:14s} median {r['median']:.5f} ({r['median'] / base['cost_after_100s']:.2f}x "
              f"base), mean {r['mean']:.4g} ({r['mean'] / base['cost_after_100s_mean']:.2f}x), "
              f"log std {args.log_std_init:g} -> {r['log_std_end']:.2f}, "
              f"{r['minutes']:.1f} min", flush=True)
        print(json.dumps({"arm": arm, **r}), flush=True)


if __name__ == "__main__":
    main()
