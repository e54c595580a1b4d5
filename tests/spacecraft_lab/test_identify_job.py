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


def test_the_figures_of_the_identify_command_show_their_point(tmp_path):
    """`spacecraft identify`'s figures on a small case: every figure written; the
    prediction figure has at most five series per panel with an interquartile band, its
    legend outside the data and an axis that starts near the lowest median; the modal
    figure's line styles are explained by a legend, not by a paragraph of a title."""
    from spacecraft_lab.plots import PREDICTION_SERIES, plot_prediction_horizons

    metrics = run_identification("docking", 2, tmp_path, n_samples=800, convergence_s=50.0,
                                 methods=["rigid-flexible", "improved-rpbsid", "classical-rpbsid",
                                          "predictor-rpbsid"], progress=False)
    for name in ("prediction", "gain", "modal", "responses"):
        assert (tmp_path / f"{name}.png").stat().st_size > 20_000, name
    fig = plot_prediction_horizons(tmp_path / "again.png", metrics, {}, None)
    for ax in fig.axes:
        labels = [line.get_label() for line in ax.get_lines()]
        assert 2 <= len(labels) <= 5 and set(labels) <= set(PREDICTION_SERIES), labels
        assert ax.get_legend() is None and ax.get_ylim()[1] <= 101
        assert len(ax.collections) == len(labels)            # one band per series
    assert len(fig.legends) == 1
    summary = metrics["methods"]["classical-rpbsid"]["summary"]["h_step_vaf"]
    cell = summary[str(metrics["horizons_samples"][-1])]["rate"]
    assert cell["q25"] <= cell["median"] <= cell["q75"]
    ylim = fig.axes[1].get_ylim()[0]
    lowest = min(metrics["methods"][m]["summary"]["h_step_vaf"][h]["rate"]["median"]
                 for m in metrics["methods"] if m in PREDICTION_SERIES
                 for h in map(str, metrics["horizons_samples"]))
    assert max(0.0, lowest - 10) <= ylim <= max(lowest, 0.0)

    assert len(fig.get_suptitle()) < 110

    # the terminal's table: at most 100 columns, a row per method, no 100-digit numbers
    from spacecraft_lab.reporting import identification_brief

    brief = identification_brief(metrics).splitlines()
    assert max(map(len, brief)) <= 100 and len(brief) == 2 + len(metrics["methods"])
    assert not any("e+" in line for line in brief)


def test_a_diverged_seed_counts_as_the_worst_value_in_either_direction():
    """A diverged seed (None) is the worst: +inf for a test error (lower is better), -inf
    for a VAF; the median of a majority of diverged seeds is None (strict JSON), and the
    table says "diverged", never "-inf"."""
    from spacecraft_lab.identification import _aggregate
    from spacecraft_lab.reporting import _median

    seeds = [{"test_error_pct": [1.0], "vaf": 1.0}, {"test_error_pct": [None], "vaf": None},
             {"test_error_pct": [3.0], "vaf": 3.0}]
    out = _aggregate(seeds)
    assert out["test_error_pct"][0]["median"] == 3.0 and out["vaf"]["median"] == 1.0
    assert out["vaf"]["diverged"] == 1
    most = _aggregate([{"e": None}, {"e": None}, {"e": 2.0}])["e"]
    assert most["median"] is None and most["diverged"] == 2
    assert _median(most) == "diverged"
    json.dumps(out, allow_nan=False)


def test_the_adaptive_lqgs_identifier_runs_from_the_identify_command(tmp_path):
    """``scheduled-physical`` (the adaptive LQG's identifier) is a method of `spacecraft
    identify`, fed the drive's angle at every sample: on paddle rotation it predicts the
    tip deflections 10 s ahead better than persistence."""
    metrics = run_identification("paddle_rotation", 1, tmp_path, n_samples=800,
                                 convergence_s=50.0, methods=["scheduled-physical"],
                                 progress=False)
    vaf = {name: metrics["methods"][name]["summary"]["h_step_vaf"][
        str(metrics["horizons_samples"][-1])]["deflection"]["median"]
        for name in ("scheduled-physical", "persistence")}
    assert vaf["scheduled-physical"] > max(95.0, vaf["persistence"] + 5.0), vaf
