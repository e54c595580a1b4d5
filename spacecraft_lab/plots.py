"""Figures of the experiments, drawn through matplotlib's object API.

Every function builds a :class:`matplotlib.figure.Figure` directly and
saves it (PNG); none touches pyplot's global state or selects a backend, so
they work in any process and never open a window.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from controllers import Trajectory, stage_costs
from controllers.harness import SAME_START_S
from identifiers import ModelSequence
from spacecraft_conventions import AXIS_NAMES, DEG_PER_RAD
from spacecraft_env import FlexibleSpacecraftModel
from spacecraft_lab.reporting import FAST_ADAPTIVE_LQG

__all__ = [
    "MAX_AGENT_SERIES",
    "PREDICTION_SERIES",
    "mark_events",
    "plot_adaptation",
    "plot_control_comparison",
    "plot_demo_response",
    "plot_identification_modal",
    "plot_identification_responses",
    "plot_learning_curves",
    "plot_prediction_horizons",
    "plot_rigid_gain",
    "plot_rl_comparison",
    "save",
    "sensor_name",
]


def save(fig: Figure, path: str | Path, dpi: int = 100) -> None:
    """Lay out and write ``fig`` to ``path`` (a figure made with a layout engine, such as
    ``layout="constrained"`` for a legend outside the axes, keeps it)."""
    if fig.get_layout_engine() is None:
        fig.tight_layout()
    fig.savefig(path, dpi=dpi)


def mark_events(axes: Sequence[Axes] | np.ndarray, events: Sequence[float]) -> None:
    """Dashed vertical lines at the scenario's event times (dockings), s."""
    for ax in np.ravel(axes):
        for event in events:
            ax.axvline(event, color="k", ls="--", lw=0.8)


def plot_identification_responses(path: str | Path, u_test: np.ndarray, y_test: np.ndarray,
                                  seqs: Mapping[str, ModelSequence], scenario: str,
                                  dt: float) -> None:
    """True vs identified responses to the paper's test torques, attitude and rate."""
    t = np.arange(y_test.shape[0]) * dt
    names = ["psi_x (deg)", "psi_y (deg)", "psi_z (deg)",
             "omega_x (deg/s)", "omega_y (deg/s)", "omega_z (deg/s)"]
    fig = Figure(figsize=(12, 9))
    axes = fig.subplots(3, 2, sharex=True)
    for ch in range(6):
        ax = axes[ch % 3, ch // 3]
        truth = y_test[:, ch] * DEG_PER_RAD
        ax.plot(t, truth, "k", lw=2.0, label="true")
        lim = 3 * np.abs(truth).max() + 1e-12
        for name, seq in seqs.items():
            with np.errstate(all="ignore"):
                y = seq.simulate(u_test)[:, ch] * DEG_PER_RAD
            ax.plot(t, np.clip(y, -lim, lim), lw=1.0, label=name)
        ax.set_ylim(-lim, lim)
        ax.set_ylabel(names[ch])
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"{scenario}: test responses, true vs identified (seed 0; "
                 "identified curves clipped at 3x the true peak)")
    save(fig, path)


