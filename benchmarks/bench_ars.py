"""What each choice of ``spacecraft train --algo ars`` buys: one arm per choice removed.

Trains a linear policy with augmented random search on the task family (slew
task, cost reward, one decision a second, the attitude error and rate observed),
scoring it every ``--eval-every`` env steps through the harness on the ten
evaluation episodes (seeds 1000-1009) beside the oracle LQG on the same episodes,
and prints the median and mean cost from 100 s over the oracle's, after the same
ratios for attitude PD laws (:class:`controllers.PD`: a linear map of the same two
signals, the policy class's reach). Arms:

* ``paired``: the training job's setting (:func:`spacecraft_lab.random_search.paired_ars`:
  each antithetic pair on one episode, centred; observations in nominal units,
  :class:`spacecraft_env.NominalUnits`; rewarded from 100 s,
  :class:`controllers.ScoredWindowReward`);
* ``whole-episode``: the same, rewarded over the whole episode (the slew included);
* ``unpaired``: sb3-contrib's ARS itself (every candidate on its own episode), in
  nominal units, rewarded from 100 s;
* ``running-norm``: sb3-contrib's ARS with SB3's running observation normalization
  (``VecNormalize``, as ARS's "V2" and rl-zoo3 run it), rewarded over the whole episode.

Usage: ``python benchmarks/bench_ars.py [--arms paired unpaired] [--steps 1600000]
[--eval-every 400000] [--seed 0] [--json out.json]``; an arm takes about a minute per
400k env steps on one core (run arms in separate processes to use more).
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib import ARS
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from controllers import PD, Controller, OracleLQG, ScoredWindowReward, episode_metrics, run_episode
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import ActionRepeat, NominalUnits, env_id
from spacecraft_lab.random_search import paired_ars
from spacecraft_lab.training import ACTION_REPEAT, EVAL_SEEDS, NormalizedPolicy

OUTPUTS = ("attitude_error", "rate")
#: (bandwidth rad/s, damping) of the PD laws printed beside the arms (controllers.PD's
#: default first)
PD_GRID = ((0.05, 0.7), (0.06, 0.85), (0.08, 0.85), (0.1, 0.7))
#: arm: (paired, nominal units, rewarded from 100 s)
ARMS = {"paired": (True, True, True), "whole-episode": (True, True, False),
        "unpaired": (False, True, True), "running-norm": (False, False, False)}


def _env(nominal: bool) -> gym.Env:
    env = gym.make(env_id("family"), task="slew", reward="cost", outputs=OUTPUTS)
    return NominalUnits(env) if nominal else env


def _costs(controller, nominal: bool | None) -> np.ndarray:
    """Cost from 100 s on the evaluation episodes (inf for a crash); ``nominal`` None:
    the env's standard observation (for the LQGs), else the agents' (in nominal units
    or not)."""
    costs = []
    with single_threaded_blas:
        for seed in EVAL_SEEDS:
            env = (gym.make(env_id("family"), task="slew", reward="cost") if nominal is None
                   else _env(nominal))
            make = (lambda _: controller) if isinstance(controller, Controller) \
                else controller
            traj = run_episode(env, make(env.unwrapped), seed=seed)
            costs.append(episode_metrics(traj, env.unwrapped.model)["cost_after_100s"])
    costs = np.array(costs, dtype=float)
    costs[np.isnan(costs)] = np.inf
    return costs


def train_arm(arm: str, steps: int, eval_every: int, seed: int,
              oracle: np.ndarray) -> list[dict[str, float]]:
    paired, nominal, window = ARMS[arm]

    def make() -> gym.Env:
        env = _env(nominal)
        if window:
            env = ScoredWindowReward(env)
        return Monitor(ActionRepeat(env, ACTION_REPEAT))

    venv = VecNormalize(DummyVecEnv([make]), norm_obs=not nominal, norm_reward=False)
    venv.seed(seed)
    model = (paired_ars() if paired else ARS)("LinearPolicy", venv, seed=seed)
    curve, done, started = [], 0, time.perf_counter()
    while done < steps:
        model.learn(eval_every // ACTION_REPEAT, reset_num_timesteps=False)
        done += eval_every
        venv.training = False
        costs = _costs(NormalizedPolicy(model, venv, arm, ACTION_REPEAT), nominal)
        venv.training = True
        point = {"env_steps": int(model.num_timesteps * ACTION_REPEAT),
                 "median_over_oracle": float(np.median(costs) / np.median(oracle)),
                 "mean_over_oracle": float(np.mean(costs) / np.mean(oracle)),
                 "seconds": time.perf_counter() - started}
        curve.append(point)
        print(f"{arm:<14}{point['env_steps']:>10,}{point['median_over_oracle']:>10.2f}"
              f"{point['mean_over_oracle']:>10.2f}{point['seconds']:>9.0f}", flush=True)
    return curve


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", choices=list(ARMS), default=list(ARMS))
    parser.add_argument("--steps", type=int, default=1_600_000)
    parser.add_argument("--eval-every", type=int, default=400_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    oracle = _costs(OracleLQG, None)
    print(f"oracle LQG on the {len(EVAL_SEEDS)} evaluation episodes: median "
          f"{np.median(oracle):.5f}, mean {np.mean(oracle):.5f} (cost from 100 s)")
    # the policy class's reach: attitude PD laws (a linear map of the same two signals,
    # acting every 0.1 s) on the same episodes
    for bandwidth, damping in PD_GRID:
        costs = _costs(lambda env, b=bandwidth, z=damping: PD(env, b, z), None)
        print(f"PD {bandwidth:.2f} rad/s, damping {damping:.2f}: median / oracle "
              f"{np.median(costs) / np.median(oracle):.2f}, mean / oracle "
              f"{np.mean(costs) / np.mean(oracle):.2f}")
    print(f"{'arm':<14}{'env steps':>10}{'median/or':>10}{'mean/or':>10}{'s':>9}")
    curves = {arm: train_arm(arm, args.steps, args.eval_every, args.seed, oracle)
              for arm in args.arms}
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"seed": args.seed, "curves": curves}, fh, indent=2)


if __name__ == "__main__":
    main()
