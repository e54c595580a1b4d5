"""What each choice of ``spacecraft train --algo ars`` buys: one arm per choice removed.

Trains a linear policy with augmented random search on the task family (slew
task, cost reward, one decision a second, the attitude error and rate observed),
scoring it every ``--eval-every`` env steps through the harness on the ten
evaluation episodes (seeds 1000-1009) beside the oracle LQG on the same episodes,
and prints the median and mean cost from 100 s over the oracle's, after the same
ratios for attitude PD laws (:class:`controllers.PD`: a linear map of the same two
signals, the policy class's reach), acting every 0.1 s and once a second on the last
sample or on the second's mean. Arms:

* ``paired``: the training job's setting (:func:`spacecraft_lab.random_search.paired_ars`:
  each antithetic pair on one episode, centred; observations in nominal units,
  :class:`spacecraft_env.NominalUnits`; rewarded from 100 s,
  :class:`controllers.ScoredWindowReward`);
* ``whole-episode``: the same, rewarded over the whole episode (the slew included);
* ``unpaired``: sb3-contrib's ARS itself (every candidate on its own episode), in
  nominal units, rewarded from 100 s;
* ``running-norm``: sb3-contrib's ARS with SB3's running observation normalization
  (``VecNormalize``, as ARS's "V2" and rl-zoo3 run it), rewarded over the whole episode;
* ``averaged``: the training job's ``attitude-error-averaged`` setting, each observation
  the mean of the last second's samples (:class:`spacecraft_env.ObservationAverage`).

Usage: ``python benchmarks/bench_ars.py [--arms paired unpaired] [--steps 1600000]
[--eval-every 400000] [--seed 0] [--json out.json]`` (``--arms`` with no name: the PD
laws only); an arm takes about a minute per 400k env steps on one core (run arms in
separate processes to use more).
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
from spacecraft_env import ActionRepeat, NominalUnits, ObservationAverage, env_id
from spacecraft_lab.random_search import paired_ars
from spacecraft_lab.training import ACTION_REPEAT, EVAL_SEEDS, NormalizedPolicy

OUTPUTS = ("attitude_error", "rate")
#: (bandwidth rad/s, damping) of the PD laws printed beside the arms (controllers.PD's
#: default first)
PD_GRID = ((0.05, 0.7), (0.06, 0.85), (0.08, 0.85), (0.1, 0.7))
#: arm: (paired, nominal units, rewarded from 100 s, the second's mean observed)
ARMS = {"paired": (True, True, True, False), "whole-episode": (True, True, False, False),
        "unpaired": (False, True, True, False), "running-norm": (False, False, False, False),
        "averaged": (True, True, True, True)}


def _env(nominal: bool, averaged: bool = False) -> gym.Env:
    env = gym.make(env_id("family"), task="slew", reward="cost", outputs=OUTPUTS)
    if averaged:
        env = ObservationAverage(env, ACTION_REPEAT)
    return NominalUnits(env) if nominal else env


def _costs(controller, nominal: bool | None, averaged: bool = False) -> np.ndarray:
    """Cost from 100 s on the evaluation episodes (inf for a crash); ``nominal`` None:
    the env's standard observation (for the LQGs), else the agents' (in nominal units
    or not)."""
    costs = []
    with single_threaded_blas:
        for seed in EVAL_SEEDS:
            env = (gym.make(env_id("family"), task="slew", reward="cost") if nominal is None
                   else _env(nominal, averaged))
            make = (lambda _: controller) if isinstance(controller, Controller) \
                else controller
            traj = run_episode(env, make(env.unwrapped), seed=seed)
            costs.append(episode_metrics(traj, env.unwrapped.model)["cost_after_100s"])
    costs = np.array(costs, dtype=float)
    costs[np.isnan(costs)] = np.inf
    return costs


class _Held(Controller):
    """A controller deciding every ``hold`` steps, on the last observation or (``average``)
    on the mean of the observations since its last decision, its action held between."""

    def __init__(self, inner: Controller, hold: int, average: bool) -> None:
        self.inner, self.hold, self.average = inner, hold, average
        self.name = inner.name
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.inner.reset(seed)
        self._recent: list[np.ndarray] = []
        self._held: np.ndarray | None = None
        self._age = 0

    def act(self, obs, info=None) -> np.ndarray:
        self._recent = [*self._recent[-(self.hold - 1):], np.asarray(obs, dtype=float)] \
            if self.hold > 1 else [np.asarray(obs, dtype=float)]
        if self._held is None or self._age >= self.hold:
            seen = np.mean(self._recent, axis=0) if self.average else self._recent[-1]
            self._held, self._age = self.inner.act(seen, info), 0
        self._age += 1
        return self._held


def train_arm(arm: str, steps: int, eval_every: int, seed: int,
              oracle: np.ndarray) -> list[dict[str, float]]:
    paired, nominal, window, averaged = ARMS[arm]

    def make() -> gym.Env:
        env = _env(nominal, averaged)
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
        costs = _costs(NormalizedPolicy(model, venv, arm, ACTION_REPEAT), nominal, averaged)
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
    parser.add_argument("--arms", nargs="*", choices=list(ARMS), default=list(ARMS))
    parser.add_argument("--steps", type=int, default=1_600_000)
    parser.add_argument("--eval-every", type=int, default=400_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    oracle = _costs(OracleLQG, None)
    print(f"oracle LQG on the {len(EVAL_SEEDS)} evaluation episodes: median "
          f"{np.median(oracle):.5f}, mean {np.mean(oracle):.5f} (cost from 100 s)")
    # the policy class's reach: attitude PD laws (a linear map of the same two signals)
    # on the same episodes, acting every 0.1 s, and deciding once a second as the agents
    # do, on that sample or on the mean of the second's samples
    print("PD laws, median / mean episode's cost over the oracle's: every 0.1 s; held 1 s "
          "(last sample); held 1 s (mean of the second's samples)")
    for bandwidth, damping in PD_GRID:
        cells = []
        for hold, average in ((1, False), (ACTION_REPEAT, False), (ACTION_REPEAT, True)):
            costs = _costs(lambda env, b=bandwidth, z=damping, h=hold, a=average:
                           _Held(PD(env, b, z), h, a), None)
            cells.append(f"{np.median(costs) / np.median(oracle):5.2f} / "
                         f"{np.mean(costs) / np.mean(oracle):5.2f}")
        print(f"  PD {bandwidth:.2f} rad/s, damping {damping:.2f}:  " + ";  ".join(cells))
    print(f"{'arm':<14}{'env steps':>10}{'median/or':>10}{'mean/or':>10}{'s':>9}")
    curves = {arm: train_arm(arm, args.steps, args.eval_every, args.seed, oracle)
              for arm in args.arms}
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"seed": args.seed, "curves": curves}, fh, indent=2)


if __name__ == "__main__":
    main()
