"""benchmarks/bench_tracking.py: its one pass over a record and the README's command."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from identifiers import default_identifier
from spacecraft_lab.identification import env_record


def test_the_pass_in_stretches_is_one_fit_and_reads_the_bands_on_the_way(load_benchmark):
    bench = load_benchmark("bench_tracking")
    u, y, _, _ = env_record("docking", 0, 40.0, steps=700)
    seq, bands = bench.run(default_identifier(), u, y, None)
    whole = default_identifier().fit(u, y)
    np.testing.assert_array_equal(seq.valid, whole.valid)
    np.testing.assert_array_equal(seq.A[whole.valid], whole.A[whole.valid])
    np.testing.assert_array_equal(seq.states[whole.valid], whole.states[whole.valid])
    loop = default_identifier()
    for k in range(700):
        loop.update(u[k], y[k])
        if k % 10 == 0 and bands[k] is not None:
            np.testing.assert_array_equal(bands[k].gain, loop.rigid_gain.gain)
    assert sorted(bands) == list(range(0, 700, 10)) and bands[690] is not None


def test_the_readmes_command_runs_the_scheduled_fit(load_benchmark, monkeypatch, capsys):
    """`python benchmarks/bench_tracking.py --identifier scheduled --seeds 10`, its
    arguments parsed and handed on (each record's scoring stubbed: minutes each; one
    worker, so the stub is the one called)."""
    bench = load_benchmark("bench_tracking")
    calls = []

    def score(scenario, seed, snr, rms, identifier, **options):
        calls.append((scenario, seed, snr, rms, identifier, options))
        return {"vaf": {row: [99.0, 98.0, 97.0] for row in
                        ("persistence", "frozen", "identifier")},
                "mode_error_pct": 0.1, "frozen_mode_error_pct": 1.46, "gain_error_pct": 0.4,
                "coverage": 0.9, "change_events": [], "seconds": 1.0}

    monkeypatch.setattr(bench, "score", score)
    monkeypatch.setattr(sys, "argv", ["bench_tracking.py", "--identifier", "scheduled",
                                      "--seeds", "10", "--hold-through-changes",
                                      "--scenarios", "paddle_rotation", "--workers", "1"])
    bench.main()
    assert len(calls) == 50 and {c[4] for c in calls} == {"scheduled"}
    assert all(c[5] == {"refit_on_change": False} for c in calls)
    assert "identifier: scheduled" in capsys.readouterr().out


def test_the_re_search_ablation_reaches_the_default_identifier(load_benchmark, monkeypatch):
    """`--rediscover none`: the default identifier without re-searches (the cost
    ablation of docs/benchmarks.md); the scheduled fit has no such option."""
    bench = load_benchmark("bench_tracking")
    calls = []
    monkeypatch.setattr(bench, "score", lambda *args, **options: calls.append(options) or {
        "vaf": {row: [99.0] * 3 for row in ("persistence", "frozen", "identifier")},
        "mode_error_pct": 0.1, "frozen_mode_error_pct": 1.46, "gain_error_pct": 0.4,
        "coverage": 0.9, "change_events": [], "seconds": 1.0})
    argv = ["bench_tracking.py", "--seeds", "1", "--scenarios", "docking",
            "--conditions", "40:1", "--workers", "1", "--rediscover"]
    monkeypatch.setattr(sys, "argv", [*argv, "none"])
    bench.main()
    monkeypatch.setattr(sys, "argv", [*argv, "250"])
    bench.main()
    assert calls == [{"rediscover": None}, {"rediscover": 250}]
    monkeypatch.setattr(sys, "argv", [*argv, "none", "--identifier", "scheduled"])
    with pytest.raises(SystemExit):
        bench.main()


def test_each_behaviour_of_the_cost_ablation_is_an_option_of_the_default(load_benchmark,
                                                                         monkeypatch):
    """benchmarks/bench_identifier_parts.py --behaviours: every variant builds and runs
    (a 60 s record, one round) and is timed, beside the bare RLS of the same record."""
    # the script imports its sibling bench_identifiers, as when run from benchmarks/
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    bench = load_benchmark("bench_identifier_parts")
    truth, u, y = bench.record()
    bare, best = bench.behaviours(truth, u[:600], y[:600], repeats=1)
    assert set(best) == set(bench.BEHAVIOURS) and len(best) == 6
    assert bench.BEHAVIOURS["no re-search after the warm-up's"] == {"rediscover": None}
    # times only (no assertion on them: a cold numba cache or a busy machine moves them)
    assert bare > 0 and all(0 < t < np.inf for t in best.values())
