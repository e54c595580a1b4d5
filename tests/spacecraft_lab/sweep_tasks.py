"""Task functions for test_sweeps.py (importable by spawned workers)."""

from __future__ import annotations

import math
import os


def affine(*, seed: int, slope: float = 1.0, offset: float = 0.0, fail_on: int = -1) -> dict:
    """metrics: value = slope * seed + offset, diverged-like NaN for seed 99."""
    if seed == fail_on:
        raise RuntimeError(f"planned failure on seed {seed}")
    value = math.nan if seed == 99 else slope * seed + offset
    return {"metrics": {"value": value, "even": seed % 2 == 0, "series": [seed, seed]},
            "timings": {"time_s": 0.001 * (seed + 1)}}


def crash(*, seed: int) -> dict:
    """Kills its worker process (a segfault or OOM kill, as the pool sees it)."""
    os._exit(3)


def not_a_dict(*, seed: int) -> list:
    return [seed]


def sleepy(*, seed: int, duration: float = 0.3) -> dict:
    """Takes ``duration`` seconds; reports its worker's pid."""
    import time

    time.sleep(duration)
    return {"metrics": {"seed": seed}, "timings": {"pid": os.getpid()}}
