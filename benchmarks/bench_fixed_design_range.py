"""Where the fixed design fails: its true closed loop's spectral radius against the paddle angle.

The fixed LQG is designed once at the nominal configuration (paddles at
0 deg). For each paddle angle the true plant is frozen there and the loop of
that fixed design (gain, steady-state Kalman filter, attitude integral) is
closed around it (:meth:`controllers.FixedLQG.closed_loop_radius`); a radius
above 1 means the loop grows there, however slowly. Printed: the radius every
``--step`` degrees and the intervals where it exceeds 1, with the growth per
100 s at the worst angle.

Usage: ``python benchmarks/bench_fixed_design_range.py [--step 1]``
"""

from __future__ import annotations

import argparse

import numpy as np

from controllers import FixedLQG
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import ConstantScenario, FlexibleSpacecraftEnv


def radii(step: float) -> tuple[np.ndarray, np.ndarray]:
    angles = np.arange(0.0, 360.0, step)
    out = []
    for angle in angles:
        env = FlexibleSpacecraftEnv(ConstantScenario(paddle_angle_deg=float(angle)))
        out.append(FixedLQG(env).closed_loop_radius(env.model, 0.0))
    return angles, np.array(out)


def unstable_intervals(angles: np.ndarray, radius: np.ndarray) -> list[tuple[float, float]]:
    bad = radius > 1.0
    intervals, start = [], None
    for angle, flag in zip(angles, bad, strict=True):
        if flag and start is None:
            start = angle
        if not flag and start is not None:
            intervals.append((start, angle))
            start = None
    if start is not None:
        intervals.append((start, 360.0))
    return intervals


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--step", type=float, default=1.0)
    args = parser.parse_args()
    with single_threaded_blas:
        angles, radius = radii(args.step)
    dt = 0.1
    for lo, hi in unstable_intervals(angles, radius):
        print(f"unstable from {lo:g} deg to below {hi:g} deg")
    worst = int(np.argmax(radius))
    print(f"worst: {angles[worst]:g} deg, radius {radius[worst]:.5f}, "
          f"{radius[worst] ** (100 / dt):.2f}x per 100 s")
    for angle in (0, 60, 85, 88, 92, 96, 100, 150, 200, 236, 240, 300):
        i = int(np.argmin(np.abs(angles - angle)))
        print(f"  {angles[i]:5.1f} deg: radius {radius[i]:.5f} "
              f"({radius[i] ** (100 / dt):.2f}x per 100 s)")


if __name__ == "__main__":
    main()
