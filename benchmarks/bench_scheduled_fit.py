"""The drive-scheduled physical fit: what one fit of the warm-up's record costs.

Flies the adaptive LQG on the drive-scheduled identifier
(``controllers.scheduled_identifier``) through its 30 s
warm-up on paddle rotation, captures the record the identifier fits, then
times, on that record:

* one whole fit (``identifiers.fit_scheduled_model`` with the identifier's
  settings: four equation-error starts refined, the best continued), beside
  the record's own length (how many times faster than real time);
* one simulation of the record (what every residual and every Jacobian column
  of the fit costs): the stacked, compiled :func:`simulate_scheduled` beside a
  plain per-block reference (one exponential per block, the recursion in
  Python), measured in the same run, and their largest difference;
* one whole closed-loop episode (250 s, the warm-up's fit and the accumulating
  refits at 60, 120 and 240 s) with the refits refining every equation-error
  start (``refit_restarts=True``) beside the default (the held model alone),
  their wall times, ratio and common costs from 100 s (skip with ``--no-episode``).

Usage: ``python benchmarks/bench_scheduled_fit.py [--seed 0] [--snr-db 40] [--repeats 3]
[--no-episode]``
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import identifiers.physical.scheduled_identifier as scheduled_module
from controllers import AdaptiveLQG, LQRWeights, episode_metrics, run_episode, scheduled_identifier
from identifiers.physical.scheduled_simulation import segments, simulate_scheduled
from spacecraft_lab.control import env_id, env_kwargs_for


def _loop(snr_db: float | None, **options) -> tuple[gym.Env, AdaptiveLQG]:
    """Paddle rotation (slew) and the adaptive LQG on the scheduled identifier, built
    with ``options``."""
    env = gym.make(env_id("paddle_rotation"),
                   **env_kwargs_for("paddle_rotation", task="slew", snr_db=snr_db))
    return env, AdaptiveLQG(env, weights=LQRWeights(),
                            identifier=scheduled_identifier(env, **options))


def _record(seed: int, snr_db: float | None) -> tuple[tuple, dict]:
    """The arguments of the identifier's fit call at the end of its warm-up."""
    env, ctrl = _loop(snr_db)
    captured: list = []
    real_fit = scheduled_module.fit_scheduled_model

    def capture(*args, **kwargs):
        captured.append((args, kwargs))
        return real_fit(*args, **kwargs)

    scheduled_module.fit_scheduled_model = capture
    try:
        obs, info = env.reset(seed=seed)
        ctrl.reset(seed)
        while not captured:
            obs, _, _, _, info = env.step(ctrl.act(obs, info))
    finally:
        scheduled_module.fit_scheduled_model = real_fit
    return captured[0]


def _reference(model, u, angle, dt, x0):
    """Per block: one exponential, then the recursion sample by sample in Python."""
    states = np.empty((u.shape[0], model.order))
    x = x0.copy()
    for s0, s1 in segments(angle):
        ad, bd = model.zoh(0.5 * (angle[s0] + angle[s1 - 1]), dt)
        for t in range(s0, s1):
            states[t] = x
            x = ad @ x + bd @ u[t]
    return states


def _episode(seed: int, snr_db: float | None, **options) -> tuple[float, float]:
    """Wall time (s) and common cost from 100 s of one closed-loop episode."""
    env, ctrl = _loop(snr_db, **options)
    start = time.perf_counter()
    traj = run_episode(env, ctrl, seed=seed)
    seconds = time.perf_counter() - start
    cost = episode_metrics(traj, env.unwrapped.model)["cost_after_100s"]
    env.close()
    return seconds, cost


def _best_of(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--snr-db", type=float, default=40.0,
                        help="measurement SNR per channel, dB (negative: noise-free)")
    parser.add_argument("--repeats", type=int, default=3, help="fits timed (best kept)")
    parser.add_argument("--no-episode", action="store_true",
                        help="skip the closed-loop episodes (about a minute)")
    args = parser.parse_args()
    snr = None if args.snr_db < 0 else args.snr_db
    fit_args, fit_kwargs = _record(args.seed, snr)
    u, _, angle, dt = fit_args[:4]
    fit = scheduled_module.fit_scheduled_model(*fit_args, **fit_kwargs)   # compiles
    seconds = _best_of(lambda: scheduled_module.fit_scheduled_model(*fit_args,
                                                                         **fit_kwargs),
                       args.repeats)
    record_s = u.shape[0] * dt
    print(f"paddle rotation, seed {args.seed}, {args.snr_db:g} dB: a {record_s:.0f} s record "
          f"({len(segments(angle))} blocks of 0.25 deg)")
    print(f"one fit: {seconds:.2f} s (best of {args.repeats}), {record_s / seconds:.1f}x "
          f"real time; cost / noise floor {fit.cost / fit.noise_floor:.3f}")
    x0 = fit.initial_state
    fast = _best_of(lambda: simulate_scheduled(fit.model, u, angle, dt, x0), 20)
    slow = _best_of(lambda: _reference(fit.model, u, angle, dt, x0), 5)
    diff = np.abs(simulate_scheduled(fit.model, u, angle, dt, x0)
                  - _reference(fit.model, u, angle, dt, x0)).max()
    print(f"one simulation: {1e3 * fast:.2f} ms stacked and compiled, {1e3 * slow:.2f} ms per "
          f"block in Python; ratio {fast / slow:.2f}; largest difference {diff:.1e}")
    if args.no_episode:
        return
    every, every_cost = _episode(args.seed, snr, refit_restarts=True)
    held, held_cost = _episode(args.seed, snr)
    print(f"one 250 s episode: {every:.1f} s with every start refined at each refit, "
          f"{held:.1f} s with the held model alone (the default); ratio {held / every:.2f}; "
          f"cost from 100 s {every_cost:.3g} and {held_cost:.3g}")


if __name__ == "__main__":
    main()
