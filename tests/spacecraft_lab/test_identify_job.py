"""The identification job: the same numbers on a process pool as in one process."""

from __future__ import annotations

import json
import math

import pytest

from spacecraft_lab.identification import run_identification


def _numbers(metrics, path=""):
    """Every numeric leaf but the wall times, with its path."""
    if isinstance(metrics, dict):
        for key, value in metrics.items():
            if key != "time_s":
                yield from _numbers(value, f"{path}/{key}")
    elif isinstance(metrics, list):
        for i, value in enumerate(metrics):
            yield from _numbers(value, f"{path}[{i}]")
    elif isinstance(metrics, float):
        yield path, metrics


def test_seeds_on_a_process_pool_give_the_serial_numbers(tmp_path):
    options = dict(methods=["rigid-flexible"], n_samples=800, convergence_s=50.0,
                   progress=False)
    serial = run_identification("docking", 3, tmp_path / "serial", workers=1, **options)
    pooled = run_identification("docking", 3, tmp_path / "pooled", workers=2, **options)
    a, b = dict(_numbers(serial)), dict(_numbers(pooled))
    assert a.keys() == b.keys() and len(a) > 50
    for key, value in a.items():
        assert b[key] == pytest.approx(value, rel=1e-9, nan_ok=True) or \
            (math.isnan(value) and math.isnan(b[key])), key
    assert json.loads((tmp_path / "pooled" / "metrics.json").read_text())["seeds"] == 3
    with pytest.raises(ValueError, match="workers"):
        run_identification("docking", 1, tmp_path / "bad", workers=0, **options)
    assert not (tmp_path / "bad").exists()             # refused before anything was written