def plot_identification_modal(path: str | Path, truth: FlexibleSpacecraftModel,
                              scores: Mapping[str, Any], scenario: str) -> Figure:
    """Identified modal frequencies (dots) against the truth's (lines), zoomed to
    the first paddle and antenna modes; true events dashed, detected ones marked.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    from matplotlib.lines import Line2D

    n_samples = len(next(iter(scores.values())).models)
    t = np.arange(0, n_samples, 10) * truth.dt
    true_f = np.array([truth.modal_residues(float(tk))[0] for tk in t])
    weight = np.array([truth.modal_residues(float(tk))[2] for tk in t])
    cols = min(3, len(scores))
    rows = -(-len(scores) // cols)
    fig = Figure(figsize=(5 * cols, 3.6 * rows + 0.8), layout="constrained")
    axes = fig.subplots(rows, cols, sharey=True, squeeze=False)
    for ax in axes.flat[len(scores):]:
        ax.set_visible(False)
    for ax, (name, score) in zip(axes.flat, scores.items(), strict=False):
        for tk, freqs in score.frequency_history:
            ax.plot(np.full(freqs.size, tk), freqs, ".", color="tab:blue", ms=2)
        for j in range(true_f.shape[1]):
            strong = weight[:, j].max() >= 0.1
            ax.plot(t, true_f[:, j], "k-" if strong else "k:", lw=1.2 if strong else 0.8)
        mark_events([ax], truth.scenario.event_times())
        for ev in score.events:
            ax.axvline(ev, color="tab:red", lw=0.8, alpha=0.7)
        ax.set_title(name)
        ax.set_xlabel("time (s)")
        ax.set_ylim(0.07, 0.1)
        ax.grid(alpha=0.3)
    for row in axes:
        row[0].set_ylabel("natural frequency (Hz)")
    handles = [Line2D([], [], ls="", marker=".", color="tab:blue", label="identified"),
               Line2D([], [], color="k", lw=1.2, label="true, torque-excited"),
               Line2D([], [], color="k", ls=":", lw=0.8, label="true, weakly excited"),
               Line2D([], [], color="tab:red", lw=0.8, label="detected change")]
    if truth.scenario.event_times():
        handles.append(Line2D([], [], color="k", ls="--", lw=0.8, label="docking"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles))
    fig.suptitle(f"{scenario}: identified vs true modal frequencies (first paddle and "
                 "antenna modes), seed 0")
    save(fig, path)
    return fig


def plot_rigid_gain(path: str | Path, truth: FlexibleSpacecraftModel,
                    scores: Mapping[str, Any], scenario: str) -> None:
    """Diagonal of the identified inverse inertia over time against the truth's."""
    fig = Figure(figsize=(10, 8))
    axes = fig.subplots(3, 1, sharex=True)
    n_samples = len(next(iter(scores.values())).models)
    t = np.arange(0, n_samples) * truth.dt
    true_g = np.array([np.diag(np.linalg.inv(truth.inertia(tk))) for tk in t[::10]])
    for i, axis in enumerate(("x (roll)", "y (pitch)", "z (yaw)")):
        ax = axes[i]
        ax.plot(t[::10], 1e5 * true_g[:, i], "k-", lw=2, label="true")
        for j, (name, score) in enumerate(scores.items()):
            hist = score.gain_history
            if hist is None or not len(hist):
                continue
            ax.plot(hist[:, 0], 1e5 * hist[:, 1 + i], lw=1, color=f"C{j}", label=name)
        lo, hi = true_g[:, i].min(), true_g[:, i].max()
        ax.set_ylim(1e5 * lo * 0.7, 1e5 * hi * 1.3)
        ax.set_ylabel(f"(J^-1)_{axis[0]}{axis[0]} (1e-5 / kg m^2)")
        ax.grid(alpha=0.3)
    mark_events(axes, truth.scenario.event_times())
    axes[0].legend(fontsize=7, ncol=4)
    axes[-1].set_xlabel("time (s)")
    events = "; dashed: dockings" if truth.scenario.event_times() else ""
    fig.suptitle(f"{scenario}: rigid-body gain J(t)^-1 read from the identified model, seed 0\n"
                 f"(axis zoomed to +-30 % of the truth{events})", fontsize=10)
    save(fig, path)


#: The series of the prediction figure, at most five: the trivial baseline, the ceiling,
#: the default identifier and the paper's two recursive methods (the rest are in the table).
PREDICTION_SERIES = ("persistence", "truth frozen at k", "rigid-flexible", "improved-rpbsid",
                     "classical-rpbsid")


