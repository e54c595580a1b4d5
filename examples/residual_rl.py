"""Residual RL: PPO corrects a fixed LQG's torque, seeing the identifier's estimates.

``ResidualControl`` adds the agent's action (scaled by 0.25) to the base
controller's; ``PhysicalFeatures`` sits outside it, so the identifier sees the
whole torque. A silent agent (zero residual) flies exactly the base design.

    python examples/residual_rl.py                       # 400k env steps
    python examples/residual_rl.py --timesteps 20000
"""

import argparse

import gymnasium as gym
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from controllers import FixedLQG, PhysicalFeatures, ResidualControl, episode_metrics, run_episode
from spacecraft_env import ActionRepeat
from spacecraft_lab.training import NormalizedPolicy

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--timesteps", type=int, default=400_000, help="env steps (0.1 s each)")
args = parser.parse_args()

ENV = "spacecraft_env:FlexibleSpacecraftFamily-v2"
KWARGS = {"task": "slew", "reward": "bounded"}


def residual_env() -> gym.Env:
    inner = gym.make(ENV, **KWARGS)
    return PhysicalFeatures(ResidualControl(inner, FixedLQG(inner.unwrapped)))


venv = VecNormalize(DummyVecEnv([lambda: ActionRepeat(residual_env(), 10)]))
venv.seed(0)
decisions = max(args.timesteps // 10, 1)
# PPO collects n_steps decisions before its first update (SB3's default 2048): a smaller
# budget gets a smaller rollout, a multiple of the 64-decision mini-batch
model = PPO("MlpPolicy", venv, seed=0, n_steps=min(2048, max(64, decisions // 64 * 64)),
            policy_kwargs={"log_std_init": -1.0})
model.learn(total_timesteps=decisions)
venv.training = False

env = residual_env()
with_agent = episode_metrics(run_episode(env, NormalizedPolicy(model, venv, "residual", 10),
                                         seed=1000), env.unwrapped.model)
base_env = gym.make(ENV, **KWARGS)
base = episode_metrics(run_episode(base_env, FixedLQG(base_env.unwrapped), seed=1000),
                       base_env.unwrapped.model)
print(f"cost from 100 s: fixed LQG {base['cost_after_100s']:.4g}, "
      f"fixed LQG + residual PPO {with_agent['cost_after_100s']:.4g}")
