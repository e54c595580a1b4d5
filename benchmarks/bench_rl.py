"""PPO training throughput: our env with and without model features, beside Pendulum-v1.

Measures, in one run on this machine, stable-baselines3 PPO (``MlpPolicy``,
default hyperparameters, one env, torch on one thread) training env steps
per second on

* Gymnasium's ``Pendulum-v1`` (the yardstick),
* ``FlexibleSpacecraftDocking-v2`` (slew task) with no features,
* the same with :class:`controllers.IdentifiedModelFeatures` (the default
  identifier runs every step),
* the same with :class:`controllers.OracleModelFeatures` (truth features),
* the task family with no features, with :class:`controllers.PhysicalFeatures`
  (the identifier's physical estimates, the default identifier every step),
  the same from the identifier the agents' adaptive LQG flies
  (:func:`controllers.fast_identifier`, the closed-loop settings: no re-search,
  no change test) and with :class:`controllers.PrivilegedFeatures` (the same
  from the truth).

and prints every rate beside the no-feature rate and Pendulum's.

Usage: ``python benchmarks/bench_rl.py [--steps 8192] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import torch
from stable_baselines3 import PPO

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import (
    IdentifiedModelFeatures,
    OracleModelFeatures,
    PhysicalFeatures,
    PrivilegedFeatures,
    fast_identifier,
)
from spacecraft_conventions import single_threaded_blas


def _loop_features(env: gym.Env) -> PhysicalFeatures:
    """The physical features from the identifier the agents' adaptive LQG flies
    (:func:`controllers.fast_identifier`: the default's closed-loop settings)."""
    return PhysicalFeatures(env, identifier=fast_identifier(env))


CASES = {
    "Pendulum-v1": lambda: gym.make("Pendulum-v1"),
    "docking, no features": lambda: gym.make("FlexibleSpacecraftDocking-v2", task="slew"),
    "docking, identified features": lambda: IdentifiedModelFeatures(
        gym.make("FlexibleSpacecraftDocking-v2", task="slew")),
    "docking, oracle features": lambda: OracleModelFeatures(
        gym.make("FlexibleSpacecraftDocking-v2", task="slew")),
    "family, no features": lambda: gym.make("FlexibleSpacecraftFamily-v2", task="slew"),
    "family, physical features": lambda: PhysicalFeatures(
        gym.make("FlexibleSpacecraftFamily-v2", task="slew")),
    "family, physical features, loop identifier": lambda: _loop_features(
        gym.make("FlexibleSpacecraftFamily-v2", task="slew")),
    "family, privileged features": lambda: PrivilegedFeatures(
        gym.make("FlexibleSpacecraftFamily-v2", task="slew")),
}


def ppo_rate(make, steps: int) -> float:
    """PPO training env steps/s (after a first rollout that builds everything)."""
    model = PPO("MlpPolicy", make(), n_steps=2048, seed=0, verbose=0)
    model.learn(2048)
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=8192)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    with single_threaded_blas:
        rates = {name: ppo_rate(make, args.steps) for name, make in CASES.items()}
    pend = rates["Pendulum-v1"]
    print(f"PPO training env steps/s ({args.steps} steps, one env, torch on one thread); "
          "'/ no features': against the same task without features")
    print(f"{'case':<44}{'steps/s':>10}{'/ no features':>15}{'/ Pendulum':>12}")
    for name, rate in rates.items():
        plain = rates.get(f"{name.split(',')[0]}, no features", rate)
        print(f"{name:<44}{rate:>10,.0f}{rate / plain:>15.2f}{rate / pend:>12.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rates, fh, indent=2)


if __name__ == "__main__":
    main()
