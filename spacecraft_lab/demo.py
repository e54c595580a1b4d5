"""Environment demo: a rendered rollout of a time-varying scenario.

Runs one episode of the environment under the attitude PD baseline
(:class:`controllers.PD`, bandwidth 0.05 rad/s, well below the first
flexible mode), prints a summary and writes

* ``summary.json``: episode figures,
* ``response.png``: attitude, tip deflections, inertia J(t) and the first
  system frequencies over time, docking events marked,
* ``rollout.gif`` and ``frame.png``: rendered frames.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image
from tqdm import tqdm

from controllers import PD, Trajectory
from spacecraft_conventions import AXIS_NAMES, DEG_PER_RAD
from spacecraft_env import FlexibleSpacecraftEnv
from spacecraft_lab.plots import plot_demo_response

__all__ = ["MAX_DEMO_STEPS", "MAX_GIF_FRAMES", "demo_summary", "run_demo"]

#: Frames the GIF keeps at most: a longer rollout keeps every k-th frame with k grown to
#: fit, so the demo's memory does not grow with ``steps`` (each frame is held as a
#: palette image, one byte per pixel, until the GIF is written).
MAX_GIF_FRAMES = 250
#: Longest demo rollout, steps (about 2.8 h of flight).
MAX_DEMO_STEPS = 100_000


def run_demo(scenario: str = "docking", out: str | Path = "results/demo", seed: int = 0,
             steps: int = 2500, gif_every: int = 10, save_trajectory: bool = False) -> dict:
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
        Keep every ``gif_every``-th frame in the GIF (more apart when the
        rollout has over :data:`MAX_GIF_FRAMES` of them).
    save_trajectory : bool
        Also write the rollout as ``trajectory.npz`` (:class:`controllers.Trajectory`).

    Returns
    -------
    dict
        The summary written to ``summary.json``.

    Raises
    ------
    ValueError
        ``steps`` or ``gif_every`` not an integer in range.
    """
    if isinstance(steps, bool) or not isinstance(steps, int) \
            or not 1 <= steps <= MAX_DEMO_STEPS:
        raise ValueError(f"steps must be an integer in [1, {MAX_DEMO_STEPS}], got {steps!r}")
    if isinstance(gif_every, bool) or not isinstance(gif_every, int) or gif_every < 1:
        raise ValueError(f"gif_every must be an integer >= 1, got {gif_every!r}")
    gif_every = max(gif_every, -(-steps // MAX_GIF_FRAMES))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    env = FlexibleSpacecraftEnv(scenario, render_mode="rgb_array", initial_attitude_deg=3.0)
    obs, info = env.reset(seed=seed)
    pd = PD(env)
    pd.reset(seed)
    layout = env.model.output_layout
    c_att = env.model.C[layout.slice("attitude")]
    c_defl = env.model.C[layout.slice("deflection")]
    initial_attitude = c_att @ info["state"]
    times, att, defl, torque, inertia, freqs, frames = [], [], [], [], [], [], []
    # the full record is kept only when it is saved
    observations, actions, states, refs, rewards = [obs], [], [info["state"]], \
        [info["reference"]], []
    keep = save_trajectory
    total_reward = 0.0
    for k in tqdm(range(steps), desc=f"{scenario} rollout", unit="step"):
        action = pd.act(obs, info)
        obs, reward, terminated, truncated, info = env.step(action)
        total_reward += reward
        if keep:
            observations.append(obs)
            actions.append(action)
            states.append(info["state"])
            refs.append(info["reference"])
            rewards.append(reward)
        times.append(info["time"])
        att.append(c_att @ info["state"] * DEG_PER_RAD)
        defl.append(c_defl @ info["state"])
        torque.append(info["torque"])
        if k % gif_every == 0:
            frames.append(Image.fromarray(env.render()).quantize(256))
            inertia.append(np.diag(env.model.inertia(env.time)))
            freqs.append(env.model.modal(env.time)[0][:3])
        if terminated or truncated:
            break
    t = np.array(times)
    att, defl, torque = np.array(att), np.array(defl), np.array(torque)
    t_sparse = t[::gif_every][: len(inertia)]
    events = list(env.scenario.event_times())

    inertia_arr, freq_arr = np.array(inertia), np.array(freqs)
    plot_demo_response(out / "response.png", t, att, defl,
                       env.model.output_labels[layout.slice("deflection")], t_sparse,
                       inertia_arr, freq_arr, events,
                       f"{scenario}: PD-regulated rollout, seed {seed}"
                       + (" (dashed: docking events)" if events else ""))

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
        "initial_attitude_deg": (initial_attitude * DEG_PER_RAD).tolist(),
        "final_attitude_error_deg": float(np.abs(att[-1] - env.reference * DEG_PER_RAD).max()),
        "peak_tip_deflection_mm": float(1e3 * np.abs(defl).max()),
        "peak_torque_Nm": float(np.abs(torque).max()),
        "docking_events_s": events,
        "inertia_diag_start": inertia_arr[0].tolist(),
        "inertia_diag_end": inertia_arr[-1].tolist(),
        "first_frequencies_hz_start": freq_arr[0].tolist(),
        "first_frequencies_hz_end": freq_arr[-1].tolist(),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    if save_trajectory:
        Trajectory(time=t, observations=np.array(observations), actions=np.array(actions),
                   torque=torque, states=np.array(states), reference=np.array(refs),
                   rewards=np.array(rewards), terminated=bool(terminated),
                   events=tuple(events)).save(out / "trajectory.npz")
    return summary


def _hz(freqs: list[float]) -> str:
    return "/".join(f"{f:.4f}" for f in freqs)


def demo_summary(summary: dict, out: str | Path) -> str:
    """Plain sentences on a demo rollout, numbers rounded, and where the figures are.

    Returns
    -------
    str
        The sentences, one per line.
    """
    events = summary["docking_events_s"]
    j0, j1 = summary["inertia_diag_start"], summary["inertia_diag_end"]
    f0, f1 = summary["first_frequencies_hz_start"], summary["first_frequencies_hz_end"]
    lines = [
        f"Flew the {summary['scenario']} scenario for {summary['duration_s']:.0f} s "
        f"(seed {summary['seed']}) under a PD attitude regulator, the demo's simple "
        "controller ('spacecraft control' compares the LQG designs).",
        f"It ended {summary['final_attitude_error_deg']:.3f} deg from the target attitude; "
        f"the tip deflections peaked at {summary['peak_tip_deflection_mm']:.1f} mm and the "
        f"torque at {summary['peak_torque_Nm']:.2f} N m.",
    ]
    if events:
        change = ", ".join(f"{axis} {a:,.0f} -> {b:,.0f} kg m^2 ({100 * (b / a - 1):+.0f} %)"
                           for axis, a, b in zip(AXIS_NAMES, j0, j1, strict=True))
        lines.append("Events at " + ", ".join(f"{t:.0f} s" for t in events) + " changed the "
                     f"plant: inertia {change}; first frequencies {_hz(f0)} -> {_hz(f1)} Hz.")
    else:
        lines.append(f"The plant's first frequencies went {_hz(f0)} -> {_hz(f1)} Hz.")
    out = Path(out)
    lines.append(f"Figures: {out / 'response.png'} (attitude, deflections, inertia and "
                 f"frequencies against time), {out / 'rollout.gif'} and {out / 'frame.png'}; "
                 f"numbers in {out / 'summary.json'}.")
    return "\n".join(lines)
