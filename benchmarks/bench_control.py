"""One adaptive control step: identifier update + re-design + act.

Runs the adaptive LQG in closed loop (paddle rotation by default, seed 0) and
times each ``act`` call (which feeds the identifier, designs the gain on its
model, judges it and computes the torque); every fifth step it also times a
from-scratch ``scipy.linalg.solve_discrete_are`` on that step's identified
model, so that both are measured under the same load.

Printed: the adaptive step's median and 90th percentile beside the
from-scratch Riccati solve, and their ratio.

The loop flies the adaptive LQG's default identifier, the drive-scheduled
physical fit (``controllers.scheduled_identifier``; ``--identifier scheduled``,
the default since 2026-11-28): its fits (the warm-up's, then the refits on the
growing record: steps longer than 0.5 s) are printed apart with their times,
the steps between them are timed as usual, and the refits counted: kept, kept
out by the guard (less certain than the held fit), skipped by the screen
(``screen_refits``: predicted so at the held parameters, not fitted).
``--identifier fast`` flies the structured recursive identifier
(``controllers.fast_identifier``, the default before), every step timed.

On paddle rotation (the default) the identified model moves with the paddles
(re-discretized per 0.5 deg of drive travel, every 14 samples): each new model
is solved exactly once (structure-preserving doubling), and the steps in
between get that design and its verdict back (printed: the designs handed back
and solved). ``--iterations 4`` flies the former design instead, four
warm-started Riccati iterations every step. Step times on a shared two-core
machine drift by up to 1.7x between runs; the ratio to the from-scratch DARE,
measured in the same run, does not.

Usage: ``python benchmarks/bench_control.py [--steps 1500] [--identifier scheduled|fast]
[--scenario paddle_rotation|docking|constant|solar_rotation] [--iterations N]``
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
from scipy.linalg import solve_discrete_are

from controllers import AdaptiveLQG, fast_identifier, scheduled_identifier
from controllers.lqg import augment_integral
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import env_id

#: A step longer than this (s) is one of the scheduled identifier's fits.
FIT_STEP_S = 0.5

#: Every this many steps, a from-scratch DARE on the step's model is timed.
DARE_EVERY = 5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--identifier", choices=("scheduled", "fast"), default="scheduled")
    parser.add_argument("--scenario", choices=("paddle_rotation", "docking", "constant",
                                               "solar_rotation"), default="paddle_rotation")
    parser.add_argument("--iterations", type=int, default=None,
                        help="warm-started Riccati iterations per step (default: each new "
                             "model solved exactly)")
    args = parser.parse_args()
    env = gym.make(env_id(args.scenario))
    make = scheduled_identifier if args.identifier == "scheduled" else fast_identifier
    ctrl = AdaptiveLQG(env.unwrapped, identifier=make(env), iterations=args.iterations)
    obs, info = env.reset(seed=0)
    ctrl.reset(0)
    step_times, dare, order = [], [], env.unwrapped.model.n
    law = ctrl.law
    att = ctrl.measured_layout.indices("attitude")
    with single_threaded_blas:
        for k in range(args.steps):
            start = time.perf_counter()
            action = ctrl.act(obs, info)
            step_times.append(time.perf_counter() - start)
            model = ctrl.identifier.model
            if model is not None and k % DARE_EVERY == 0:
                # the from-scratch reference, timed beside the steps it is compared with
                # (a shared machine's speed drifts by up to 1.7x within minutes)
                order = model.A.shape[0]
                q = law.weight_matrix(model.C)
                a, b = augment_integral(model.A, model.B, model.C[att], law.dt)
                start = time.perf_counter()
                try:
                    solve_discrete_are(a, b, q, law.r)
                except (np.linalg.LinAlgError, ValueError):
                    pass
                dare.append(time.perf_counter() - start)
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                obs, info = env.reset()
        warm = ctrl.identifier.warmup
        after = np.array(step_times[warm:])
        # the scheduled identifier's fits (the warm-up's, then the refits as its record
        # grows) are reported one by one, not mixed into the steps: a step of more than
        # FIT_STEP_S is a fit
        fits = (np.flatnonzero(after > FIT_STEP_S) if args.identifier == "scheduled"
                else np.zeros(0, dtype=int))
        adaptive = np.delete(after, fits)
    dare = np.array(dare)
    med = np.median(adaptive) * 1e3
    design = ("exact design per model" if args.iterations is None
              else f"{args.iterations} warm-started Riccati iterations")
    print(f"adaptive LQG step (identifier + {design} + act), {args.identifier} "
          f"identifier, model order {order}: median {med:.3f} ms, p90 "
          f"{np.percentile(adaptive, 90) * 1e3:.3f} ms -> {100 / med:.0f}x faster than real "
          f"time at dt = 0.1 s")
    print(f"scipy solve_discrete_are from scratch on the same models, every {DARE_EVERY}th "
          f"step: median {np.median(dare) * 1e3:.3f} ms (DARE alone, without the identifier)")
    print(f"adaptive step / from-scratch DARE: {med / (np.median(dare) * 1e3):.2f}")
    tracker = ctrl.law.tracker
    print(f"mean step {np.mean(adaptive) * 1e3:.3f} ms; designs: {tracker.n_reused} handed "
          f"back for an unchanged model, {tracker.n_exact} solved exactly"
          + ("" if args.iterations is None else ", the rest warm-started iterations"))
    if fits.size:
        dt = env.unwrapped.model.dt
        print("the fits, each one step: " + ", ".join(
            f"{after[i]:.1f} s at t = {(warm + i) * dt:.0f} s" for i in fits)
            + f"; {after[fits].sum():.1f} s in all")
        ident = ctrl.identifier
        print(f"accumulating refits: {ident.n_refits} kept, {ident.n_refits_kept_out} kept "
              f"out by the guard, {ident.n_refits_skipped} skipped by the screen (judged "
              f"at the held parameters, not fitted)")


if __name__ == "__main__":
    main()
