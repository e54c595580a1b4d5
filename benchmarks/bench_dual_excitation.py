"""Does the adaptive LQG excite only when information is needed? (dual control)

Runs :class:`controllers.AdaptiveLQG` on the slew task and prints the RMS of
its designed excitation torque (N m, all axes) in windows: the identifier's
warm-up (0-30 s), the 20 s after each docking, and the last 50 s, on the
constant plant (where, once the gain is known, there should be none) and on
docking (where a change should bring it back). The budget after warm-up is
``AdaptiveLQG.excitation_budget`` (0.1 N m per axis); the bar for the last
50 s of the constant plant is 0.01 N m. Median [worst] over seeds.

It then flies the constant plant for ``--long`` seconds (default 1000) and
prints, side by side, the adaptive LQG's and the oracle LQG's common cost from
100 s and torque RMS over the last 100 s (all axes, N m), with the bars: cost at
most 1.2x the oracle's, torque RMS at most 1.5x the oracle's + 0.005 N m.

``--identifier scheduled`` (the default since 2026-11-28) flies the adaptive LQG's
default identifier, the drive-scheduled physical fit
(``controllers.scheduled_identifier``); ``--identifier fast`` the structured
recursive identifier (``controllers.fast_identifier``, the default before).

Usage: ``python benchmarks/bench_dual_excitation.py [--seeds 3] [--long 1000]
[--identifier scheduled|fast]``
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import (
    AdaptiveLQG,
    OracleLQG,
    episode_metrics,
    fast_identifier,
    run_episode,
    scheduled_identifier,
)


def adaptive(env, identifier: str) -> AdaptiveLQG:
    """The adaptive LQG on ``env`` with the scheduled or the fast identifier."""
    make = scheduled_identifier if identifier == "scheduled" else fast_identifier
    return AdaptiveLQG(env.unwrapped, identifier=make(env))


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
    parser.add_argument("--long", type=float, default=1000.0,
                        help="length of the constant-plant run, s (0: skip it)")
    parser.add_argument("--identifier", choices=("scheduled", "fast"), default="scheduled")
    args = parser.parse_args()
    print("excitation RMS (N m, all axes), median [worst] over seeds")
    for env_id in ("FlexibleSpacecraft-v2", "FlexibleSpacecraftDocking-v2"):
        rows = []
        for seed in range(args.seeds):
            env = gym.make(env_id, task="slew")
            traj = run_episode(env, adaptive(env, args.identifier), seed=seed)
            rows.append(windows(traj, env.unwrapped.scenario.event_times()))
        print(env_id)
        for name in rows[0]:
            values = np.array([r[name] for r in rows])
            print(f"  {name:<26}{np.median(values):8.3f} [{values.max():.3f}]")
    if args.long > 0:
        long_run(args.seeds, args.long, args.identifier)


def long_run(seeds: int, seconds: float, identifier: str = "scheduled") -> None:
    """The constant plant over ``seconds``: cost and late torque, adaptive beside oracle."""
    steps = round(seconds / 0.1)
    print(f"constant plant over {seconds:.0f} s: adaptive / oracle LQG, paired seeds")
    print("  seed  cost ratio  torque RMS last 100 s (N m): adaptive  oracle  bar")
    ratios, torques = [], []
    for seed in range(seeds):
        env = gym.make("FlexibleSpacecraft-v2", task="slew", max_episode_steps=steps)
        out = {}
        for name, make in (("adaptive", lambda e: adaptive(e, identifier)),
                           ("oracle", lambda e: OracleLQG(e.unwrapped))):
            traj = run_episode(env, make(env), seed=seed)
            late = traj.time > traj.time[-1] - 100.0
            out[name] = (episode_metrics(traj, env.unwrapped.model)["cost_after_100s"],
                         float(np.sqrt(np.mean(np.sum(traj.torque[late] ** 2, axis=1)))))
        ratio = out["adaptive"][0] / out["oracle"][0]
        bar = 1.5 * out["oracle"][1] + 0.005
        ratios.append(ratio)
        torques.append(out["adaptive"][1] / bar)
        print(f"  {seed:4d}  {ratio:10.2f}  {out['adaptive'][1]:34.4f}  {out['oracle'][1]:6.4f}"
              f"  {bar:.4f}")
    print(f"  median cost ratio {np.median(ratios):.2f} (bar 1.2), worst {max(ratios):.2f}; "
          f"torque / its bar median {np.median(torques):.2f} (bar 1), worst {max(torques):.2f}")


if __name__ == "__main__":
    main()
