"""Train PPO on the task family with the identifier's physical estimates.

The recommended stack: the family env (a new plant every episode), the slew task
and the bounded reward; ``PhysicalFeatures`` appends what the online identifier
knows (rigid-body gain, dominant modes, their uncertainty, a change flag);
``ActionRepeat`` makes one decision per second; ``VecNormalize`` scales the
observations. Scores on the common quadratic cost beside the oracle LQG.

    python examples/train_ppo_family.py                  # 800k env steps, ~10 min
    python examples/train_ppo_family.py --timesteps 20000
"""

import argparse

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from controllers import OracleLQG, PhysicalFeatures, episode_metrics, run_episode
from spacecraft_env import ActionRepeat
from spacecraft_lab.training import NormalizedPolicy

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--timesteps", type=int, default=800_000, help="env steps (0.1 s each)")
parser.add_argument("--episodes", type=int, default=3, help="evaluation episodes")
args = parser.parse_args()

ENV = "spacecraft_env:FlexibleSpacecraftFamily-v2"
KWARGS = {"task": "slew", "reward": "bounded"}
REPEAT = 10


def make_env() -> gym.Env:
    return Monitor(ActionRepeat(PhysicalFeatures(gym.make(ENV, **KWARGS)), REPEAT))


venv = VecNormalize(DummyVecEnv([make_env]), norm_obs=True, norm_reward=True, clip_obs=10.0)
venv.seed(0)
decisions = max(args.timesteps // REPEAT, 1)
# PPO collects n_steps decisions before its first update (SB3's default 2048): a smaller
# budget gets a smaller rollout, a multiple of the 64-decision mini-batch
model = PPO("MlpPolicy", venv, seed=0, n_steps=min(2048, max(64, decisions // 64 * 64)),
            policy_kwargs={"log_std_init": -1.0})
model.learn(total_timesteps=decisions)
venv.training = False

agent = NormalizedPolicy(model, venv, "PPO + physical", repeat=REPEAT)
for seed in range(1000, 1000 + args.episodes):
    env = PhysicalFeatures(gym.make(ENV, **KWARGS))
    mine = episode_metrics(run_episode(env, agent, seed=seed), env.unwrapped.model)
    plain = gym.make(ENV, **KWARGS)
    oracle = episode_metrics(run_episode(plain, OracleLQG(plain.unwrapped), seed=seed),
                             plain.unwrapped.model)
    print(f"episode {seed}: PPO cost from 100 s {mine['cost_after_100s']:.4g}, "
          f"oracle LQG {oracle['cost_after_100s']:.4g} "
          f"(ratio {mine['cost_after_100s'] / oracle['cost_after_100s']:.3g}); "
          f"attitude RMS {mine['attitude_rms_deg']:.2f} deg")
print("the full comparison: spacecraft train --scenario family --features physical "
      "(docs/results/rl.md)")
np.testing.assert_equal(np.isfinite(mine["cost_after_100s"]), True)
