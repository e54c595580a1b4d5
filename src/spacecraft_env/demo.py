"""Environment demo: a rendered rollout of a time-varying scenario.

Runs one episode of a registered environment under a simple attitude PD law
(bandwidth 0.05 rad/s, well below the first flexible mode; a stand-in until
the ``controllers`` package's harness is used), prints a summary and writes

* ``summary.json``: episode figures,
* ``response.png``: attitude, tip deflections, inertia J(t) and the first
  system frequencies over time, docking events marked,
* ``rollout.gif`` and ``frame.png``: rendered frames.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from tqdm import tqdm

from spacecraft_env.env import FlexibleSpacecraftEnv

__all__ = ["run_demo"]


def _pd_action(env: FlexibleSpacecraftEnv, obs: np.ndarray) -> np.ndarray:
    """Attitude PD on the measured angles and rates, normalized to [-1, 1]."""
    j = np.diag(env.model.inertia(env.time))
    wc, zeta = 0.05, 0.7
    torque = -j * wc**2 * (obs[:3] - env.reference) - 2 * zeta * wc * j * obs[3:6]
    return np.clip(torque / env.max_torque, -1, 1).astype(np.float32)


def run_demo(scenario: str = "docking", out: str | Path = "results/demo", seed: int = 0,
             steps: int = 2500, gif_every: int = 10) -> dict:
    """Run the demo rollout and write its artefacts to ``out``.

    Parameters
    ----------
    scenario : str
        Scenario name (see :data:`spacecraft_env.SCENARIOS`).
    out : path
        Output directory (created).
    seed : int
        Environment seed.
    steps : int
        Episode length in steps (dt = 0.1 s).
    gif_every : int
        Keep every ``gif_every``-th frame in the GIF.

    Returns
    -------
    dict
        The summary written to ``summary.json``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    env = FlexibleSpacecraftEnv(scenario, render_mode="rgb_array", initial_attitude_deg=3.0)
    obs, info = env.reset(seed=seed)
    initial_attitude = info["state"][:3].copy()
    times, att, defl, torque, inertia, freqs, frames = [], [], [], [], [], [], []
    total_reward = 0.0
    for k in tqdm(range(steps), desc=f"{scenario} rollout", unit="step"):
        action = _pd_action(env, obs)
        obs, reward, terminated, truncated, info = env.step(action)
        total_reward += reward
        times.append(info["time"])
        att.append(np.rad2deg(info["state"][:3]))
        defl.append(env.model.C[6:] @ info["state"])
        torque.append(info["torque"])
        if k % gif_every == 0:
            frames.append(Image.fromarray(env.render()))
            inertia.append(np.diag(env.model.inertia(env.time)))
            freqs.append(env.model.modal(env.time)[0][:3])
        if terminated or truncated:
            break
    t = np.array(times)
    att, defl, torque = np.array(att), np.array(defl), np.array(torque)
    t_sparse = t[::gif_every][: len(inertia)]
    events = list(env.scenario.event_times())

    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axes[0].plot(t, att[:, i], label=name)
    axes[0].set_ylabel("attitude (deg)")
    for i, label in enumerate(env.model.output_labels[6:]):
        axes[1].plot(t, 1e3 * defl[:, i], label=label)
    axes[1].set_ylabel("tip deflection (mm)")
    inertia_arr = np.array(inertia)
    for i, name in enumerate(("J_xx", "J_yy", "J_zz")):
        axes[2].plot(t_sparse, inertia_arr[:, i], label=name)
    axes[2].set_ylabel("inertia (kg m$^2$)")
    freq_arr = np.array(freqs)
    for i in range(freq_arr.shape[1]):
        axes[3].plot(t_sparse, freq_arr[:, i], label=f"mode {i + 1}")
    axes[3].set_ylabel("system frequency (Hz)")
    axes[3].set_xlabel("time (s)")
    for ax in axes:
        for ev_t in events:
            ax.axvline(ev_t, color="k", ls="--", lw=0.8)
        ax.legend(loc="upper right", fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{scenario}: PD-regulated rollout, seed {seed} (dashed: docking events)")
    fig.tight_layout()
    fig.savefig(out / "response.png", dpi=110)
    plt.close(fig)

    frames[0].save(out / "rollout.gif", save_all=True, append_images=frames[1:],
                   duration=100, loop=0)
    mid = min(len(frames) - 1, int(events[0] / env.model.dt / gif_every) + 3) if events else -1
    frames[mid].save(out / "frame.png")

    summary = {
        "scenario": scenario,
        "seed": seed,
        "steps": len(t),
        "duration_s": float(t[-1]) if len(t) else 0.0,
        "return": float(total_reward),
        "initial_attitude_deg": np.rad2deg(initial_attitude).tolist(),
        "final_attitude_error_deg": float(np.abs(att[-1] - np.rad2deg(env.reference)).max()),
        "peak_tip_deflection_mm": float(1e3 * np.abs(defl).max()),
        "peak_torque_Nm": float(np.abs(torque).max()),
        "docking_events_s": events,
        "inertia_diag_start": inertia_arr[0].tolist(),
        "inertia_diag_end": inertia_arr[-1].tolist(),
        "first_frequencies_hz_start": freq_arr[0].tolist(),
        "first_frequencies_hz_end": freq_arr[-1].tolist(),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary
