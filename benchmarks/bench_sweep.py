"""Sweep throughput: the same grid run serially and on the local process pool, one run.

The grid is real work: classical RPBSID at the paper's constants and the
default rigid-flexible identifier on the docking record (n = 22, 250 s at
40 dB), ``--seeds`` seeds each. The
serial backend runs the tasks one after another in this process; the local
backend runs them on a ``spawn`` pool with one worker per core (process
start-up and imports included in its time). Optionally the Ray backend on a
new local instance (``--ray``; start-up included). The metrics of every
backend must agree bit for bit.

Printed: wall time of each backend and its speed-up over serial, with a check
that every backend computed the same numbers.

Usage: ``python benchmarks/bench_sweep.py [--seeds 8] [--workers 2] [--ray] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from spacecraft_lab.sweeps import ResultStore, SweepConfig, run_sweep


def grid(seeds: int) -> SweepConfig:
    return SweepConfig.from_dict({
        "name": "bench", "task": "identify", "seeds": seeds,
        "params": {"scenario": "docking", "order": 22},
        "cases": [{"method": "classical-rpbsid", "preset": "paper"}, {"method": "rigid-flexible"}],
    })


def timed(config: SweepConfig, backend: str, workers: int | None, root: Path) -> tuple:
    out = root / backend
    start = time.perf_counter()
    report = run_sweep(config, out, backend, workers=workers, progress=False, summarize=False)
    wall = time.perf_counter() - start
    if report.errors:
        raise RuntimeError(f"{backend}: {report.errors} tasks failed")
    metrics = {k: r["metrics"] for k, r in ResultStore(out / "results.jsonl").load().items()}
    busy = sum(r["wall_s"] for r in ResultStore(out / "results.jsonl"))
    return wall, busy, metrics


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--ray", action="store_true", help="also time the Ray backend")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    config = grid(args.seeds)
    n_tasks = len(config.tasks())
    backends = ["serial", "local"] + (["ray"] if args.ray else [])
    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in backends:
            res[name] = timed(config, name, None if name == "serial" else args.workers,
                              Path(tmp))
    serial_wall = res["serial"][0]
    print(f"grid: {n_tasks} identify tasks (classical + moment-refit, n = 22, "
          f"{args.seeds} seeds), {args.workers} workers, {os.cpu_count()} cores")
    print(f"{'backend':8s} {'wall (s)':>9s} {'task time (s)':>14s} {'speed-up':>9s} "
          f"{'efficiency':>11s} {'same numbers':>13s}")
    out = {"tasks": n_tasks, "workers": args.workers, "cores": os.cpu_count(), "backends": {}}
    for name, (wall, busy, metrics) in res.items():
        speedup = serial_wall / wall
        workers = 1 if name == "serial" else args.workers
        same = metrics == res["serial"][2]
        print(f"{name:8s} {wall:9.2f} {busy:14.2f} {speedup:8.2f}x {speedup / workers:10.0%} "
              f"{same!s:>13s}")
        out["backends"][name] = {"wall_s": wall, "task_s": busy, "speedup": speedup,
                                 "identical_metrics": same}
    goal = res["local"][0] * 1.8 <= serial_wall
    print(f"goal local >= 1.8x serial: {'met' if goal else 'MISSED'} "
          f"({serial_wall / res['local'][0]:.2f}x)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
