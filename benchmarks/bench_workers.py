"""Seeds on every core: the comparison and the identification job, serial beside pooled.

Runs, one after the other in this process, the same job with ``workers=1``
and with one worker per core (``os.cpu_count()``), checks that both give the
same numbers, and prints the wall times and their ratio:

* :func:`controllers.compare` of the robust, adaptive and oracle LQG on the
  docking scenario (``--control-seeds``, default 4);
* :func:`spacecraft_lab.identification.run_identification` on docking
  (``--identify-seeds``, default 10; the bar of the performance work is a
  ratio of at most 0.6 on a 2-core machine).

Usage: ``python benchmarks/bench_workers.py [--control-seeds 4] [--identify-seeds 10]``
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from functools import partial

import gymnasium as gym
import numpy as np

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import AdaptiveLQG, OracleLQG, RobustLQG, compare
from spacecraft_lab.identification import run_identification


def _costs(table: dict) -> np.ndarray:
    return np.array([[m["cost_after_100s"] for m in row["per_seed"]]
                     for row in table.values()])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--control-seeds", type=int, default=4)
    parser.add_argument("--identify-seeds", type=int, default=10)
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    print(f"{cores} cores; wall time, serial beside {cores} workers, same run")

    factories = {"robust": partial(RobustLQG), "adaptive": partial(AdaptiveLQG),
                 "oracle": partial(OracleLQG)}
    make_env = partial(gym.make, "spacecraft_env:FlexibleSpacecraftDocking-v2", task="slew")
    seeds = list(range(args.control_seeds))
    times, tables = [], []
    for workers in (1, cores):
        start = time.perf_counter()
        table, _ = compare(factories, make_env, seeds, progress=False, workers=workers)
        times.append(time.perf_counter() - start)
        tables.append(_costs(table))
    same = np.allclose(tables[0], tables[1], rtol=1e-9, atol=0.0)
    print(f"compare, docking, {len(seeds)} seeds x 3 controllers: {times[0]:6.1f} s serial, "
          f"{times[1]:6.1f} s pooled, ratio {times[1] / times[0]:.2f}; same costs: {same}")

    times, medians = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for workers in (1, cores):
            start = time.perf_counter()
            m = run_identification("docking", args.identify_seeds, f"{tmp}/w{workers}",
                                   progress=False, workers=workers)
            times.append(time.perf_counter() - start)
            medians.append(m["methods"]["rigid-flexible"]["summary"]["test_error_pct"])
    print(f"spacecraft identify, docking, {args.identify_seeds} seeds: {times[0]:6.1f} s "
          f"serial, {times[1]:6.1f} s pooled, ratio {times[1] / times[0]:.2f} (bar 0.6); "
          f"same numbers: {medians[0] == medians[1]}")


if __name__ == "__main__":
    main()
