"""Environment throughput: steps per second per scenario, beside Pendulum-v1.

Measures, in one run on this machine:

* single env (``gym.make``, with the standard wrappers) for each scenario,
  first episode (cold matrix cache) and a repeated episode (warm cache),
* ``gym.make_vec(..., num_envs=8, vectorization_mode="sync")``, env steps/s,
* Gymnasium's ``Pendulum-v1`` the same way, as the yardstick.

Every rate is printed beside Pendulum-v1's, measured in the same run.

Usage: ``python benchmarks/bench_env.py [--steps 2500] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import numpy as np

from spacecraft_env import ENV_IDS

IDS = {scenario: env_id for env_id, scenario in ENV_IDS.items()}


def single_rate(env_id: str, steps: int, episodes: int = 1) -> list[float]:
    """Steps/s of consecutive ``steps``-long runs of one env (zero action)."""
    env = gym.make(env_id)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.reset(seed=0)
    rates = []
    for _ in range(episodes):
        env.reset()
        start = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        rates.append(steps / (time.perf_counter() - start))
    env.close()
    return rates


def vec_rate(env_id: str, steps: int, num_envs: int = 8) -> float:
    """Env steps/s of a synchronous vector env (``num_envs`` steps per call)."""
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync")
    envs.reset(seed=0)
    action = np.zeros((num_envs, *envs.single_action_space.shape), dtype=np.float32)
    calls = max(1, steps // num_envs)
    start = time.perf_counter()
    for _ in range(calls):
        envs.step(action)
    rate = calls * num_envs / (time.perf_counter() - start)
    envs.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2500)
    parser.add_argument("--json", default=None, help="write the figures to this file")
    args = parser.parse_args()

    pend_single = max(single_rate("Pendulum-v1", args.steps, episodes=3))
    pend_vec = vec_rate("Pendulum-v1", args.steps * 4)
    rows = []
    for name, env_id in IDS.items():
        cold, warm = single_rate(env_id, args.steps, episodes=2)
        vec = vec_rate(env_id, args.steps * 4)
        rows.append({"scenario": name, "single_cold": cold, "single_warm": warm,
                     "vec8_sync": vec, "ratio_cold": cold / pend_single,
                     "ratio_warm": warm / pend_single, "ratio_vec": vec / pend_vec})

    print(f"Pendulum-v1: single {pend_single:10,.0f} steps/s   make_vec(8, sync) "
          f"{pend_vec:10,.0f} env-steps/s")
    print(f"{'scenario':<16}{'single, 1st ep':>16}{'single, repeat':>16}{'vec8 sync':>12}"
          f"{'1st/Pend':>10}{'rep/Pend':>10}{'vec/Pend':>10}")
    for r in rows:
        print(f"{r['scenario']:<16}{r['single_cold']:>16,.0f}{r['single_warm']:>16,.0f}"
              f"{r['vec8_sync']:>12,.0f}{r['ratio_cold']:>10.0%}{r['ratio_warm']:>10.0%}"
              f"{r['ratio_vec']:>10.0%}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"pendulum_single": pend_single, "pendulum_vec8": pend_vec, "rows": rows},
                      fh, indent=2)


if __name__ == "__main__":
    main()
