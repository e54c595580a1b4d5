"""Environment throughput: steps per second per scenario, beside Pendulum-v1.

Measures, in one run on this machine:

* single env (``gym.make``, with the standard wrappers) for each scenario,
  first episode (a new env with cold matrix caches, as in a new process),
  a repeated episode (warm caches) and ``randomize=True`` episodes (a new
  scenario draw every reset; the second of two, cold start),
* ``gym.make_vec(..., num_envs=8)`` with ``vectorization_mode="sync"`` and
  ``"async"`` (subprocesses), env steps/s from new envs,
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
from tqdm.auto import tqdm

from spacecraft_env import ENV_IDS

IDS = {scenario: env_id for env_id, scenario in ENV_IDS.items()}


def single_rate(env_id: str, steps: int, repeats: int = 3, **kwargs) -> tuple[float, float]:
    """Steps/s of a new env's first ``steps`` and of a second run after a reset.

    The best of ``repeats`` new envs (zero action; the least disturbed run, as
    ``timeit`` reports, and the same statistic for every env, the yardstick
    included), each started with cold
    matrix caches (``clear_cache`` empties the process-wide ones too); a run
    that ends its episode resets and goes on. With ``randomize=True`` every
    reset draws a new scenario, so the second run is a new draw too.
    """
    first, second = [], []
    for _ in range(repeats):
        env = gym.make(env_id, **kwargs)
        model = getattr(env.unwrapped, "model", None)
        if model is not None:
            model.clear_cache()   # cold: also the process-wide caches other envs filled
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        env.reset(seed=0)
        for rates in (first, second):
            env.reset()
            start = time.perf_counter()
            for _ in range(steps):
                _, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    env.reset()
            rates.append(steps / (time.perf_counter() - start))
        env.close()
    return float(np.max(first)), float(np.max(second))


def vec_rate(env_id: str, steps: int, num_envs: int = 8, mode: str = "sync") -> float:
    """Env steps/s of a new vector env (``num_envs`` steps per call)."""
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode)
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

    # every single-env rate first, then the vector envs: the subprocesses of an async
    # vector env still exiting took CPU from the next single-env measurement
    pend_first, pend_repeat = single_rate("Pendulum-v1", args.steps)
    pend_single = max(pend_first, pend_repeat)
    singles = {}
    for name, env_id in tqdm(IDS.items(), desc="single envs", leave=False):
        cold, warm = single_rate(env_id, args.steps)
        randomized = min(single_rate(env_id, args.steps, randomize=True))
        singles[name] = (cold, warm, randomized)
    pend = {"sync": vec_rate("Pendulum-v1", args.steps * 4),
            "async": vec_rate("Pendulum-v1", args.steps * 4, mode="async")}
    rows = []
    for name, env_id in tqdm(IDS.items(), desc="vector envs", leave=False):
        cold, warm, randomized = singles[name]
        sync = vec_rate(env_id, args.steps * 4)
        asyn = vec_rate(env_id, args.steps * 4, mode="async")
        rows.append({"scenario": name, "single_first": cold, "single_repeat": warm,
                     "single_randomized": randomized, "vec8_sync": sync, "vec8_async": asyn,
                     "ratio_first": cold / pend_first, "ratio_repeat": warm / pend_repeat,
                     "ratio_randomized": randomized / pend_single,
                     "ratio_sync": sync / pend["sync"], "ratio_async": asyn / pend["async"]})

    print(f"Pendulum-v1: single {pend_first:,.0f} (1st ep) / {pend_repeat:,.0f} (repeat) "
          f"steps/s; make_vec(8) sync "
          f"{pend['sync']:,.0f}, async {pend['async']:,.0f} env-steps/s")
    print("env steps/s, and in brackets the ratio to Pendulum-v1 measured the same way")
    heads = ("single, 1st ep", "single, repeat", "randomized", "vec8 sync", "vec8 async")
    keys = ("first", "repeat", "randomized", "sync", "async")
    cols = ("single_first", "single_repeat", "single_randomized", "vec8_sync", "vec8_async")
    print(f"{'scenario':<16}" + "".join(f"{h:>17}" for h in heads))
    for r in rows:
        cells = "".join(f"{r[c]:>10,.0f} ({r['ratio_' + k]:>3.0%})"
                        for c, k in zip(cols, keys, strict=True))
        print(f"{r['scenario']:<16}{cells}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"pendulum_single": pend_single, "pendulum_first": pend_first,
                       "pendulum_repeat": pend_repeat, "pendulum_vec8": pend, "rows": rows},
                      fh, indent=2)


if __name__ == "__main__":
    main()
