"""Our batch PBSID against SRIM (mdof) on the same data: the issue's goal, measured.

Slow and needs the optional peers: ``make test-peers`` builds their environment
and runs this file. Without them it is skipped.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mdof")
pytest.importorskip("sippy_unipi")
pytest.importorskip("osysid")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def bench(load_benchmark):
    return load_benchmark("bench_peers")


@pytest.fixture(scope="module")
def results(bench):
    return bench.run(seeds=3, methods=("pbsid", "srim", "sippy-n4sid"))


def test_pbsid_at_least_as_accurate_as_srim_and_ten_times_faster(results):
    ours, srim = results["batch"]["pbsid"], results["batch"]["srim"]
    med = lambda rows, key: float(np.median([r[key] for r in rows]))  # noqa: E731
    assert med(ours, "test_error_attitude") <= 7.0
    assert med(ours, "test_error_attitude") <= med(srim, "test_error_attitude") * 1.1
    ratio = np.median([s["time_s"] / o["time_s"] for o, s in zip(ours, srim, strict=True)])
    assert ratio >= 10.0


def test_every_peer_ran_and_was_scored(results):
    for name, rows in results["batch"].items():
        assert len(rows) == 3 and all("error" not in r for r in rows), name
    for seed_rows in results["online"]:
        assert set(seed_rows) == {"rigid-flexible", "classical", "osysid-arx", "persistence"}


def test_online_default_beats_persistence_on_every_group(results):
    for seed_rows in results["online"]:
        for group in ("attitude", "rate", "deflection"):
            assert seed_rows["rigid-flexible"][group] > seed_rows["persistence"][group]
