"""Minimal use of the registered environments: a random-torque rollout.

    python examples/env_rollout.py
"""

import gymnasium as gym
import numpy as np

env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2")
obs, info = env.reset(seed=0)
total = 0.0
for _ in range(1000):
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    total += reward
    if terminated or truncated:
        break
model = env.unwrapped.model
true = model.discrete(info["time"])          # true (A, B, C, D) right now
print(f"t = {info['time']:.1f} s, return {total:.1f}, state order n = {true.A.shape[0]}")
print("J(t) diagonal (kg m^2):", np.round(np.diag(model.inertia(info["time"])), 1))
