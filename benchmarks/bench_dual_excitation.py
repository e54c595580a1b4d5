"""Does the adaptive LQG excite only when information is needed? (dual control)

Runs :class:`controllers.AdaptiveLQG` on the slew task and prints the RMS of
its designed excitation torque (N m, all axes) in windows: the identifier's
warm-up (0-30 s), the 20 s after each docking, and the last 50 s, on the
constant plant (where, once the gain is known, there should be none) and on
docking (where a change should bring it back). The budget after warm-up is
``AdaptiveLQG.excitation_budget`` (0.1 N m per axis); the bar for the last
50 s of the constant plant is 0.01 N m. Median [worst] over seeds.

Usage: ``python benchmarks/bench_dual_excitation.py [--seeds 3]``
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import AdaptiveLQG, run_episode


def windows(traj, events) -> dict[str, float]:
    t, exc = traj.time, traj.excitation
    rms = {}

    def window(name: str, lo: float, hi: float) -> None:
        inside = (t >= lo) & (t < hi)
        rms[name] = float(np.sqrt(np.mean(np.sum(exc[inside] ** 2, axis=1)))) \
            if inside.any() else float("nan")

    window("warm-up 0-30 s", 0.0, 30.0)
    for i, event in enumerate(events):
        window(f"20 s after docking {i + 1}", event, event + 20.0)
    window("last 50 s", t[-1] - 50.0, t[-1] + 1.0)
    return rms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    print("excitation RMS (N m, all axes), median [worst] over seeds")
    for env_id in ("FlexibleSpacecraft-v1", "FlexibleSpacecraftDocking-v1"):
        rows = []
        for seed in range(args.seeds):
            env = gym.make(env_id, task="slew")
            traj = run_episode(env, AdaptiveLQG(env.unwrapped), seed=seed)
            rows.append(windows(traj, env.unwrapped.scenario.event_times()))
        print(env_id)
        for name in rows[0]:
            values = np.array([r[name] for r in rows])
            print(f"  {name:<26}{np.median(values):8.3f} [{values.max():.3f}]")


if __name__ == "__main__":
    main()
