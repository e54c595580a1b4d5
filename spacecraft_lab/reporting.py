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

__all__ = ["control_table", "identification_table", "rl_table"]


def _fmt(mean, std) -> str:
    if mean is None:
        return "diverged"
    if abs(mean) >= 1e4:
        return f"{mean:.1e}"
    return f"{mean:.2f} ± {std:.2f}"


def identification_table(metrics: dict[str, Any]) -> str:
    """Markdown tables like the paper's Tables 3/4, our figures beside the paper's."""
    scen = metrics["scenario"]
    lines = [f"### {scen}: test-response normalized error (%), mean ± std over "
             f"{metrics['seeds']} seeds (runs that diverged excluded and counted), "
             f"SNR {metrics['snr_db']} dB, n = {metrics['order_n']}, p = {metrics['p']}, "
             f"forgetting {metrics['forgetting']}, regularization "
             f"{metrics['regularization']}, warm-up {metrics.get('warmup') or 'default'}", ""]
    head = ("| method | psi_x | psi_y | psi_z | omega_x | omega_y | omega_z | diverged "
            "| paper psi (x, y, z) | paper omega (x, y, z) |")
    lines += [head, "|" + "---|" * 10]
    paper = metrics.get("paper") or {}
    for name, res in metrics["methods"].items():
        att, rate = res["test_error_pct"]["attitude"], res["test_error_pct"]["rate"]
        cells = [_fmt(m, s) for m, s in zip(att["mean"], att["std"], strict=True)]
        cells += [_fmt(m, s) for m, s in zip(rate["mean"], rate["std"], strict=True)]
        ref = paper.get(name, {})
        pp = ", ".join(f"{x:.2f}" for x in ref.get("psi", [])) or "-"
        po = ", ".join(f"{x:.2f}" for x in ref.get("omega", [])) or "-"
        div = max(att["diverged_runs"], rate["diverged_runs"])
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {div} | {pp} | {po} |")
    lines += ["", f"### {scen}: one-step-ahead prediction VAF (%) on held-out data, "
              f"t >= {metrics['convergence_s']:.0f} s (mean over channels, median over seeds)",
              "", "| method | attitude | rate | deflection | run time (s) |",
              "|---|---|---|---|---|"]
    for name, res in metrics["methods"].items():
        v = res["one_step_vaf_pct"]
        cells = []
        for grp in ("attitude", "rate", "deflection"):
            med = [x for x in v[grp]["median"] if x is not None]
            cells.append(f"{np.mean(med):.1f}" if med and np.all(np.isfinite(med))
                         and np.mean(med) > -1e4 else "diverged")
        t = res["run_time_s"]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {t['mean']:.2f} |")
    return "\n".join(lines) + "\n"


def control_table(table: dict[str, dict], oracle: str | None = None) -> str:
    """Markdown table of :func:`controllers.compare` results (mean ± std over seeds)."""
    head = ("| controller | stable | attitude RMS (deg) | RMS t >= 50 s (deg) | peak (deg) "
            "| vibration RMS (mm) | torque RMS (N m) | return |"
            + (" RMS / oracle | RMS t >= 50 s / oracle |" if oracle else ""))
    lines = [head, "|" + "---|" * (8 + (2 if oracle else 0))]
    ref = table[oracle]["mean"]["attitude_rms_deg"] if oracle in table else None
    ref_late = table[oracle]["mean"]["attitude_rms_after_deg"] if oracle in table else None
    for name, row in table.items():
        mu, sd = row["mean"], row["std"]
        cells = [f"{row['stable_runs']}/{row['runs']}",
                 f"{mu['attitude_rms_deg']:.4f} ± {sd['attitude_rms_deg']:.4f}",
                 f"{mu['attitude_rms_after_deg']:.4f} ± {sd['attitude_rms_after_deg']:.4f}",
                 f"{mu['attitude_peak_deg']:.3f} ± {sd['attitude_peak_deg']:.3f}",
                 f"{mu['vibration_rms_mm']:.3f} ± {sd['vibration_rms_mm']:.3f}",
                 f"{mu['torque_rms_Nm']:.3f} ± {sd['torque_rms_Nm']:.3f}",
                 f"{mu['return']:.4g}"]
        if ref:
            cells.append(f"{mu['attitude_rms_deg'] / ref:.2f}")
            cells.append(f"{mu['attitude_rms_after_deg'] / ref_late:.2f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def rl_table(directories: Sequence[str | Path]) -> str:
    """Markdown table of several ``spacecraft train`` output directories."""
    rows, baseline = [], None
    for directory in directories:
        m = json.loads((Path(directory) / "metrics.json").read_text())
        baseline = m["adaptive_lqr"]
        reached = [r["steps_to_2x_adaptive"] for r in m["runs"]]
        rows.append(f"| {m['algo'].upper()} | {m['features']} | {m['timesteps']:,} "
                    f"| {m['final_attitude_rms_deg']:.3f} | {m['final_return']:.4g} "
                    f"| {', '.join('not reached' if x is None else f'{x:,}' for x in reached)} |")
    head = ["| agent | features | env steps | final attitude RMS (deg) | final return "
            "| env steps to <= 2x adaptive LQR RMS |", "|---|---|---|---|---|---|"]
    if baseline is not None:
        rows.append(f"| adaptive LQR | - | - | {baseline['attitude_rms_deg']:.3f} "
                    f"| {baseline['return']:.4g} | - |")
    return "\n".join(head + rows) + "\n"
