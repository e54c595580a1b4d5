"""BLAS threads: per-step cost with 1 and 2 BLAS threads, the library's guard on and off.

The library runs its per-sample kernels single-threaded whatever the caller's
BLAS setting (:mod:`spacecraft_conventions.blas`). This benchmark measures,
in one process and one run, three paths users never wrap themselves:

* ``update()`` of the default identifier,
* a step of the identified-model features wrapper (env step + identifier),
* a step of the adaptive LQG (identifier + re-design + act) plus the env step,

each with BLAS limited to 1 thread and to 2 threads by the caller, and with
the library's guard switched off (``single_threaded_blas.enabled = False``)
at 2 threads: what users got before. Printed: seconds per 1000 steps and the
ratio 2 threads / 1 thread.

Usage: ``python benchmarks/bench_threads.py [--steps 1500]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np
from threadpoolctl import threadpool_limits

from controllers import AdaptiveLQG, IdentifiedModelFeatures, fast_identifier
from identifiers import default_identifier
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import FlexibleSpacecraftModel


def identifier_path(steps: int) -> Callable[[], float]:
    truth = FlexibleSpacecraftModel(scenario="docking")
    rng = np.random.default_rng(0)
    u = rng.normal(size=(steps, 3))
    y = truth.simulate(u)[1]

    def run() -> float:
        ident = default_identifier()
        start = time.perf_counter()
        for k in range(steps):
            ident.update(u[k], y[k])
        return time.perf_counter() - start

    return run


def features_path(steps: int) -> Callable[[], float]:
    def run() -> float:
        env = IdentifiedModelFeatures(gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2"))
        env.reset(seed=0)
        action = np.full(3, 0.05, dtype=np.float32)
        start = time.perf_counter()
        for _ in range(steps):
            env.step(action)
        return time.perf_counter() - start

    return run


def adaptive_path(steps: int) -> Callable[[], float]:
    def run() -> float:
        env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2")
        ctrl = AdaptiveLQG(env.unwrapped, identifier=fast_identifier(env))
        obs, info = env.reset(seed=0)
        ctrl.reset(0)
        start = time.perf_counter()
        for _ in range(steps):
            obs, _, _, _, info = env.step(ctrl.act(obs, info))
        return time.perf_counter() - start

    return run


def timed(run: Callable[[], float], threads: int, guard: bool) -> float:
    single_threaded_blas.enabled = guard
    try:
        with threadpool_limits(limits=threads, user_api="blas"):
            return min(run() for _ in range(2))
    finally:
        single_threaded_blas.enabled = True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    args = parser.parse_args()
    paths = {"identifier update": identifier_path(args.steps),
             "features wrapper step": features_path(args.steps),
             "adaptive LQG + env step": adaptive_path(args.steps)}
    per = 1000.0 / args.steps
    print(f"{'path':<26}{'1 thread':>11}{'2 threads':>11}{'ratio':>8}"
          f"{'2 thr, guard off':>18}{'ratio':>8}   (s per 1000 steps)")
    for name, run in paths.items():
        one = timed(run, 1, True) * per
        two = timed(run, 2, True) * per
        off = timed(run, 2, False) * per
        print(f"{name:<26}{one:>11.3f}{two:>11.3f}{two / one:>8.2f}{off:>18.3f}"
              f"{off / one:>8.2f}")


if __name__ == "__main__":
    main()
