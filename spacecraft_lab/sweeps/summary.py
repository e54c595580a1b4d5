"""Turn a sweep's ``results.jsonl`` into tables (mean and spread over seeds) and plots.

Records are grouped by everything but the seed. For each group and each
scalar metric or timing it reports the number of runs, how many gave a
non-finite value (a diverged identifier is recorded as null), how many
tasks failed, and mean, sample standard deviation, median, minimum and
maximum over the finite values. Files written (``spacecraft sweep-summary
DIR``, also at the end of every sweep):

* ``summary.csv``: one row per group and metric (long format);
* ``summary.json``: the same, with the pivot layout used below;
* ``summary.md``: one pivot table per metric, rows x columns (e.g. method x
  system order) of ``mean ± std``, with published reference values and
  ratios to a baseline row when the sweep file's ``[summary]`` asks;
* ``summary.png``: one panel per metric, mean ± std against the column
  parameter, one line per row (references dashed).
"""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from spacecraft_lab.plots import save
from spacecraft_lab.sweeps.config import SummarySpec, SweepConfig
from spacecraft_lab.sweeps.store import ResultStore

__all__ = ["METRIC_LABELS", "group_statistics", "metric_label", "summarize"]

_STATS = ("count", "finite", "errors", "mean", "std", "median", "min", "max")


def _scalar_items(record: dict[str, Any]) -> dict[tuple[str, str], float | None]:
    """(section, name) -> value for the scalar metrics and timings of an ok
    record (bools as 0/1)."""
    out: dict[tuple[str, str], float | None] = {}
    for section in ("metrics", "timings"):
        for key, value in (record.get(section) or {}).items():
            if isinstance(value, bool):
                out[section, key] = float(value)
            elif isinstance(value, (int, float)) or value is None:
                out[section, key] = None if value is None else float(value)
    return out


def _stats(values: list[float | None], errors: int, section: str = "metrics") -> dict[str, Any]:
    arr = np.array([np.nan if v is None else v for v in values], dtype=float)
    good = arr[np.isfinite(arr)]
    res: dict[str, Any] = {"count": int(arr.size), "finite": int(good.size), "errors": errors,
                           "timing": section == "timings"}
    if good.size:
        with np.errstate(over="ignore", invalid="ignore"):  # diverged runs near 1e300
            stats = {"mean": good.mean(), "std": good.std(ddof=1) if good.size > 1 else 0.0,
                     "median": np.median(good), "min": good.min(), "max": good.max()}
        res.update({k: float(v) if np.isfinite(v) else None for k, v in stats.items()})
    else:
        res.update(mean=None, std=None, median=None, min=None, max=None)
    return res


def _seed_key(seed: Any) -> tuple[int, float, str]:
    """Ints in order, anything else after them (a custom kind may have no seed)."""
    if isinstance(seed, int) and not isinstance(seed, bool):
        return (0, float(seed), "")
    return (1, 0.0, repr(seed))


