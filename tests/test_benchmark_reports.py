"""The reports of the ceiling check and the fault table: what they flag, print and keep."""

from __future__ import annotations

import json

import numpy as np


def _condition(**costs):
    """A condition of a ``bench_ceiling --out`` file: controller -> key -> per-seed costs."""
    return {name: {"cost": list(c[0]), "cost_after_start": list(c[1]),
                   "cost_after_100s": list(c[2])} for name, c in costs.items()}


def test_the_ceiling_check_flags_a_controller_below_any_ceiling(load_benchmark):
    bench = load_benchmark("bench_ceiling")
    fine = _condition(**{"ceiling": ([1.0, 1.0], [0.5, 0.5], [0.1, 0.1]),
                         "same-start ceiling": ([1.1, 1.1], [0.2, 0.2], [0.1, 0.1]),
                         "window ceiling": ([2.0, 2.0], [1.0, 1.0], [1e-6, 1e-6]),
                         "robust LQG": ([1.05, 1.2], [0.3, 0.3], [0.2, 0.3])})
    assert bench.check(fine)[1] == []
    below_window = dict(fine, **_condition(PD=([1.1, 1.1], [0.3, 0.3], [5e-7, 2e-6])))
    (violation,) = bench.check(below_window)[1]
    assert violation.startswith("PD: from 100 s 0.500 of the window ceiling")
    # the same-start ceiling bounds only the loops that fly its start
    loop = dict(fine, **_condition(**{"adaptive LQG": ([1.1, 1.1], [0.1, 0.3], [0.1, 0.1])}))
    (violation,) = bench.check(loop)[1]
    assert "after the start 0.500 of the same-start ceiling" in violation
    table = bench.markdown({"conditions": {"constant/slew": below_window}})
    assert "| constant, slew | 1 |" in table and table.rstrip().endswith("| 0.500 |")


def test_the_ceiling_check_extends_a_stored_run_with_the_missing_controllers(
        load_benchmark, tmp_path, capsys):
    bench = load_benchmark("bench_ceiling")
    out = tmp_path / "ceiling.json"
    common = ["--seeds", "1", "--steps", "60", "--scenarios", "constant", "--tasks",
              "regulation", "--workers", "1", "--out", str(out)]
    assert bench.main([*common, "--controllers", "pd"]) == 0
    first = json.loads(out.read_text())["conditions"]["constant/regulation"]
    assert set(first) == {"PD", "window ceiling", "same-start ceiling", "ceiling"}
    assert bench.main([*common, "--controllers", "pd", "robust-lqg", "--extend",
                       str(out)]) == 0
    second = json.loads(out.read_text())["conditions"]["constant/regulation"]
    assert set(second) == set(first) | {"robust LQG"}
    assert all(second[name] == first[name] for name in first)    # kept, not flown again
    capsys.readouterr()


def test_the_fault_table_counts_declarations_and_their_delays(load_benchmark):
    bench = load_benchmark("bench_faults")
    row = {"clean": [1.0, 2.0],
           **{name: {"late": [2.0, 4.0], "stable": [True, False],
                     "verdict": ["stable", "growing"]} for name in bench.FLOWN},
           "declared": [[{"kind": "gyro bias", "detected_s": bench.ONSET_S + 6.0}],
                        [{"kind": "gyro bias", "detected_s": bench.ONSET_S + 8.0}]]}
    assert bench._detection(row) == (2, 7.0)
    report = {"alarm_seeds": 3, "faults": {"docking/gyro bias": row},
              "false_alarms": {"constant": [[], [], [{"kind": "gyro bias"}]]}}
    text = bench.markdown(report)
    assert "| docking | gyro bias | 1 / 1 / 1 (of 2) | 2 | 1 | 1 | 2/2 (gyro bias) | 7.0 |" \
        in text
    assert "(3 seeds each): constant 1." in text
    assert "fault-free family draws" not in text
    text = bench.markdown(dict(report, false_alarms_fast_family=[[], [{"kind": "a"}] * 2]))
    assert "on 2 fault-free family draws: 2." in text
    assert np.isnan(bench._detection(dict(row, declared=[[], []]))[1])