def plot_prediction_horizons(path: str | Path, metrics: Mapping[str, Any],
                             raw: Mapping[str, Any], layout: Any) -> Figure:
    """VAF against prediction horizon per output group: median and interquartile band
    over seeds for at most five methods (:data:`PREDICTION_SERIES`), persistence grey
    dashed and the frozen truth black dashed; each panel's axis starts just below the
    lowest median it shows (values below are drawn at the axis' edge).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    dt = metrics["dt"]
    horizons = [str(h) for h in metrics["horizons_samples"]]
    hs = np.array([int(h) * dt for h in horizons])
    groups = [g for g in ("attitude", "rate", "deflection")
              if any(g in metrics["methods"][m]["summary"]["h_step_vaf"][horizons[0]]
                     for m in metrics["methods"])]
    fig = Figure(figsize=(4.2 * len(groups) + 2.2, 4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(groups)))
    shown = [m for m in metrics["methods"] if m in PREDICTION_SERIES] or \
        list(metrics["methods"])[:5]

    def column(vaf: Mapping[str, Any], group: str, key: str) -> np.ndarray:
        values = [vaf[h].get(group, {}).get(key, vaf[h].get(group, {}).get("median"))
                  for h in horizons]
        return np.array([np.nan if v is None else v for v in values], dtype=float)

    lowest = {g: 100.0 for g in groups}
    for j, name in enumerate(shown):
        vaf = metrics["methods"][name]["summary"]["h_step_vaf"]
        style = "--" if name in ("persistence", "truth frozen at k") else "-"
        color = "k" if name == "truth frozen at k" else "0.5" if name == "persistence" \
            else f"C{j}"
        for ax, group in zip(axes, groups, strict=True):
            med = column(vaf, group, "median")
            ax.plot(hs, med, style, marker="o", ms=3, color=color, label=name)
            ax.fill_between(hs, column(vaf, group, "q25"), column(vaf, group, "q75"),
                            color=color, alpha=0.12, lw=0)
            if np.isfinite(med).any():
                lowest[group] = min(lowest[group], float(np.nanmin(med)))
    for ax, group in zip(axes, groups, strict=True):
        ax.set_xscale("log")
        floor = max(0.0, 5.0 * np.floor(lowest[group] / 5.0) - 5.0)
        ax.set_ylim(floor, 100.5)
        ax.set_xlabel("prediction horizon (s)")
        ax.set_ylabel(f"{group} VAF (%)")
        ax.set_title(group)
        ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right center", fontsize=8)
    fig.suptitle(f"{metrics['scenario']}, {metrics['snr_db']} dB: h-step-ahead prediction "
                 f"VAF, median and interquartile band over {metrics['seeds']} seeds")
    save(fig, path)
    return fig


def _band(ax: Axes, t: np.ndarray, runs: Sequence[np.ndarray], label: str, color: str,
          log: bool = False, ls: str = "-") -> None:
    """Median line and interquartile band over seeds (runs cut to the shortest)."""
    n = min(r.size for r in runs)
    stack = np.array([r[:n] for r in runs])
    with warnings.catch_warnings():          # all-NaN columns: before an identifier's warm-up
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, med, hi = np.nanpercentile(stack, [25, 50, 75], axis=0)
    plot = ax.semilogy if log else ax.plot
    # a dotted series is drawn as a wide pale band line, so it shows under a dashed one
    # that it follows (the scheduled LQG under the oracle)
    if ls == ":":
        plot(t[:n], med, lw=4, color=color, alpha=0.45, solid_capstyle="round", label=label)
    else:
        plot(t[:n], med, lw=1.2, color=color, ls=ls, label=label)
    ax.fill_between(t[:n], lo, hi, color=color, alpha=0.15, lw=0)


#: The controllers the comparison figure draws, at most five, each with its style
#: (colour, line): the adaptive loop, what it must beat (the robust design), the design
#: that goes unstable, the ceiling (black dashed) and the same-start ceiling (grey
#: dashed: the adaptive loop's start, then the clairvoyant law). The others are in the
#: table.
FIGURE_SERIES = {"fixed LQG": ("C3", "-"), "robust LQG": ("C0", "-"),
                 "adaptive LQG": ("C4", "-"), "same-start ceiling": ("0.55", "--"),
                 "ceiling": ("k", "--")}


def plot_control_comparison(runs: Mapping[str, Sequence[Trajectory]],
                            model: FlexibleSpacecraftModel, path: str | Path,
                            title: str = "", scored_from_s: float = 100.0) -> None:
    """Closed-loop comparison over seeds: median and interquartile band.

    Panels: the common quadratic stage cost (mean over the last 10 s, log; the
    quantity every LQG here minimizes, :func:`controllers.stage_costs`), the
    attitude error (log), tip deflection, torque, and for controllers with an
    identifier the identified rigid-body gain's error against the true
    ``J(t)^-1`` and the identified against the true modal frequencies (seed 0,
    zoomed on the flexible band). Dashed lines: scenario events; dotted: the
    end of the adaptive loop's start (40 s) and the stationary window's start.
    """
    shown = [name for name in FIGURE_SERIES if name in runs]
    shown += [name for name in runs if name not in shown][:max(0, 5 - len(shown))]
    styles = {name: FIGURE_SERIES.get(name, (f"C{5 + i}", "-"))
              for i, name in enumerate(shown)}
    runs = {name: runs[name] for name in shown}
    adaptive = {n: r for n, r in runs.items() if r[0].gain_error is not None}
    rows = 6 if adaptive else 4
    layout = model.output_layout
    c_att = model.C[layout.slice("attitude")]
    c_defl = model.C[layout.slice("deflection")]
    fig = Figure(figsize=(12, 2.5 * rows), layout="constrained")
    all_axes = fig.subplots(rows, 1, sharex=True)
    cost_ax, axes = all_axes[0], all_axes[1:]
    colors = {name: color for name, (color, _) in styles.items()}
    lines = {name: ls for name, (_, ls) in styles.items()}
    window = max(1, round(10.0 / model.dt))

    def trailing_mean(values: np.ndarray) -> np.ndarray:
        """Mean over the last ``window`` samples (fewer at the start)."""
        total = np.cumsum(values)
        total[window:] = total[window:] - total[:-window]
        return total / np.minimum(np.arange(1, values.size + 1), window)

    for name, trajs in runs.items():
        t = trajs[0].time
        costs = [trailing_mean(stage_costs(tr, model)[:, :4].sum(axis=1)) for tr in trajs]
        style = {"log": True, "ls": lines[name]}
        _band(cost_ax, t, [np.maximum(c, 1e-8) for c in costs], name, colors[name], **style)
        err = [np.abs((tr.states[1:] @ c_att.T - tr.reference[1:]) * DEG_PER_RAD).max(axis=1)
               for tr in trajs]
        _band(axes[0], t, [np.maximum(e, 1e-5) for e in err], name, colors[name], **style)
        _band(axes[1], t, [np.abs(tr.states[1:] @ c_defl.T).max(axis=1) * 1e3 for tr in trajs],
              name, colors[name], **style)
        _band(axes[2], t, [np.linalg.norm(tr.torque, axis=1) for tr in trajs], name,
              colors[name], **style)
    for name, trajs in adaptive.items():
        tf = trajs[0].frequency_time
        _band(axes[3], tf, [100 * tr.gain_error for tr in trajs], name, colors[name])
        first = trajs[0]
        axes[4].plot(tf, first.identified_frequencies, ".", ms=2, color=colors[name])
        axes[4].plot(tf, first.true_frequencies, "k-", lw=1)
    cost_ax.set_ylabel("stage cost\n(10 s running mean)")
    cost_ax.set_title("the common quadratic cost (what every LQG here minimizes), 10 s running "
                      "mean\nthe tables' ratios: its mean over the whole episode to the "
                      "ceiling's, from 40 s (dotted) to the same-start ceiling's", fontsize=9)
    axes[0].set_ylabel("max |attitude error| (deg)")
    axes[1].set_ylabel("max |tip deflection| (mm)")
    axes[2].set_ylabel("|torque| (N m)")
    if adaptive:
        axes[3].set_ylabel("rigid gain error (%)")
        axes[3].set_ylim(0, 50)
        axes[3].set_title("identified rigid-body gain against the true J(t)^-1", fontsize=9)
        axes[4].set_ylabel("frequency (Hz)")
        true = np.concatenate([tr[0].true_frequencies.ravel() for tr in adaptive.values()])
        true = true[np.isfinite(true)]
        if true.size:
            axes[4].set_ylim(0.7 * true.min(), 1.3 * true.max())
        axes[4].set_title("identified (dots) vs true (lines) modal frequencies, seed 0",
                          fontsize=9)
    axes[-1].set_xlabel("time (s)")
    first_run = next(iter(runs.values()))[0]
    mark_events(all_axes, first_run.events)
    for ax in all_axes:
        for start in (SAME_START_S, scored_from_s):
            ax.axvline(start, color="gray", ls=":", lw=0.8)
        ax.grid(alpha=0.3)
    fig.legend(*cost_ax.get_legend_handles_labels(), loc="outside right upper", fontsize=9,
               title="median, 25-75 %\nband over seeds", title_fontsize=8)
    fig.suptitle(title, fontsize=10)
    save(fig, path)


def plot_learning_curves(path: str | Path, metrics: Mapping[str, Any]) -> None:
    """Evaluation cost, attitude RMS and return against env steps; the oracle, adaptive
    and fixed LQG on the same episodes as horizontal lines."""
    fig = Figure(figsize=(15, 4))
    axes = fig.subplots(1, 3)
    keys = ("cost_after_100s", "attitude_rms_deg", "return")
    for run in metrics["runs"]:
        if not run["curve"]:
            continue
        steps = [c["timesteps"] for c in run["curve"]]
        for ax, key in zip(axes, keys, strict=True):
            if all(key in c for c in run["curve"]):
                ax.plot(steps, [c[key] for c in run["curve"]], "o-", label=f"seed {run['seed']}")
    for name, ref, style in (("oracle LQG", "oracle_lqg", ":"),
                             (FAST_ADAPTIVE_LQG, "adaptive_lqg", "--"),
                             ("fixed LQG", "fixed_lqg", "-.")):
        for ax, key in zip(axes, keys, strict=True):
            if ref in metrics and key in metrics[ref]:
                ax.axhline(metrics[ref][key], color="k", ls=style, label=name)
    axes[0].set_yscale("log")
    axes[1].set_yscale("log")
    axes[0].set_ylabel("cost from 100 s (median episode)")
    axes[1].set_ylabel("attitude RMS (deg), mean over episodes")
    axes[2].set_ylabel("return, mean over episodes")
    for ax in axes:
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{metrics['algo'].upper()}, features: {metrics['features']}, "
                 f"{metrics['scenario']}")
    save(fig, path)


#: Agent settings a comparison figure draws at most (the rest are in ``rl-table``).
MAX_AGENT_SERIES = 5


def plot_rl_comparison(path: str | Path, runs: Sequence[Mapping[str, Any]]) -> Figure:
    """Learning curves of several ``spacecraft train`` runs: median and range over seeds.

    The common cost from 100 s, median episode (log scale; the attitude RMS
    for runs that did not record it) and a second panel against env steps, one colour per
    setting (algorithm and features; at most :data:`MAX_AGENT_SERIES`, the
    title says when more were given); the oracle, adaptive and fixed LQG on the
    same evaluation episodes as thin grey reference lines under the agents (and
    the scheduled LQG, for runs that scored it); the right panel is the return
    for a bounded reward and, for a cost reward (whose return the slew
    dominates), the cost from 100 s over the mean episode;
    the legend outside the data. An evaluation with an infinite cost (an episode
    that left the attitude bound) sits on a marked "crashed" level ten times
    above the largest finite value.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    shown = list(runs[:MAX_AGENT_SERIES])
    fig = Figure(figsize=(13, 4.8), layout="constrained")
    axes = fig.subplots(1, 2)
    # the common cost where every run recorded it (older runs: the attitude RMS)
    def recorded(key: str) -> bool:
        return all(key in c for m in runs for r in m["runs"] for c in r["curve"])

    left = "cost_after_100s" if recorded("cost_after_100s") else "attitude_rms_deg"
    markers = "osD^v"
    last = runs[-1]
    bounded = last.get("reward", "cost") == "bounded"
    # right: the return of a bounded reward (steps held); under a cost reward the
    # return is the whole episode's cost, which the slew dominates alike for every
    # policy, so the right panel is the cost from 100 s over the mean episode instead
    right = "cost_after_100s_mean" if not bounded and recorded("cost_after_100s_mean") \
        else "return"
    references = [(name, key, style) for name, key, style in (
        ("oracle LQG", "oracle_lqg", ":"),
        ("scheduled LQG", "scheduled_lqg", (0, (3, 1, 1, 1, 1, 1))),
        (FAST_ADAPTIVE_LQG, "adaptive_lqg", "--"),
        ("fixed LQG", "fixed_lqg", "-."))
        if key in last and left in last[key] and right in last[key]]
    series = []
    for m in shown:
        curves = [r["curve"] for r in m["runs"] if r["curve"]]
        if curves:
            length = min(len(c) for c in curves)
            series.append((m, curves, length, {
                key: np.array([[c[key] for c in curve[:length]] for curve in curves],
                              dtype=float) for key in (left, right)}))
    # an evaluation whose episode left the attitude bound costs infinity; it is drawn
    # on a marked "crashed" level above every finite value instead of vanishing
    crash = {}
    for key in (left, right):
        finite = np.concatenate([np.ravel(values[key]) for *_, values in series]
                                + [[float(last[ref][key]) for _, ref, _ in references]])
        finite = finite[np.isfinite(finite)]
        if any(np.any(~np.isfinite(values[key])) for *_, values in series):
            crash[key] = 10.0 * finite.max() if finite.size and finite.max() > 0 else 1.0
    for j, (m, curves, length, values) in enumerate(series):
        steps = np.array([c["timesteps"] for c in curves[0][:length]])
        label = f"{m['algo'].upper()}, {m['features']} ({len(curves)} seeds)"
        for ax, key in zip(axes, (left, right), strict=True):
            shown_values = np.where(np.isfinite(values[key]), values[key], crash.get(key, np.nan))
            line, = ax.plot(steps, np.median(shown_values, axis=0), "-", marker=markers[j],
                            ms=5, lw=1.8, color=f"C{j}", label=label, zorder=3)
            ax.fill_between(steps, shown_values.min(axis=0), shown_values.max(axis=0),
                            color=line.get_color(), alpha=0.15, zorder=2)
    for name, key, style in references:
        for ax, value in zip(axes, (last[key][left], last[key][right]), strict=True):
            ax.axhline(value, color="0.4", ls=style, lw=1.0, zorder=1,
                       label=f"{name} (same episodes)")
    for ax, key in zip(axes, (left, right), strict=True):
        if key in crash:
            ax.axhline(crash[key], color="C3", ls=(0, (1, 3)), lw=1.0, zorder=1)
            ax.annotate("crashed (an episode left the attitude bound: cost infinite)",
                        (0.01, crash[key]), xycoords=("axes fraction", "data"),
                        xytext=(0, 3), textcoords="offset points", fontsize=7, color="C3")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("cost from 100 s, median episode" if left == "cost_after_100s"
                       else "attitude RMS (deg), evaluation seeds")
    if right == "return":
        axes[1].set_ylabel("return (bounded reward: steps held, of 2500)" if bounded
                           else "return (negative cost), evaluation seeds")
        if not bounded:            # cost returns span decades (crashes pay ~1e6)
            axes[1].set_yscale("symlog", linthresh=1e4)
    else:
        axes[1].set_ylabel("cost from 100 s, mean over episodes")
        axes[1].set_yscale("log")
    for ax in axes:
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 4),
               fontsize=8)
    algos = sorted({m["algo"].upper() for m in shown})
    task = ("randomized " if last.get("randomize") else "") + last["scenario"]
    more = f" (the first {len(shown)} of {len(runs)} settings)" if len(runs) > len(shown) \
        else ""
    fig.suptitle(f"{' and '.join(algos)} on {task}{more}: median (line) and range (band) "
                 "over training seeds")
    save(fig, path)
    return fig


