"""Figures of the experiments, drawn through matplotlib's object API.

Every function builds a :class:`matplotlib.figure.Figure` directly and
saves it (PNG); none touches pyplot's global state or selects a backend, so
they work in any process and never open a window.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from controllers import Trajectory
from identifiers import ModelSequence
from spacecraft_conventions import DEG_PER_RAD
from spacecraft_env import FlexibleSpacecraftModel

__all__ = [
    "mark_events",
    "plot_control_comparison",
    "plot_demo_response",
    "plot_identification_modal",
    "plot_identification_responses",
    "plot_learning_curves",
    "save",
]


def save(fig: Figure, path: str | Path, dpi: int = 100) -> None:
    """Lay out and write ``fig`` to ``path``."""
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
                              seqs: Mapping[str, ModelSequence], scenario: str) -> None:
    """Identified modal frequencies (dots) against the truth's (lines) over time."""
    dt = truth.dt
    n_samples = len(next(iter(seqs.values())))
    steps = np.arange(0, n_samples, 10)
    t = steps * dt
    true_f = np.array([truth.modal(float(tk))[0] for tk in t])
    cols = min(3, len(seqs))
    rows = -(-len(seqs) // cols)
    fig = Figure(figsize=(5 * cols, 3.6 * rows))
    axes = fig.subplots(rows, cols, sharey=True, squeeze=False)
    for ax in axes.flat[len(seqs):]:
        ax.set_visible(False)
    for ax, (name, seq) in zip(axes.flat, seqs.items(), strict=False):
        for k in steps:
            if seq.valid[k]:
                f, z = seq[k].modal()
                keep = (f < 1.0) & (z > -0.2) & (z < 1.0)
                ax.plot(np.full(keep.sum(), k * dt), f[keep], ".", color="tab:blue", ms=2)
        ax.plot(t, true_f, "k-", lw=1.0)
        mark_events([ax], truth.scenario.event_times())
        ax.set_title(name)
        ax.set_xlabel("time (s)")
        ax.set_ylim(0, 0.7)
        ax.grid(alpha=0.3)
    for row in axes:
        row[0].set_ylabel("natural frequency (Hz)")
    fig.suptitle(f"{scenario}: identified modal frequencies (dots) vs true (lines), seed 0")
    save(fig, path)


def plot_control_comparison(first: Mapping[str, Trajectory], model: FlexibleSpacecraftModel,
                            path: str | Path, title: str = "") -> None:
    """Attitude error, torque, tip deflection and identified frequencies of one seed."""
    has_freq = any(t.identified_frequencies is not None for t in first.values())
    rows = 4 if has_freq else 3
    layout = model.output_layout
    c_att = model.C[layout.slice("attitude")]
    c_defl = model.C[layout.slice("deflection")]
    fig = Figure(figsize=(10, 2.6 * rows))
    axes = fig.subplots(rows, 1, sharex=True)
    for name, traj in first.items():
        err = np.abs((traj.states[1:] @ c_att.T - traj.reference[1:]) * DEG_PER_RAD).max(axis=1)
        axes[0].semilogy(traj.time, np.maximum(err, 1e-5), label=name, lw=1)
        axes[1].plot(traj.time, np.linalg.norm(traj.torque, axis=1), lw=0.8, label=name)
        defl = np.abs(traj.states[1:] @ c_defl.T).max(axis=1) * 1e3
        axes[2].plot(traj.time, defl, lw=0.8, label=name)
        if has_freq and traj.identified_frequencies is not None:
            axes[3].plot(traj.frequency_time, traj.identified_frequencies, ".", ms=2,
                         color="tab:blue")
            axes[3].plot(traj.frequency_time, traj.true_frequencies, "k-", lw=1)
    axes[0].set_ylabel("max |attitude error| (deg)")
    axes[1].set_ylabel("|torque| (N m)")
    axes[2].set_ylabel("max |tip deflection| (mm)")
    if has_freq:
        axes[3].set_ylabel("frequency (Hz)")
        axes[3].set_ylim(0, 1.0)
        axes[3].set_title("identified (dots) vs true (lines) modal frequencies", fontsize=9)
    axes[-1].set_xlabel("time (s)")
    mark_events(axes, next(iter(first.values())).events)
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=4)
    fig.suptitle(title)
    save(fig, path)


def plot_learning_curves(path: str | Path, metrics: Mapping[str, Any]) -> None:
    """Evaluation attitude RMS and return against env steps, adaptive LQR dashed."""
    fig = Figure(figsize=(11, 4))
    axes = fig.subplots(1, 2)
    for run in metrics["runs"]:
        if not run["curve"]:
            continue
        steps = [c["timesteps"] for c in run["curve"]]
        axes[0].plot(steps, [c["attitude_rms_deg"] for c in run["curve"]], "o-",
                     label=f"seed {run['seed']}")
        axes[1].plot(steps, [c["return"] for c in run["curve"]], "o-")
    axes[0].axhline(metrics["adaptive_lqr"]["attitude_rms_deg"], color="k", ls="--",
                    label="adaptive LQR")
    axes[0].axhline(metrics["target_attitude_rms_deg"], color="gray", ls=":",
                    label="2x adaptive LQR")
    axes[1].axhline(metrics["adaptive_lqr"]["return"], color="k", ls="--")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("attitude RMS (deg), eval seeds")
    axes[1].set_ylabel("return, eval seeds")
    for ax in axes:
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{metrics['algo'].upper()}, features: {metrics['features']}, "
                 f"{metrics['scenario']}")
    save(fig, path)


def plot_demo_response(path: str | Path, t: np.ndarray, attitude_deg: np.ndarray,
                       deflection_m: np.ndarray, deflection_labels: Sequence[str],
                       t_sparse: np.ndarray, inertia_diag: np.ndarray,
                       frequencies_hz: np.ndarray, events: Sequence[float],
                       title: str) -> None:
    """Attitude, tip deflections, inertia J(t) and the first system frequencies."""
    fig = Figure(figsize=(9, 10))
    axes = fig.subplots(4, 1, sharex=True)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axes[0].plot(t, attitude_deg[:, i], label=name)
    axes[0].set_ylabel("attitude (deg)")
    for i, label in enumerate(deflection_labels):
        axes[1].plot(t, 1e3 * deflection_m[:, i], label=label)
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