def group_statistics(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Statistics over seeds for every group of records.

    Parameters
    ----------
    records : list of dict
        Task records (:func:`spacecraft_lab.sweeps.tasks.execute`), one per task.

    Returns
    -------
    list of dict
        One entry per group: ``label``, ``params`` (without the seed),
        ``seeds``, ``errors`` and ``metrics`` (name -> statistics: count,
        finite, errors, mean, std (ddof 1), median, min, max, and ``timing``
        for wall-clock timings).
    """
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for rec in records:
        params = {k: v for k, v in rec["params"].items() if k != "seed"}
        key = json.dumps({"kind": rec["kind"], "label": rec.get("label"), "params": params},
                         sort_keys=True)
        groups[key].append(rec)
    out = []
    for key, recs in groups.items():
        head = json.loads(key)
        ok = [r for r in recs if r.get("status") == "ok"]
        n_err = len(recs) - len(ok)
        values: dict[tuple[str, str], list[float | None]] = defaultdict(list)
        for r in ok:
            for item, v in _scalar_items(r).items():
                values[item].append(v)
        out.append({"kind": head["kind"], "label": head["label"], "params": head["params"],
                    "seeds": sorted((r["params"].get("seed") for r in recs), key=_seed_key),
                    "errors": n_err,
                    "error_messages": sorted({r.get("error", "") for r in recs} - {""}),
                    "metrics": {m: _stats(v, n_err, section)
                                for (section, m), v in values.items()}})
    return out


def _layout(groups: list[dict[str, Any]], spec: SummarySpec,
            grid_axes: list[str]) -> tuple[str | None, str | None, dict[int, tuple[str, str]]]:
    """Row and column parameter and each group's (row name, column value)."""
    keys = sorted({k for g in groups for k in g["params"]})
    distinct = {k: {json.dumps(g["params"].get(k)) for g in groups} for k in keys}
    varying = [k for k in keys if len(distinct[k]) > 1]
    columns = spec.columns
    if columns is None:
        numeric = [k for k in grid_axes + varying if k in varying and all(
            isinstance(g["params"].get(k), (int, float)) for g in groups)]
        columns = numeric[0] if numeric else None
    labelled = any(g["label"] is not None for g in groups)
    rows = spec.rows or ("label" if labelled else None)

    def value(g: dict[str, Any], name: str | None) -> str:
        if name is None:
            return "all"
        v = g["label"] if name == "label" else g["params"].get(name)
        return str(v)

    cells: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for g in groups:
        cells[(value(g, rows), value(g, columns))].append(g)
    extra = [k for k in varying if k not in (rows, columns) and any(
        len({json.dumps(g["params"].get(k)) for g in cell}) > 1 for cell in cells.values())]
    if rows is None and not extra:
        extra = [k for k in varying if k != columns]
    place = {}
    for i, g in enumerate(groups):
        parts = [value(g, rows)] if rows is not None else []
        parts += [f"{k}={g['params'].get(k)}" for k in extra]
        place[i] = (", ".join(parts) or "all", value(g, columns))
    return rows, columns, place


def _sort_key(text: str) -> tuple[int, float, str]:
    try:
        return (0, float(text), text)
    except ValueError:
        return (1, 0.0, text)


def _fmt(x: float | None) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    ax = abs(x)
    if ax != 0 and (ax >= 1e5 or ax < 1e-3):
        return f"{x:.2e}"
    return f"{x:.4g}" if ax < 10 else f"{x:.1f}" if ax < 1e4 else f"{x:.0f}"


def _cell(st: dict[str, Any] | None) -> str:
    if st is None:
        return ""
    if st["mean"] is None:
        text = "diverged" if st["count"] else "failed"
    else:
        text = f"{_fmt(st['mean'])} ± {_fmt(st['std'])}"
    notes = []
    if st["finite"] < st["count"]:
        notes.append(f"{st['count'] - st['finite']} non-finite")
    if st["errors"]:
        notes.append(f"{st['errors']} failed")
    return text + (f" ({', '.join(notes)})" if notes else "")


def summarize(out: str | Path, spec: SummarySpec | None = None) -> dict[str, Any]:
    """Write ``summary.csv``, ``summary.json``, ``summary.md`` and ``summary.png``.

    Parameters
    ----------
    out : path
        A sweep directory (``results.jsonl``; ``sweep.json`` when present
        restricts the summary to the sweep's current grid and gives the
        ``[summary]`` settings).
    spec : SummarySpec, optional
        Overrides the sweep file's settings.

    Returns
    -------
    dict
        The content of ``summary.json``.
    """
    out = Path(out)
    store = ResultStore(out / "results.jsonl")
    records = store.load()
    grid_axes: list[str] = []
    name = out.name
    ignored = 0
    config_path = out / "sweep.json"
    if config_path.exists():
        config = SweepConfig.from_dict(json.loads(config_path.read_text()), validate=False)
        order = {t.task_id: i for i, t in enumerate(config.tasks())}
        ignored = sum(1 for k in records if k not in order)
        records = {k: records[k] for k in sorted(set(records) & set(order), key=order.get)}
        spec = spec or config.summary
        grid_axes = list(config.grid)
        name = config.name
    spec = spec or SummarySpec()
    if not records:
        raise ValueError(f"{out}: no results to summarize")
    groups = group_statistics(list(records.values()))
    rows, columns, place = _layout(groups, spec, grid_axes)
    metric_names = sorted({m for g in groups for m in g["metrics"]})
    if spec.metrics is not None:
        unknown = [m for m in spec.metrics if m not in metric_names]
        if unknown and len(unknown) == len(spec.metrics):
            raise ValueError(f"[summary] metrics {unknown} not in the results; "
                             f"available: {metric_names}")
        metric_names = [m for m in spec.metrics if m in metric_names]
    row_names = list(dict.fromkeys(r for r, _ in place.values()))  # grid order
    col_names = sorted({c for _, c in place.values()}, key=_sort_key)
    table = {m: {r: {} for r in row_names} for m in metric_names}
    for i, g in enumerate(groups):
        r, c = place[i]
        for m in metric_names:
            if m in g["metrics"]:
                table[m][r][c] = g["metrics"][m]
            elif g["errors"]:
                table[m][r][c] = _stats([], g["errors"])

    summary = {"sweep": name, "records": len(records), "ignored_records": ignored,
               "skipped_lines": store.n_skipped,
               "errors": sum(g["errors"] for g in groups), "rows": rows, "columns": columns,
               "row_names": row_names, "column_names": col_names, "metrics": metric_names,
               "table": table, "groups": groups, "spec": spec.to_dict()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
    _write_csv(out / "summary.csv", groups, metric_names)
    (out / "summary.md").write_text(_markdown(summary, spec))
    _plot(out / "summary.png", summary, spec)
    return summary


def _write_csv(path: Path, groups: list[dict[str, Any]], metrics: list[str]) -> None:
    keys = sorted({k for g in groups for k in g["params"]})
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["label", *keys, "metric", *_STATS])
        for g in groups:
            for m in metrics:
                st = g["metrics"].get(m)
                if st is None:
                    continue
                writer.writerow([g["label"] or "", *[g["params"].get(k, "") for k in keys], m,
                                 *["" if st[s] is None else st[s] for s in _STATS]])


def _markdown(summary: dict[str, Any], spec: SummarySpec) -> str:
    rows_title = summary["rows"] or "group"
    cols = summary["column_names"]
    col_title = summary["columns"] or ""
    lines = [f"# Sweep `{summary['sweep']}`: mean ± std over seeds", "",
             f"{summary['records']} task records, {summary['errors']} failed"
             + (f"; {summary['ignored_records']} records outside the current grid ignored"
                if summary["ignored_records"] else "")
             + (f"; {summary['skipped_lines']} lines that are not complete records skipped "
                "(their tasks run again when the sweep resumes)"
                if summary["skipped_lines"] else "") + ".", ""]
    for m in summary["metrics"]:
        refs = [r for r in spec.reference if r.metric == m]
        lines += [f"## {m}", "",
                  f"| {rows_title} \\ {col_title} | " + " | ".join(cols) + " |",
                  "|---" * (len(cols) + 1) + "|"]
        for r in summary["row_names"]:
            lines.append(f"| {r} | " + " | ".join(_cell(summary["table"][m][r].get(c))
                                                  for c in cols) + " |")
        for ref in refs:
            lines.append(f"| {ref.row} ({ref.source}) | "
                         + " | ".join(_fmt(ref.values.get(c)) for c in cols) + " |")
        lines += ["", "Median [min, max]:", "",
                  f"| {rows_title} \\ {col_title} | " + " | ".join(cols) + " |",
                  "|---" * (len(cols) + 1) + "|"]
        for r in summary["row_names"]:
            lines.append(f"| {r} | " + " | ".join(_spread(summary["table"][m][r].get(c))
                                                  for c in cols) + " |")
        base = spec.ratio_to
        is_timing = any(st.get("timing") for row in summary["table"][m].values()
                        for st in row.values())
        if base is not None and base in summary["table"][m] and is_timing:
            lines += ["", f"Ratio of means to `{base}` (same column):", "",
                      f"| {rows_title} \\ {col_title} | " + " | ".join(cols) + " |",
                      "|---" * (len(cols) + 1) + "|"]
            for r in summary["row_names"]:
                lines.append(f"| {r} | " + " | ".join(
                    _fmt(_ratio(summary["table"][m][r].get(c),
                                summary["table"][m][base].get(c))) for c in cols) + " |")
            base_ref = next((x for x in refs if x.row == base), None)
            for ref in refs:
                if base_ref is None:
                    break
                lines.append(f"| {ref.row} ({ref.source}) | " + " | ".join(
                    _fmt(_div(ref.values.get(c), base_ref.values.get(c))) for c in cols) + " |")
        lines.append("")
    failed = [g for g in summary["groups"] if g["error_messages"]]
    if failed:
        lines += ["## Failed tasks", ""]
        for g in failed:
            lines.append(f"- {g['label'] or ''} {g['params']}: {g['errors']} failed; "
                         + "; ".join(msg[:200] for msg in g["error_messages"][:3]))
        lines.append("")
    return "\n".join(lines)


def _spread(st: dict[str, Any] | None) -> str:
    if st is None or st["median"] is None:
        return "-" if st is None else _cell(st)
    return f"{_fmt(st['median'])} [{_fmt(st['min'])}, {_fmt(st['max'])}]"


def _div(a: float | None, b: float | None) -> float | None:
    if a is None or b is None or b == 0:
        return None
    return a / b


def _ratio(a: dict[str, Any] | None, b: dict[str, Any] | None) -> float | None:
    if a is None or b is None:
        return None
    return _div(a["mean"], b["mean"])


#: Readable panel titles (with units) of the metrics sweeps usually plot.
METRIC_LABELS = {
    "time_s": "run time (s)",
    "cost_after_100s": "quadratic cost from 100 s",
    "attitude_rms_deg": "attitude RMS (deg)",
    "attitude_rms_after_100s_deg": "attitude RMS from 100 s (deg)",
    "vibration_rms_mm": "vibration RMS (mm)",
    "test_error_attitude_pct": "test-response error, attitude (%)",
    "test_error_rate_pct": "test-response error, rate (%)",
    "vaf_h100_attitude": "10 s-ahead VAF, attitude (%)",
    "vaf_h100_rate": "10 s-ahead VAF, rate (%)",
    "vaf_h100_deflection": "10 s-ahead VAF, deflection (%)",
    "gain_error_pct": "rigid-body gain error (%)",
    "vaf_attitude_pct": "held-out one-step VAF, attitude (%)",
    "vaf_rate_pct": "held-out one-step VAF, rate (%)",
    "vaf_deflection_pct": "held-out one-step VAF, deflection (%)",
    "unstable_share": "share of models with a pole outside 1.001",
    "within_5pct": "runs with every test error within 5 % (share)",
    "nonfinite": "runs that overflowed (share)",
}
#: Most rows (series) one panel of ``summary.png`` draws; ``[summary] plot_rows`` picks them.
MAX_PLOT_ROWS = 5
#: A plotted value beyond this many times the panel's median magnitude is drawn
#: at the bound (a diverged run), so the typical values stay readable.
_CLIP_FACTOR = 1e3


def metric_label(key: str) -> str:
    """A panel title for a metric key: :data:`METRIC_LABELS` or the key in words.

    Returns
    -------
    str
        The title.
    """
    return METRIC_LABELS.get(key, key.replace("_", " "))


def _bar(cell: dict[str, Any]) -> tuple[float, float]:
    """The std bar below and above a cell's mean, cut to the values observed."""
    std = cell.get("std") or 0.0
    low, high = cell.get("min"), cell.get("max")
    return (min(std, cell["mean"] - (-np.inf if low is None else low)),
            min(std, (np.inf if high is None else high) - cell["mean"]))


def _plot(path: Path, summary: dict[str, Any], spec: SummarySpec) -> Figure | None:
    # a metric that is 0 everywhere says nothing: no panel for it
    metrics = [m for m in summary["metrics"]
               if any(st["mean"] not in (None, 0) for row in summary["table"][m].values()
                      for st in row.values())][:9]
    if not metrics:
        return
    cols = summary["column_names"]
    try:
        xs = [float(c) for c in cols]
        categorical = False
    except ValueError:
        xs = list(range(len(cols)))
        categorical = True
    rows_all = list(summary["row_names"])
    plotted = [r for r in (spec.plot_rows or rows_all) if r in rows_all][:MAX_PLOT_ROWS]
    ncol = min(3, len(metrics))
    nrow = -(-len(metrics) // ncol)
    fig = Figure(figsize=(5.2 * ncol, 3.8 * nrow + 0.8), layout="constrained")
    axes = fig.subplots(nrow, ncol, squeeze=False)
    for ax in axes.flat[len(metrics):]:
        ax.set_visible(False)
    for ax, m in zip(axes.flat, metrics, strict=False):
        cells_all = [st for row in summary["table"][m].values() for st in row.values()
                     if st["mean"] is not None]
        # diverged runs make the mean meaningless: show medians instead
        heavy = any(abs(st["mean"] - st["median"]) > 10 * max(abs(st["median"]), 1.0)
                    for st in cells_all)
        positive = []
        for i, r in enumerate(rows_all):
            if r not in plotted:
                continue
            cells = summary["table"][m][r]
            # the bar is the std, cut to the values observed (a share never goes below 0)
            pts = [(x, cells[c]["median" if heavy else "mean"],
                    *((0.0, 0.0) if heavy else _bar(cells[c])))
                   for x, c in zip(xs, cols, strict=True)
                   if c in cells and cells[c]["mean"] is not None]
            if not pts:
                continue
            x, y, lo, hi = (np.array(v, dtype=float) for v in zip(*pts, strict=True))
            ax.errorbar(x, y, yerr=None if heavy else np.vstack([np.maximum(lo, 0.0),
                                                                  np.maximum(hi, 0.0)]),
                        marker="o", ms=4, capsize=3, label=r, color=f"C{i}")
            positive.extend(y)
            for ref in spec.reference:
                if ref.metric == m and ref.row == r:
                    rx = [xv for xv, c in zip(xs, cols, strict=True) if c in ref.values]
                    ry = [ref.values[c] for c in cols if c in ref.values]
                    ax.plot(rx, ry, "--", marker="s", ms=3, color=f"C{i}",
                            label=f"{r} ({ref.source})")
                    positive.extend(ry)
        vals = np.array(positive, dtype=float)
        mags = np.abs(vals)
        bound = _CLIP_FACTOR * max(float(np.median(mags)), 1.0) if vals.size else np.inf
        clipped = bool(vals.size and mags.max() > bound)
        if clipped:
            # diverged runs: the axis ends at the bound; the points beyond sit on it
            for line in ax.get_lines():
                y = np.asarray(line.get_ydata(), dtype=float)
                line.set_ydata(np.clip(y, -bound, bound))
            inside = vals[np.abs(vals) <= bound]
            lo = min(float(inside.min()) if inside.size else 0.0, 0.0)
            hi = max(float(inside.max()) if inside.size else 0.0, 0.0)
            lo = -bound if vals.min() < -bound else lo
            hi = bound if vals.max() > bound else hi
            if np.all(vals > 0):
                # positive (errors, times): a log axis keeps 5 % and 100 % apart below
                # the diverged runs drawn at the bound
                ax.set_yscale("log")
                ax.set_ylim(float(vals.min()) / 2, bound * 1.5)
            else:
                # signed (VAF): linear near the typical values, logarithmic beyond, so
                # the methods near 100 % stay apart from those at -1e5
                # a VAF (at most 100 %) is linear over its meaningful range
                scale = 100.0 if vals.max() <= 100.0 else max(float(np.median(mags)), 1.0)
                ax.set_yscale("symlog", linthresh=scale, linscale=2.0)
                ax.set_ylim(lo * 1.5 if lo < 0 else lo - 0.05 * scale,
                            hi * 1.5 if hi > 0 else hi + 0.05 * scale)
        elif vals.size and np.all(vals > 0) and vals.max() / vals.min() > 50:
            ax.set_yscale("log")
        title = metric_label(m)
        if heavy:
            title += ", median (some runs diverged)"
        if clipped:
            title += f"\nvalues beyond {bound:.3g} drawn at it"
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(metric_label(summary["columns"]) if summary["columns"] else "")
        ax.set_xticks(xs, cols, rotation=20 if categorical else 0)
        ax.grid(alpha=0.3)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 4),
               fontsize=8)
    shown = "" if len(plotted) == len(rows_all) else \
        f"; {len(plotted)} of {len(rows_all)} rows drawn, all in summary.md"
    fig.suptitle(f"sweep {summary['sweep']}: mean ± std over seeds (bars cut to the observed "
                 f"range; dashed: references){shown}")
    save(fig, path)
    return fig
