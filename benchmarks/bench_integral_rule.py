"""When should the LQG's attitude integral run? Settle times side by side.

Every model-based design here shares :class:`controllers.lqg.LQGLaw`, whose
attitude integral (LQI) runs only while every attitude error is within
:data:`controllers.lqg.INTEGRAL_BAND`; ``settle_s`` makes it wait until the
errors have stayed there that long, so the tail of a transient (a slew's
settling, the adaptive loop's warm-up) does not charge an integral meant for a
constant disturbance. This flies the oracle LQG (the ceiling every design is
judged against), the robust fixed design and, with ``--designs``, the adaptive
LQG (whose integral also waits out its warm-up) with several settle times, on
the slew and regulation tasks of paddle rotation and docking, with no
disturbance torque and with a constant one (``--disturbance``, N m per axis:
the case the integral is for), and prints the common cost from 100 s as a
paired-seed ratio to the same design with ``settle_s = 0`` (the integral as
published): median [best, worst] over seeds, the median cost and its
attitude share, and the median steady attitude offset over the last 50 s
(deg, all axes: what the integral is there to remove).

Usage: ``python benchmarks/bench_integral_rule.py [--seeds 6] [--settle 0 20 50 100]
[--disturbance 0.01] [--designs oracle robust] [--workers 2]`` (about 5 minutes on 2
cores; ``--designs adaptive --settle 0 50 --seeds 10`` about 10 minutes).
"""

from __future__ import annotations

import argparse
from functools import partial

import gymnasium as gym
import numpy as np

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import AdaptiveLQG, LQRWeights, OracleLQG, RobustLQG, compare, set_integral_settle
from spacecraft_env import DEFAULT_SNR_DB, env_id
from spacecraft_lab.control import env_kwargs_for

#: The designs that can be compared, by their ``--designs`` name: (row name, class).
DESIGNS = {"oracle": ("oracle LQG", OracleLQG), "robust": ("robust LQG", RobustLQG),
           "adaptive": ("adaptive LQG", AdaptiveLQG)}

#: (scenario, task) pairs flown.
CONDITIONS = (("paddle_rotation", "slew"), ("paddle_rotation", "regulation"),
              ("docking", "slew"), ("docking", "regulation"))


def settled(env: gym.Env, design: type, settle_s: float):
    """``design`` on ``env`` with its integral waiting ``settle_s`` in the band."""
    # the adaptive LQG's robust fallback has its own law: both wait the same time
    return set_integral_settle(design(env, weights=LQRWeights()), settle_s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--settle", type=float, nargs="+", default=[0.0, 20.0, 50.0, 100.0],
                        help="settle times to compare, s (the first is the reference)")
    parser.add_argument("--disturbance", type=float, default=0.01,
                        help="constant disturbance torque per axis of the second pass, N m")
    parser.add_argument("--designs", nargs="+", choices=sorted(DESIGNS),
                        default=["oracle", "robust"], help="designs to fly")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    designs = dict(DESIGNS[key] for key in args.designs)
    print(f"{'condition':44s} {'design, settle':24s} {'/ settle ' + str(args.settle[0]):>12s}"
          f" {'[best, worst]':>15s} {'cost':>9s} {'att share':>9s} {'offset deg':>10s}")
    for disturbance in (0.0, args.disturbance):
        for scenario, task in CONDITIONS:
            kwargs = {**env_kwargs_for(scenario, task=task, snr_db=DEFAULT_SNR_DB),
                      "disturbance_torque": disturbance}
            rows = {f"{name}, {settle:g} s": partial(settled, design=design, settle_s=settle)
                    for name, design in designs.items() for settle in args.settle}
            table, trajectories = compare(rows, partial(gym.make, env_id(scenario), **kwargs),
                                          list(range(args.seeds)), progress=False,
                                          workers=args.workers)
            condition = f"{scenario} {task}, disturbance {disturbance:g} N m"
            for name in designs:
                reference = np.array([m["cost_after_100s"] for m in
                                      table[f"{name}, {args.settle[0]:g} s"]["per_seed"]])
                for settle in args.settle:
                    row = f"{name}, {settle:g} s"
                    seeds = table[row]["per_seed"]
                    cost = np.array([m["cost_after_100s"] for m in seeds])
                    ratio = cost / reference
                    share = np.median([m["cost_attitude_after_100s"] / m["cost_after_100s"]
                                       for m in seeds])
                    offsets = []
                    for traj in trajectories[row]:
                        last = int(np.count_nonzero(traj.time > traj.time[-1] - 50.0))
                        error = traj.states[-last:, :3] - traj.reference[-last:]
                        offsets.append(np.rad2deg(np.abs(error.mean(axis=0)).max()))
                    print(f"{condition:44s} {row:24s} {np.median(ratio):12.2f} "
                          f"[{ratio.min():.2f}, {ratio.max():.2f}]".ljust(102)
                          + f"{np.median(cost):9.3g} {share:9.2f} {np.median(offsets):10.4f}",
                          flush=True)


if __name__ == "__main__":
    main()