def plot_adaptation(path: str | Path, result: Mapping[str, Any]) -> Figure:
    """The RMA comparison of :func:`spacecraft_lab.adaptation.run_adaptation`.

    Left: each policy's cost from 100 s on every scored episode (points) and
    the median (bar), flown with the true, the estimated and the nominal
    parameters, beside the oracle and scheduled LQG's medians on the same
    episodes (grey lines). Right: the parameter error from 60 s (RMS, frame
    units) of the adaptation module's estimate, the identifier's raw vector
    and the nominal one, per channel group and policy.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    sources = ("true", "estimated", "nominal")
    agents = result["agents"]
    fig = Figure(figsize=(13, 4.8), layout="constrained")
    left, right = fig.subplots(1, 2)
    width = 0.8 / len(sources)
    for i, agent in enumerate(agents):
        for j, source in enumerate(sources):
            costs = np.asarray(agent["scores"][source]["cost_after_100s_per_seed"], float)
            x = i + (j - (len(sources) - 1) / 2) * width
            left.scatter(np.full(costs.size, x), costs, s=12, color=f"C{j}", alpha=0.6,
                         zorder=3, label=f"{source} parameters" if i == 0 else None)
            left.hlines(np.median(costs), x - 0.4 * width, x + 0.4 * width, color=f"C{j}",
                        lw=2.5, zorder=4)
    for name, key, style in (("oracle LQG", "oracle_lqg", ":"),
                             ("scheduled LQG", "scheduled_lqg", "--")):
        if key in result["comparators"]:
            left.axhline(result["comparators"][key]["cost_after_100s"], color="0.4", ls=style,
                         lw=1.0, zorder=1, label=f"{name}, median (same episodes)")
    left.set_xticks(range(len(agents)))
    left.set_xticklabels([Path(a["path"]).stem.rsplit("-", 1)[-1].replace("seed", "seed ")
                          for a in agents])
    left.set_xlabel("policy (training seed)")
    left.set_yscale("log")
    left.set_ylabel("cost from 100 s per episode (bar: median)")
    groups = ("gain", "frequency", "damping")
    vectors = ("estimated", "identifier", "nominal")
    names = {"estimated": "adaptation module", "identifier": "identifier, raw",
             "nominal": "nominal plant"}
    width = 0.8 / len(vectors)
    for j, vector in enumerate(vectors):
        errors = np.array([[a["errors"][vector][g] for g in groups] for a in agents])
        x = np.arange(len(groups)) + (j - (len(vectors) - 1) / 2) * width
        right.bar(x, np.median(errors, axis=0), width, color=f"C{j + 3}",
                  label=f"{names[vector]} (median over policies)")
        right.scatter(np.repeat(x[None], len(agents), axis=0).ravel(), errors.ravel(), s=10,
                      color="k", zorder=3)
    right.set_xticks(range(len(groups)))
    right.set_xticklabels(["log gain", "log frequency", "10 x damping"])
    right.set_ylabel("RMS error from 60 s (frame units)")
    right.set_yscale("log")
    for ax in (left, right):
        ax.grid(alpha=0.3)
    handles, labels = [], []
    for ax in (left, right):
        h, lab = ax.get_legend_handles_labels()
        handles += h
        labels += lab
    fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=8)
    seeds = result["eval_seeds"]
    fig.suptitle(f"Each policy ({result['features']}, {result['scenario']}) flown with the "
                 f"true, estimated and nominal parameters, episodes {seeds[0]}-{seeds[-1]}\n"
                 "right: how far each parameter vector is from the truth")
    save(fig, path)
    return fig


_APPENDAGES = {"s": "solar paddle", "a": "antenna"}


def sensor_name(label: str) -> str:
    """A deflection channel's label in words: ``"w_s1_1.00"`` -> ``"solar paddle 1, tip"``
    (``w_<appendage><number>_<position along the span>``); other labels unchanged.

    Returns
    -------
    str
        The label.
    """
    parts = label.split("_")
    if len(parts) != 3 or parts[0] != "w" or parts[1][:1] not in _APPENDAGES:
        return label
    where = "tip" if float(parts[2]) == 1.0 else f"{float(parts[2]):.0%} of the span"
    return f"{_APPENDAGES[parts[1][0]]} {parts[1][1:]}, {where}"


def plot_demo_response(path: str | Path, t: np.ndarray, attitude_deg: np.ndarray,
                       deflection_m: np.ndarray, deflection_labels: Sequence[str],
                       t_sparse: np.ndarray, inertia_diag: np.ndarray,
                       frequencies_hz: np.ndarray, events: Sequence[float],
                       title: str) -> None:
    """Attitude, tip deflections, inertia J(t) and the first system frequencies."""
    fig = Figure(figsize=(9, 10))
    axes = fig.subplots(4, 1, sharex=True)
    for i, name in enumerate(AXIS_NAMES):
        axes[0].plot(t, attitude_deg[:, i], label=name)
    axes[0].set_ylabel("attitude (deg)")
    for i, label in enumerate(deflection_labels):
        axes[1].plot(t, 1e3 * deflection_m[:, i], label=sensor_name(label))
    axes[1].set_ylabel("tip deflection (mm)")
    for i, name in enumerate(("J_xx", "J_yy", "J_zz")):
        axes[2].plot(t_sparse, inertia_diag[:, i], label=name)
    axes[2].set_ylabel("inertia (kg m$^2$)")
    for i in range(frequencies_hz.shape[1]):
        axes[3].plot(t_sparse, frequencies_hz[:, i], label=f"mode {i + 1}")
    axes[3].set_ylabel("system frequency (Hz)")
    axes[3].set_xlabel("time (s)")
    mark_events(axes, events)
    for ax in axes:
        ax.legend(loc="upper right", fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    save(fig, path, dpi=110)


def plot_performance_profiles(path: str | Path, thresholds: np.ndarray,
                              profiles: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
                              title: str = "") -> Figure:
    """The share of runs and draws costing at most each threshold, with 95 % bands
    (:func:`spacecraft_lab.rl_protocol.performance_profiles`); higher and further left
    is better.

    Parameters
    ----------
    path : str or Path
        The PNG written.
    thresholds : (k,) ndarray
        The costs on the x-axis (log scale).
    profiles : mapping
        Name -> ``(share, low, high)``, each ``(k,)``.
    title : str
        The figure's title.

    Returns
    -------
    matplotlib.figure.Figure
        The figure (also saved to ``path``).
    """
    fig = Figure(figsize=(7.5, 4.5))
    ax = fig.subplots()
    for j, (name, (share, low, high)) in enumerate(profiles.items()):
        line, = ax.step(thresholds, share, where="post", lw=2.0 if name == "agent" else 1.3,
                        color=f"C{j}", label=name)
        ax.fill_between(thresholds, low, high, step="post", color=line.get_color(),
                        alpha=0.15)
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("cost from 100 s (common quadratic cost), threshold")
    ax.set_ylabel("share of runs x draws at or below it")
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(loc="outside right upper", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    save(fig, path)
    return fig
