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
from spacecraft_lab.training import NormalizedPolicy, ppo_rollout

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
# PPO trains whole rollouts: the rollout nearest SB3's 2048 decisions that makes the
# budget whole ones, so it trains exactly the decisions asked
n_steps, batch_size = ppo_rollout(decisions)
model = PPO("MlpPolicy", venv, seed=0, n_steps=n_steps, batch_size=batch_size,
            policy_kwargs={"log_std_init": -1.0})
model.learn(total_timesteps=decisions)
venv.training = False

agent = NormalizedPolicy(model, venv, "PPO + physical", repeat=REPEAT)
scored = []
for seed in range(1000, 1000 + args.episodes):
    env = PhysicalFeatures(gym.make(ENV, **KWARGS))
    mine = episode_metrics(run_episode(env, agent, seed=seed), env.unwrapped.model)
    plain = gym.make(ENV, **KWARGS)
    oracle = episode_metrics(run_episode(plain, OracleLQG(plain.unwrapped), seed=seed),
                             plain.unwrapped.model)
    scored.append(mine["cost_after_100s"])
    # a short budget's policy may leave the attitude bound: its cost is infinite
    outcome = ("crashed (left the attitude bound)" if not np.isfinite(scored[-1]) else
               f"{scored[-1]:.4g} (ratio {scored[-1] / oracle['cost_after_100s']:.3g})")
    print(f"episode {seed}: PPO cost from 100 s {outcome}, oracle LQG "
          f"{oracle['cost_after_100s']:.4g}; attitude RMS {mine['attitude_rms_deg']:.2f} deg")
print(f"trained {model.num_timesteps * REPEAT:,} env steps; the full comparison with "
      "intervals: spacecraft train --scenario family --features physical, then spacecraft "
      "evaluate (docs/results/rl.md)")
assert model.num_timesteps == decisions and len(scored) == args.episodes
