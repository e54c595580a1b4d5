"""Markdown tables of the experiments' results.

Each function formats what an experiment wrote to ``metrics.json``:
:func:`identification_table` (``spacecraft identify``), :func:`control_table`
(``spacecraft control``) and :func:`rl_table` (``spacecraft rl-table``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from controllers.harness import SAME_START_S
from spacecraft_lab.rl_protocol import (
    improvement_probabilities,
    interval_estimates,
    protocol_table,
)

__all__ = [
    "CEILING",
    "COMPARATOR_NAMES",
    "FAST_ADAPTIVE_LQG",
    "SAME_START_CEILING",
    "SAME_START_LOOPS",
    "WINDOW_CEILING",
    "control_brief",
    "control_summary",
    "control_table",
    "fallback_causes_text",
    "flies_the_start",
    "identification_brief",
    "identification_table",
    "improvement_references",
    "load_training_metrics",
    "paired_cost_ratio",
    "pooled_training_runs",
    "rl_protocol_report",
    "rl_table",
    "training_metrics_problem",
]


def _median(cell: dict[str, Any] | None, scale: float = 1.0, digits: int = 1) -> str:
    if not cell or cell.get("median") is None:
        return "diverged" if cell and cell.get("diverged") else "-"
    value = cell["median"] * scale
    if abs(value) >= 1e4:
        return f"{value:.1e}"
    return f"{value:.{digits}f}"


def _spread(cell: dict[str, Any] | None, scale: float = 1.0, digits: int = 1) -> str:
    text = _median(cell, scale, digits)
    if not cell or cell.get("min") is None or text in ("-", "diverged"):
        return text
    lo, hi = cell["min"] * scale, cell["max"] * scale
    if max(abs(lo), abs(hi)) >= 1e4:
        return f"{text} [{lo:.0e}, {hi:.0e}]"
    bad = f", {cell['diverged']} diverged" if cell.get("diverged") else ""
    return f"{text} [{lo:.{digits}f}, {hi:.{digits}f}{bad}]"


#: A VAF below this (%), or an error above the next (%), is a model that diverged: shown
#: as such, not as a number of 100 digits.
DIVERGED_VAF = -1000.0
DIVERGED_ERROR_PCT = 1e4


def _brief_cell(cell: dict[str, Any] | None, scale: float = 1.0, vaf: bool = False) -> str:
    """A median for the terminal: "diverged" where the model did, "-" where none."""
    if not cell or cell.get("median") is None:
        return "diverged" if cell and cell.get("diverged") else "-"
    value = cell["median"] * scale
    if np.isnan(value):                   # nothing to score (no event in the record)
        return "-"
    if (vaf and value < DIVERGED_VAF) or (not vaf and abs(value) > DIVERGED_ERROR_PCT) \
            or not np.isfinite(value):
        return "diverged"
    return f"{value:.1f}"


def identification_brief(metrics: dict[str, Any], width: int = 100) -> str:
    """The terminal's short form of :func:`identification_table`, at most ``width``
    columns: per method (medians over seeds) the longest horizon's prediction VAF on
    attitude, rate and deflection beside persistence's and the frozen truth's rows, the
    rigid-body gain's error 20 s after events, the dominant mode's error, the paper's
    test error and the run time; a diverged model reads "diverged". The full tables
    are in ``table.md``.

    Returns
    -------
    str
        Plain text, lines at most ``width`` columns.
    """
    last = str(metrics["horizons_samples"][-1])
    ahead = int(last) * metrics["dt"]
    rows = [("method", "VAF att", "VAF rate", "VAF defl", "J^-1 err", "mode err",
             "test att/rate", "time s")]
    for name, res in metrics["methods"].items():
        s = res["summary"]
        vaf = s["h_step_vaf"][last]
        test = s.get("test_error_pct")
        if test is None:
            test_text = "-"
        else:
            cells = [c["median"] for g in ("attitude", "rate") for c in test[g]]
            test_text = ("diverged" if None in cells or max(map(abs, cells)) > DIVERGED_ERROR_PCT
                         else f"{np.mean(cells[:3]):.1f} / {np.mean(cells[3:]):.1f}")
        gain = s.get("gain_error_after_events", {}).get("median")
        mode = s.get("modal_error", {}).get("median")
        rows.append((name[:24], *(_brief_cell(vaf[g], vaf=True)
                                  for g in ("attitude", "rate", "deflection")),
                     _brief_cell(gain, 100), _brief_cell(mode, 100), test_text,
                     _brief_cell(s.get("time_s"))))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                       for i, (c, w) in enumerate(zip(r, widths, strict=True))).rstrip()
             for r in rows]
    head = (f"{metrics['scenario']}, {metrics['seeds']} seeds, SNR {metrics['snr_db']} dB: "
            f"medians; VAF {ahead:g} s ahead (%), errors (%) from "
            f"{metrics['convergence_s']:g} s")
    return "\n".join([head[:width], *(line[:width] for line in lines)]) + "\n"


def identification_table(metrics: dict[str, Any]) -> str:
    """Markdown tables of ``spacecraft identify``: h-step prediction VAF beside
    persistence and the frozen truth, then model quality, then the paper's metric.

    Returns
    -------
    str
        Markdown tables.
    """
    dt = metrics["dt"]
    head = (f"{metrics['scenario']}, preset `{metrics['preset']}`, SNR {metrics['snr_db']} dB, "
            f"n = {metrics['order_n']}, {metrics['seeds']} seeds; median [min, max] over "
            f"seeds; scored from t >= {metrics['convergence_s']:g} s")
    horizons = [str(h) for h in metrics["horizons_samples"]]
    lines = [f"### h-step-ahead prediction VAF (%): {head}", "",
             "Each cell: attitude / rate / deflection. Persistence is the trivial "
             "baseline (y_{k+h} = y_k), the frozen truth the ceiling.", "",
             "| method | " + " | ".join(f"{int(h) * dt:g} s ahead" for h in horizons)
             + " | 10 s ahead, attitude | 10 s ahead, rate | 10 s ahead, deflection |",
             "|---" * (len(horizons) + 4) + "|"]
    last = horizons[-1]
    for name, res in metrics["methods"].items():
        vaf = res["summary"]["h_step_vaf"]
        cells = [" / ".join(_median(vaf[h][g]) for g in ("attitude", "rate", "deflection"))
                 for h in horizons]
        cells += [_spread(vaf[last][g]) for g in ("attitude", "rate", "deflection")]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", f"### Model quality: {head}", "",
              "| method | J^-1 error before the 1st event (%) | J^-1 error >= 20 s after "
              "events (%), median / p90 | dominant-mode frequency error (%), median / max "
              "| models with a pole outside 1.001 (%) | test error, attitude / rate (%) "
              "| held-out one-step VAF (%) | run time (s) |",
              "|---|---|---|---|---|---|---|---|"]
    for name, res in metrics["methods"].items():
        s = res["summary"]
        if "gain_error_before_event" not in s:
            continue
        test = s["test_error_pct"]
        att = [c["median"] for c in test["attitude"]]
        rate = [c["median"] for c in test["rate"]]
        test_text = ("diverged" if None in att + rate else
                     f"{np.mean(att):.1f} / {np.mean(rate):.1f}")
        held = " / ".join(_median(s["held_out_vaf"][g]) for g in ("attitude", "rate",
                                                                  "deflection"))
        lines.append(
            f"| {name} | {_spread(s['gain_error_before_event']['median'], 100)} "
            f"| {_median(s['gain_error_after_events']['median'], 100)} / "
            f"{_median(s['gain_error_after_events']['p90'], 100)} "
            f"| {_median(s['modal_error']['median'], 100)} / "
            f"{_median(s['modal_error']['max'], 100)} "
            f"| {_median(s['unstable_share'], 100, 0)} | {test_text} | {held} "
            f"| {_median(s['time_s'], 1, 2)} |")
    paper = metrics.get("paper") or {}
    if paper:
        lines += ["", f"### The paper's test-response error (%), per channel: {head}", "",
                  "| method | psi_x | psi_y | psi_z | omega_x | omega_y | omega_z "
                  "| paper psi (x, y, z) | paper omega (x, y, z) |", "|---" * 9 + "|"]
        for name, res in metrics["methods"].items():
            s = res["summary"]
            if "test_error_pct" not in s:
                continue
            cells = [_median(c) for c in s["test_error_pct"]["attitude"]]
            cells += [_median(c) for c in s["test_error_pct"]["rate"]]
            ref = paper.get(name, {})
            pp = ", ".join(f"{x:.2f}" for x in ref.get("psi", [])) or "-"
            po = ", ".join(f"{x:.2f}" for x in ref.get("omega", [])) or "-"
            lines.append(f"| {name} | " + " | ".join(cells) + f" | {pp} | {po} |")
    return "\n".join(lines) + "\n"


#: The names the comparison gives the ceilings (:func:`controllers.ClairvoyantLQG`): of the
#: whole episode, of the cost from the adaptive loop's start behind that start, and of the
#: stationary window from 100 s (:func:`controllers.window_ceiling`).
CEILING = "ceiling"
SAME_START_CEILING = "same-start ceiling"
WINDOW_CEILING = "window ceiling"


#: The display name of the adaptive LQG on the fast identifier
#: (:func:`controllers.fast_identifier`): ``spacecraft control``'s ``adaptive-lqg-fast``, and
#: the adaptive loop the RL agents are based on and compared with (their ``adaptive_lqg``).
FAST_ADAPTIVE_LQG = "adaptive LQG, fast identifier"
#: The RL comparators' keys (``metrics.json``, ``evaluation.json``) -> their names in tables.
COMPARATOR_NAMES = {"oracle_lqg": "oracle LQG", "adaptive_lqg": FAST_ADAPTIVE_LQG,
                    "fixed_lqg": "fixed LQG", "scheduled_lqg": "scheduled LQG",
                    "zero_torque": "zero torque", "window_ceiling": WINDOW_CEILING,
                    "agent": "agent"}


def improvement_references(base: str | None) -> list[str]:
    """The comparators an agent's probability of improvement is given over.

    Parameters
    ----------
    base : str or None
        The key of its base law's comparator (a residual's), or None.

    Returns
    -------
    list of str
        Keys of :data:`COMPARATOR_NAMES`: its base, then the adaptive LQG the agents are
        compared with (once).
    """
    return list(dict.fromkeys(key for key in (base, "adaptive_lqg") if key))


#: The loops that fly the start the same-start ceiling flies (the default adaptive LQG's:
#: its identifier's warm-up behind the PD and excitation, then the first fit's latency),
#: by their names in the comparison; a loop on another identifier starts otherwise.
SAME_START_LOOPS = ("adaptive LQG",)


def flies_the_start(name: str) -> bool:
    """Whether the controller ``name`` flies the default adaptive loop's start, so the
    same-start ceiling bounds its cost from the end of that start (:data:`SAME_START_LOOPS`).

    Returns
    -------
    bool
        True for the loops that fly that start.
    """
    return name in SAME_START_LOOPS or name == SAME_START_CEILING


def control_table(table: dict[str, dict], ceiling: str | None = CEILING,
                  same_start: str | None = SAME_START_CEILING,
                  baseline: str | None = "robust LQG",
                  window: str | None = WINDOW_CEILING) -> str:
    """Markdown table of :func:`controllers.compare` results, by the evaluation protocol.

    Per controller (docs/design/evaluation.md): the common quadratic cost over the whole
    episode (the quantity every LQG here minimizes; :func:`controllers.stage_costs`),
    median [25th, 75th percentile] over seeds, and its ratio to ``ceiling``'s (the
    clairvoyant LQG: no controller can expect less) and to ``baseline``'s (the robust
    fixed design: what an adaptive loop must beat); the cost from the end of the
    adaptive loop's start (:data:`controllers.harness.SAME_START_S`) and its ratio to
    ``same_start``'s (the ceiling flown behind that start: the price of identification;
    shown for the controllers that fly that start, :func:`flies_the_start`); the
    stationary window from 100 s and its ratio to ``window``'s (the plan of that
    window's cost alone, a bound for every controller); ratios are medians of per-seed
    ratios (paired seeds). Then the split of the median whole-episode cost into
    attitude, rate, deflection and torque, with the excitation's share of the torque
    term, and the secondary columns: verdicts, attitude RMS and vibration from 100 s,
    excitation RMS, the identified rigid-body gain's median error and 2-sigma coverage
    of the truth from 60 s (pooled over the seeds' samples; controllers with an
    identifier), the share of steps the fallback flew from 60 s (after the warm-up) and
    over the episode, and why it flew from 60 s (:func:`fallback_causes_text`).

    Returns
    -------
    str
        Markdown: one row per controller.
    """
    def cell(row: dict, key: str, digits: int) -> str:
        return (f"{row['median'][key]:.{digits}g} "
                f"[{row['q25'][key]:.{digits}g}, {row['q75'][key]:.{digits}g}]")

    def gain(row: dict) -> str:
        # the error's median over seeds; the coverage pooled over every seed's samples
        # (the mean of the seeds' shares: a median of shares that are mostly 0 or 1 is
        # not a coverage)
        err, cover = row["median"]["gain_error_after_60s"], row["mean"]["gain_coverage_after_60s"]
        if not np.isfinite(err):
            return "-"
        return f"{100 * err:.0f} %, " + ("-" if not np.isfinite(cover) else f"{100 * cover:.0f} %")

    def paired(name: str, ref: str | None, key: str) -> str:
        ratio = None if ref is None else paired_cost_ratio(table, name, ref, key)
        return "-" if ratio is None else f"{ratio:.2f}"

    def after_start(name: str) -> str:
        # the same-start ceiling bounds only the loops that fly its start
        return paired(name, same_start, "cost_after_start") if flies_the_start(name) else "-"

    start = f"{SAME_START_S:g}"
    head = (f"| controller | cost, whole episode | / ceiling | / robust | cost t >= {start} s "
            "| / same-start ceiling | cost t >= 100 s | / window ceiling "
            "| split (whole): att / rate / defl / torque (excitation) | verdicts "
            "| attitude RMS t >= 100 s (deg) "
            "| vibration t >= 100 s (mm) | excitation RMS (N m) "
            "| gain error, coverage t >= 60 s | fallback flew t >= 60 s (all) "
            "| why it flew t >= 60 s |")
    lines = [head, "|" + "---|" * 16]
    for name, row in table.items():
        med = row["median"]
        verdicts = ", ".join(f"{v} {c}/{row['runs']}" for v, c in row["verdicts"].items())
        split = " / ".join(f"{med[f'cost_{p}']:.2g}"
                           for p in ("attitude", "rate", "deflection", "torque")) \
            + f" ({med['cost_excitation']:.2g})"
        cells = [cell(row, "cost", 3), paired(name, ceiling, "cost"),
                 paired(name, baseline, "cost"), cell(row, "cost_after_start", 3),
                 after_start(name), cell(row, "cost_after_100s", 3),
                 paired(name, window, "cost_after_100s"), split, verdicts,
                 cell(row, "attitude_rms_after_100s_deg", 3),
                 cell(row, "vibration_rms_after_100s_mm", 3),
                 f"{med['excitation_rms_Nm']:.3g}", gain(row),
                 f"{100 * med['fallback_share_after_60s']:.0f} % "
                 f"({100 * med['fallback_share']:.0f} %)",
                 fallback_causes_text(row.get("fallback_causes_after_60s", {})) or "-"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def fallback_causes_text(causes: dict[str, float], floor: float = 0.005) -> str:
    """``"prediction 38 %, dwell 1 %"``: the causes of :func:`controllers.fallback_causes`
    whose share of the steps from 60 s is at least ``floor``, largest first ("" if none).

    Parameters
    ----------
    causes : dict
        Cause -> share of the steps from 60 s (mean over seeds).
    floor : float
        Smallest share shown.

    Returns
    -------
    str
    """
    return ", ".join(f"{cause} {100 * share:.0f} %" for cause, share in causes.items()
                     if share >= floor)


def control_brief(table: dict[str, dict], ceiling: str | None = CEILING,
                  same_start: str | None = SAME_START_CEILING,
                  window: str | None = WINDOW_CEILING) -> str:
    """The terminal's short form of :func:`control_table`, within 100 columns for the
    default comparison: per controller the whole episode's cost (median over seeds) and
    its paired ratio to ``ceiling``, the cost from the end of the adaptive loop's start
    and its ratio to ``same_start`` (for the loops that fly that start), the stationary
    cost from 100 s and its ratio to ``window``, how many seeds were judged stable (the
    other verdicts are in ``table.md``) and the fallback's share from 60 s, aligned in
    plain text.

    Returns
    -------
    str
        Plain text: one row per controller.
    """
    rows = [("controller", "cost", "/ceil", f"from {SAME_START_S:g}s", "/start", "from 100s",
             "/window", "stable", "fallback")]
    for name, row in table.items():
        fallback = row["median"]["fallback_share_after_60s"]
        ratios = [paired_cost_ratio(table, name, ref, key) if ref is not None
                  and (key != "cost_after_start" or flies_the_start(name)) else None
                  for ref, key in ((ceiling, "cost"), (same_start, "cost_after_start"),
                                   (window, "cost_after_100s"))]
        rows.append((name, f"{row['median']['cost']:.3g}",
                     "-" if ratios[0] is None else f"{ratios[0]:.2f}",
                     f"{row['median']['cost_after_start']:.3g}",
                     "-" if ratios[1] is None else f"{ratios[1]:.2f}",
                     f"{row['median']['cost_after_100s']:.3g}",
                     "-" if ratios[2] is None else f"{ratios[2]:.3g}",
                     # how many were stable; the other verdicts are in table.md
                     f"{row['verdicts'].get('stable', 0)}/{row['runs']}",
                     "-" if not np.isfinite(fallback) or not name.startswith("adaptive LQG")
                     else f"{100 * fallback:.0f} %"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                               for i, (c, w) in enumerate(zip(r, widths, strict=True))).rstrip()
                     for r in rows) + "\n"


def _is_number(value: Any, optional: bool = True) -> bool:
    return (value is None and optional) or (
        isinstance(value, int | float) and not isinstance(value, bool))


#: Comparators a ``metrics.json`` may hold: each a table of episode figures.
_COMPARATORS = ("oracle_lqg", "adaptive_lqg", "fixed_lqg", "scheduled_lqg", "zero_torque")


def training_metrics_problem(m: Any) -> str | None:
    """What makes ``m`` not the ``metrics.json`` of a ``spacecraft train`` run (the
    fields :func:`rl_table` and the RL plots read, with their types), or None.

    Returns
    -------
    str or None
        A sentence naming the problem, or None for a valid record.
    """
    if not isinstance(m, dict):
        return f"not a JSON object but {type(m).__name__}"
    for key in ("algo", "features", "scenario"):
        if not isinstance(m.get(key), str):
            return f"{key!r} missing or not a string"
    if m.get("complete") is False:
        return ("an unfinished run (interrupted, or still training): its curve so far is "
                "under 'in_progress'")
    if not isinstance(m.get("timesteps"), int) or isinstance(m.get("timesteps"), bool):
        return "'timesteps' missing or not an integer"
    if not isinstance(m.get("relative_to_base", False), bool):
        return "'relative_to_base' is not a boolean"
    if not _is_number(m.get("reward_from_s"), optional=True):
        return "'reward_from_s' is not a number"
    # the threshold of "steps to 2x the adaptive LQG": on the cost from 100 s (files
    # written before it was, on the whole-episode attitude RMS)
    if not (_is_number(m.get("target_cost_after_100s"), optional=False)
            or _is_number(m.get("target_attitude_rms_deg"), optional=False)):
        return "'target_cost_after_100s' missing or not a number"
    runs = m.get("runs")
    if not isinstance(runs, list) or not runs:
        return "'runs' missing or not a non-empty list"
    for i, run in enumerate(runs):
        final = run.get("final") if isinstance(run, dict) else None
        if not isinstance(final, dict) or not _is_number(final.get("attitude_rms_deg"),
                                                          optional=False):
            return f"runs[{i}]['final'] missing or without a numeric 'attitude_rms_deg'"
        if not isinstance(run.get("curve"), list) or not all(
                isinstance(c, dict) and isinstance(c.get("timesteps"), int)
                for c in run["curve"]):
            return f"runs[{i}]['curve'] is not a list of points with integer 'timesteps'"
        reached = run.get("steps_to_2x_adaptive")
        if reached is not None and (not isinstance(reached, int) or isinstance(reached, bool)):
            return f"runs[{i}]['steps_to_2x_adaptive'] is neither an integer nor null"
        bad = [k for k in ("cost_after_100s", "cost_after_100s_mean", "vibration_rms_mm",
                           "return") if not _is_number(final.get(k))]
        if bad:
            return f"runs[{i}]['final'] has non-numeric {bad}"
    for key in _COMPARATORS:
        if key in m and not (isinstance(m[key], dict)
                             and _is_number(m[key].get("attitude_rms_deg"), optional=False)):
            return f"{key!r} is not a table with a numeric 'attitude_rms_deg'"
    return None


def load_training_metrics(directory: str | Path) -> dict[str, Any]:
    """The ``metrics.json`` of a ``spacecraft train`` directory, checked.

    Returns
    -------
    dict
        The metrics.

    Raises
    ------
    ValueError
        The file cannot be read or parsed, or is not a training run's metrics
        (:func:`training_metrics_problem`); the message names the file.
    """
    path = Path(directory) / "metrics.json"
    try:
        m = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ValueError(f"{path}: cannot read a training run's metrics ({reason})") from None
    problem = training_metrics_problem(m)
    if problem:
        raise ValueError(f"{path}: not the metrics of a 'spacecraft train' run: {problem}")
    return m


def pooled_training_runs(directories: Sequence[str | Path]) -> list[dict[str, Any]]:
    """The ``metrics.json`` of ``spacecraft train`` directories, one per setting.

    Directories with equal algorithm, features, task, env steps asked, decision
    period and reward (its form, whether the base's was subtracted, and from when it
    counts) are one
    setting: their seeds' runs are pooled (seeds trained in separate processes
    with ``--first-seed``). Order of first appearance.

    Returns
    -------
    list of dict
        One pooled record per setting.
    """
    settings: dict[tuple, dict[str, Any]] = {}
    for directory in directories:
        m = load_training_metrics(directory)
        # the env steps asked: ARS trains whole iterations of episodes whose lengths
        # differ, so seeds of one setting train slightly different numbers of steps
        asked = m.get("timesteps_requested", m["timesteps"])
        key = (m["algo"], m["features"], m["scenario"], m.get("randomize"), asked,
               m.get("repeat", 1), m.get("reward", "cost"), m.get("relative_to_base", False),
               m.get("reward_from_s", 0.0))
        if key in settings:
            settings[key]["runs"] = settings[key]["runs"] + m["runs"]
        else:
            settings[key] = dict(m)
    return list(settings.values())


def rl_table(directories: Sequence[str | Path]) -> str:
    """Markdown table of several ``spacecraft train`` output directories.

    Per setting (directories with equal algorithm, features, task, env
    steps, decision period and reward pool their seeds, so seeds trained in
    separate processes make one row), first the common quadratic cost from
    100 s (:func:`controllers.stage_costs`; per training seed the median
    over the evaluation episodes), then its ratio to the oracle LQG's and to
    the fixed LQG's on the same episodes, the attitude RMS, vibration,
    the env steps each seed needed to come within 2x of the adaptive LQG's
    cost from 100 s (median episode), and the cost's mean over the episodes
    (which counts an unstable episode at its full cost, where the median does
    not) with the worst episode named (its seed and cost) and its ratio to the
    fixed LQG's mean; each as the median [min, max] over
    training seeds. Then
    the oracle, adaptive and fixed LQG and zero torque (the trivial
    baseline) on the same evaluation episodes (taken from the last
    directory).

    Returns
    -------
    str
        Markdown: one table per setting.
    """
    def spread(values: list[float], fmt: str) -> str:
        # inf is a result (an episode that left the bound before 100 s), NaN is not
        values = [v for v in values if v is not None and not np.isnan(v)]
        if not values:
            return "-"
        return (f"{np.median(values):{fmt}} [{min(values):{fmt}}, {max(values):{fmt}}]"
                if len(values) > 1 else f"{values[0]:{fmt}}")

    median, mean = "cost_after_100s", "cost_after_100s_mean"

    def ratio(result: dict[str, Any], ref: dict[str, Any] | None,
              key: str = median) -> float | None:
        mine, theirs = result.get(key), None if ref is None else ref.get(key)
        return None if mine is None or not theirs else mine / theirs

    def worst_of(result: dict[str, Any]) -> str:
        if "worst_episode_seed" not in result:
            return "-"
        return f"{result['worst_episode_seed']}: {result['cost_after_100s_worst']:.3g}"

    rows = []
    pooled = pooled_training_runs(directories)
    last = pooled[-1] if pooled else None
    for m in pooled:
        finals = [r["final"] for r in m["runs"]]
        reached = [r["steps_to_2x_adaptive"] for r in m["runs"]]
        by_rms = m.get("threshold") != "cost_after_100s"      # a file from before
        worst = [f"{f['worst_episode_seed']}: {f['cost_after_100s_worst']:.3g}"
                 for f in finals if "worst_episode_seed" in f]
        task = "randomized " + m["scenario"] if m.get("randomize") else m["scenario"]
        task += f", {m.get('reward', 'cost')} reward"
        if m.get("relative_to_base"):
            task += " minus the base's"
        if m.get("reward_from_s"):
            task += f" from {m['reward_from_s']:g} s"
        rows.append(
            f"| {m['algo'].upper()} | {m['features']} | {task} | {m['timesteps']:,} "
            f"| {len(finals)} | {spread([f.get(median) for f in finals], '.4f')} "
            f"| {spread([ratio(f, m.get('oracle_lqg')) for f in finals], '.2f')} "
            f"| {spread([ratio(f, m.get('fixed_lqg')) for f in finals], '.2f')} "
            f"| {spread([f['attitude_rms_deg'] for f in finals], '.2f')} "
            f"| {spread([f.get('vibration_rms_mm') for f in finals], '.2f')} "
            f"| {', '.join('not reached' if x is None else f'{x:,}' for x in reached)}"
            f"{' (by attitude RMS)' if by_rms else ''} "
            f"| {spread([f.get(mean) for f in finals], '.3g')} "
            f"| {'; '.join(worst) or '-'} "
            f"| {spread([ratio(f, m.get('fixed_lqg'), mean) for f in finals], '.3g')} |")
    head = ["| agent | features | task | env steps | seeds | cost from 100 s (median episode) "
            "| / oracle LQG | / fixed LQG | attitude RMS (deg) | vibration RMS (mm) "
            f"| env steps to <= 2x the {FAST_ADAPTIVE_LQG}'s cost | cost, mean over episodes "
            "| worst episode (seed: cost) | mean / fixed LQG's mean |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    if last is not None:
        for key in ("window_ceiling", "oracle_lqg", "adaptive_lqg", "fixed_lqg",
                    "scheduled_lqg", "zero_torque"):
            name = COMPARATOR_NAMES[key]
            if key in last:
                b = last[key]
                # the window ceiling's cost is orders below the others': shown in full
                fmt = ".4f" if (b.get(median) or 0.0) >= 1e-4 else ".3g"
                rows.append(f"| {name} | - | - | - | - | {spread([b.get(median)], fmt)} "
                            f"| {spread([ratio(b, last.get('oracle_lqg'))], '.2f')} "
                            f"| {spread([ratio(b, last.get('fixed_lqg'))], '.2f')} "
                            f"| {b['attitude_rms_deg']:.2f} "
                            f"| {spread([b.get('vibration_rms_mm')], '.2f')} | - "
                            f"| {spread([b.get(mean)], '.3g')} "
                            f"| {worst_of(b)} "
                            f"| {spread([ratio(b, last.get('fixed_lqg'), mean)], '.3g')} |")
    return "\n".join(head + rows) + "\n"


def paired_cost_ratio(table: dict[str, dict], name: str, ref: str,
                      key: str = "cost_after_100s") -> float | None:
    """Median over paired seeds of ``name``'s ``key`` (a cost of
    :func:`controllers.episode_metrics`) over ``ref``'s (None if either is missing or no
    seed has a finite ratio).

    Returns
    -------
    float or None
        The median of the per-seed ratios; None without a finite pair.
    """
    if name not in table or ref not in table:
        return None
    a = np.array([m[key] for m in table[name]["per_seed"]], dtype=float)
    b = np.array([m[key] for m in table[ref]["per_seed"]], dtype=float)
    n = min(len(a), len(b))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = a[:n] / b[:n]
    return float(np.nanmedian(ratio)) if np.isfinite(ratio).any() else None


def control_summary(table: dict[str, dict], scenario: str, out: str | Path) -> str:
    """Plain sentences on a comparison: how the adaptive LQG did against the ceiling over
    the whole episode, against the same-start ceiling from the end of its start, and
    against the robust fixed design, in the common cost, and where to look. Each figure
    is the table's (the same rounding).

    Returns
    -------
    str
        The sentences.
    """
    lines = []
    seeds = max(row["runs"] for row in table.values())
    adaptive, robust = "adaptive LQG", "robust LQG"
    if adaptive in table:
        to_ceiling = paired_cost_ratio(table, adaptive, CEILING, "cost")
        to_start = paired_cost_ratio(table, adaptive, SAME_START_CEILING, "cost_after_start")
        to_robust = paired_cost_ratio(table, adaptive, robust, "cost")
        to_window = paired_cost_ratio(table, adaptive, WINDOW_CEILING, "cost_after_100s")
        parts = []
        if to_ceiling is not None:
            parts.append(f"{to_ceiling:.2f} times the ceiling's over the whole episode")
        if to_start is not None:
            parts.append(f"{to_start:.2f} times the same-start ceiling's from "
                         f"{SAME_START_S:g} s (the price of identification)")
        if to_window is not None:
            parts.append(f"{to_window:.3g} times the window ceiling's from 100 s (the "
                         "window's own optimum, which spends the first 100 s bringing the "
                         "plant to rest)")
        if to_robust is not None:
            parts.append(f"{to_robust:.2f} times the robust fixed design's over the whole "
                         "episode")
        verdicts = table[adaptive]["verdicts"]
        stable = verdicts.get("stable", 0)
        fallback = table[adaptive]["median"].get("fallback_share_after_60s", np.nan)
        why = fallback_causes_text(table[adaptive].get("fallback_causes_after_60s", {}))
        flew = ("" if not np.isfinite(fallback) else
                f"; its robust fallback flew {100 * fallback:.0f} % of the steps from 60 s"
                + (f" (why, mean over seeds: {why})" if why else ""))
        if parts:
            lines.append(f"On {scenario} over {seeds} seeds, the adaptive LQG's quadratic cost "
                         f"was {', '.join(parts)} (medians of paired seeds; lower is better); "
                         f"it was judged stable on {stable} of {seeds}{flew}.")
    others = [(name, paired_cost_ratio(table, name, "robust LQG", "cost"))
              for name in ("scheduled LQG", "fixed LQG", "PD") if name in table]
    others = [f"the {name} {r:.2f}" for name, r in others if r is not None]
    if others and "robust LQG" in table:
        lines.append(f"Beside it, the whole episode's cost over the robust design's: "
                     f"{', '.join(others)} (the scheduled LQG knows the plant's "
                     "schedule: a reference, not a competitor).")
    fixed = table.get("fixed LQG")
    if fixed is not None:
        bad = sum(c for v, c in fixed["verdicts"].items() if v != "stable")
        lines.append(f"The fixed LQG designed at the nominal plant was judged not stable on "
                     f"{bad} of {fixed['runs']} seeds.")
    lines.append(f"The figure is {Path(out) / 'comparison.png'}; per-seed numbers are in "
                 f"{Path(out) / 'results.csv'}.")
    return "\n".join(lines)


def rl_protocol_report(directories: Sequence[str | Path]) -> str:
    """The evaluation protocol's tables (:mod:`spacecraft_lab.rl_protocol`) of several
    ``spacecraft train`` directories: per setting (pooled as by :func:`rl_table`), the
    agent's cost from 100 s over its training seeds x evaluation draws and the
    comparators' on the same draws, as IQM, median and mean with 95 % intervals, and the
    probability that the agent costs less than its base (a residual's) and the adaptive
    LQG on a draw.

    Parameters
    ----------
    directories : sequence of str or Path
        ``spacecraft train`` output directories.

    Returns
    -------
    str
        One titled table per setting; a setting whose runs differ in their evaluation
        draws, or whose files lack the per-draw costs, is named with the reason.
    """
    parts = []
    for m in pooled_training_runs(directories):
        title = (f"### {m['algo'].upper()} {m['features']} on {m['scenario']}, "
                 f"{m['timesteps']:,} env steps")
        seeds = [run["final"].get("cost_after_100s_per_seed") for run in m["runs"]]
        comparators = {COMPARATOR_NAMES.get(key, key): m[key]["cost_after_100s_per_seed"]
                       for key in COMPARATOR_NAMES if key in m
                       and "cost_after_100s_per_seed" in m[key]}
        draws = {len(s) for s in seeds if s is not None} | {len(c) for c in comparators.values()}
        if any(s is None for s in seeds) or len(draws) != 1:
            parts.append(f"{title}\n\nnot scored by the protocol: its runs do not all carry "
                         "the per-draw costs of the same evaluation draws\n")
            continue
        costs = {"agent": np.array(seeds, dtype=float), **comparators}
        over = [COMPARATOR_NAMES[k] for k in improvement_references(m.get("base_comparator"))
                if k in COMPARATOR_NAMES and COMPARATOR_NAMES[k] in costs]
        table = protocol_table(interval_estimates(costs),
                               improvement_probabilities(costs, "agent", over),
                               "agent", {"agent": len(seeds)}, draws.pop())
        parts.append(f"{title}\n\n{table}")
    return "\n".join(parts)
