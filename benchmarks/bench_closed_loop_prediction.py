"""How well the identifier predicts inside the adaptive loop, beside persistence.

Runs the adaptive LQG (default settings) on a scenario, records what its
identifier was fed (applied torque, measured outputs), refits the default
identifier on that record and on an open-loop record of the same plant
(1 N m identification inputs), and prints, beside the ceiling (the true
model run from the true state on the closed-loop record), the h-step-ahead prediction mean
square error from the identifier's own state (``identifiers.h_step_predictions``)
divided by persistence's (``y_{k+h} = y_k``), after t = 100 s, for attitude
and rate at 1, 3 and 10 s. Below 1 the model beats persistence.

It also prints the applied torque's RMS after t = 100 s (what the loop
gives the identifier to learn from) and the identified rigid-body gain's
error against the true ``J(t)^-1`` (median over t >= 100 s, every 2.5 s),
beside the error of the nominal design inertia (paddles at 0 deg, nothing
docked; the trivial baseline a fixed design flies with).

This is the diagnosis behind the adaptive loop's fallback share: the
acceptance test asks for a 1 s rate prediction MSE at most 0.5x
persistence's (``GainAcceptance.max_prediction_error``).

With ``--fly`` it also flies the identified gains: the adaptive LQG with
the prediction-agreement test switched off (the identifier built with the
``--option`` settings), so a gain designed on the identified model flies
whenever it passes the physical tests (stiffness, damping, stability, the
loop's disk margin on the model). It prints the attitude RMS after
t = 100 s beside the robust fixed design (the fallback), the default
adaptive LQG and the output-feedback oracle LQG, with the share of steps
the fallback flew and the rejections by reason.

``--loop previous`` runs the loop as it was before the adaptive LQG read its
rigid states from the sensors: the identifier's own Kalman state, the
open-loop identifier settings and the agreement threshold 0.5 (the
diagnosis in docs/results/control.md was printed with it).

Usage: ``python benchmarks/bench_closed_loop_prediction.py [--scenario NAME] [--seeds 3] [--fly]
[--loop current|previous]``
"""

from __future__ import annotations

import argparse
import ast

import gymnasium as gym
import numpy as np

from controllers import (
    AdaptiveLQG,
    GainAcceptance,
    OracleLQG,
    RobustLQG,
    episode_metrics,
    run_episode,
)
from identifiers import (
    CLOSED_LOOP_SETTINGS,
    add_measurement_noise,
    default_identifier,
    h_step_predictions,
    identification_inputs,
    persistence_predictions,
    relative_gain_error,
    rigid_body_gain,
)
from identifiers.core.modal_basis import Resonator
from spacecraft_env import DEFAULT_SNR_DB, env_id
from spacecraft_lab.control import env_kwargs_for
from spacecraft_lab.identification import truth_sequence

HORIZONS = (10, 30, 100)
START = 1000          # t = 100 s
GAIN_EVERY = 25       # samples between rigid-gain checks (2.5 s)
#: The loop before the rigid states were read from the sensors (its identifier
#: had the open-loop settings).
PREVIOUS_LOOP = {"rigid_state": "filter", "max_prediction_error": 0.5}


def adaptive(env, loop: str, options: dict | None = None,
             max_prediction_error: float | None = None) -> AdaptiveLQG:
    """The adaptive LQG of ``loop`` ("current" or "previous"), its identifier
    built with ``options`` on top of the loop's settings."""
    base = env.unwrapped
    previous = loop == "previous"
    settings = {} if previous else dict(CLOSED_LOOP_SETTINGS)
    settings.update(options or {})
    probe = AdaptiveLQG(base)
    ident = default_identifier(probe.measured_layout, n=base.model.n, dt=base.model.dt,
                               **settings)
    if max_prediction_error is None:
        max_prediction_error = (PREVIOUS_LOOP["max_prediction_error"] if previous
                                else GainAcceptance().max_prediction_error)
    return AdaptiveLQG(base, identifier=ident,
                       acceptance=GainAcceptance(max_prediction_error=max_prediction_error),
                       rigid_state=PREVIOUS_LOOP["rigid_state"] if previous else "measured")


def mse_ratios(seq, u: np.ndarray, y: np.ndarray, layout) -> dict[tuple[str, int], float]:
    """h-step MSE of a model sequence's predictions over persistence's, per group and h."""
    pred = h_step_predictions(seq, u, horizons=HORIZONS)
    pers = persistence_predictions(y, horizons=HORIZONS)
    out = {}
    for group in ("attitude", "rate"):
        rows = layout.indices(group)
        for h in HORIZONS:
            e = pred[h][START:, rows] - y[START:, rows]
            d = pers[h][START:, rows] - y[START:, rows]
            out[group, h] = float(np.nanmean(e**2) / np.nanmean(d**2))
    return out


def gain_error(gain_at, truth, n_samples: int) -> float:
    """Median relative error of ``gain_at(k)`` against the true ``J^-1`` after t = 100 s."""
    return float(np.median([
        relative_gain_error(gain_at(k), np.linalg.inv(truth.inertia(k * truth.dt)))
        for k in range(START, n_samples, GAIN_EVERY)]))


def identified_gain_error(seq, truth, rate_rows) -> float:
    """:func:`gain_error` of the rigid-body gain of a model sequence (inf where invalid)."""
    def gain_at(k):
        return rigid_body_gain(seq[k], rate_rows) if seq.valid[k] else np.full((3, 3), np.nan)
    return gain_error(gain_at, truth, len(seq))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paddle_rotation")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--snr-db", type=float, default=DEFAULT_SNR_DB,
                        help="sensor SNR, dB (a negative value: noise-free sensors)")
    parser.add_argument("--excitation", type=float, default=None,
                        help="steady excitation budget after warm-up, N m per axis "
                             "(default: the adaptive LQG's 0.1)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="identifier keyword for the refits (Python literal), e.g. "
                             "detect_changes=False; repeatable")
    parser.add_argument("--fly", action="store_true",
                        help="also fly the identified gains without the agreement test")
    parser.add_argument("--loop", choices=("current", "previous"), default="current",
                        help="the adaptive loop whose record is refitted (see the docstring)")
    args = parser.parse_args()
    options = {k: ast.literal_eval(v) for k, v in (o.split("=", 1) for o in args.option)}
    if options.pop("true_modes", False):     # the truth's modes as the prior, kept
        model0 = gym.make(env_id(args.scenario)).unwrapped.model
        freq, zeta = model0.modal(0.0)
        options.update(prior=[Resonator(f, z) for f, z in zip(freq, zeta, strict=True)],
                       rediscover=None)
    snr = None if args.snr_db < 0 else args.snr_db
    closed, opened, ceiling = [], [], []
    torque_rms, gains = [], []
    for seed in range(args.seeds):
        env = gym.make(env_id(args.scenario), **env_kwargs_for(args.scenario, snr_db=snr))
        ctrl = adaptive(env, args.loop)
        if args.excitation is not None:
            ctrl.excitation.amplitude = args.excitation
        traj = run_episode(env, ctrl, seed=seed)
        layout = ctrl.measured_layout
        truth = env.unwrapped.model
        rate = layout.indices("rate")
        # the identifier got (u_k, y_k): y_k observed before action k (observations[0]: reset)
        y = traj.observations[:-1][:, ctrl._meas_obs].astype(float)
        u = traj.torque
        torque_rms.append(np.sqrt(np.mean(u[START:] ** 2, axis=0)))
        seq = default_identifier(layout, n=22, dt=0.1, **options).fit(u, y)
        closed.append(mse_ratios(seq, u, y, layout))
        # the ceiling: the true model of each step run from the true state, same record
        ceiling.append(mse_ratios(truth_sequence(truth, traj.states), u, y, layout))
        rng = np.random.default_rng(seed)
        uo = identification_inputs(u.shape[0], rng)
        yo = add_measurement_noise(truth.simulate(uo)[1], snr, rng)
        seq_open = default_identifier(layout, n=22, dt=0.1, **options).fit(uo, yo)
        opened.append(mse_ratios(seq_open, uo, yo, layout))
        nominal = np.linalg.inv(truth.nominal(0.0).inertia(0.0))
        gains.append((identified_gain_error(seq, truth, rate),
                      identified_gain_error(seq_open, truth, rate),
                      gain_error(lambda k, g=nominal: g, truth, u.shape[0])))
    print(f"{args.scenario}, SNR {snr} dB, steady excitation "
          f"{args.excitation if args.excitation is not None else 0.1} N m: h-step prediction "
          f"MSE / persistence MSE after t = 100 s, median over {args.seeds} seeds "
          f"(below 1: the model beats persistence)")
    print(f"{'record':<34}" + "".join(f"{g[:4]} {h / 10:g}s".rjust(12)
                                      for g in ("attitude", "rate") for h in HORIZONS))
    for name, rows in (("adaptive LQG loop (its own data)", closed),
                       ("  same record, true model (ceiling)", ceiling),
                       ("open loop, 1 N m identification", opened)):
        cells = "".join(f"{np.median([r[g, h] for r in rows]):>12.2f}"
                        for g in ("attitude", "rate") for h in HORIZONS)
        print(f"{name:<34}{cells}")
    print(f"applied torque RMS after t = 100 s, N m per axis (median over seeds): "
          f"{np.round(np.median(torque_rms, axis=0), 3).tolist()}")
    g = np.median(gains, axis=0)
    print(f"rigid-body gain error |G - J^-1| / |J^-1| after t = 100 s (median): identified "
          f"in the loop {g[0]:.3f}, identified open loop {g[1]:.3f}, nominal design inertia "
          f"(trivial baseline) {g[2]:.3f}")
    if args.fly:
        fly(args.scenario, args.seeds, snr, options, args.loop)


def fly(scenario: str, seeds: int, snr: float | None, options: dict, loop: str) -> None:
    """Attitude RMS after t = 100 s with the identified gains flown (see the docstring)."""
    cases = {"robust LQG (the fallback)": lambda env: RobustLQG(env.unwrapped),
             f"adaptive LQG ({loop} loop)": lambda env: adaptive(env, loop),
             "identified gains flown": lambda env: adaptive(env, loop, options, np.inf),
             "oracle LQG": lambda env: OracleLQG(env.unwrapped)}
    print(f"\nflying the identified gains ({scenario}, {loop} loop, identifier options "
          f"{options or 'none'}): "
          f"attitude RMS after t = 100 s, median [min, max] over {seeds} seeds")
    for name, make in cases.items():
        rms, share, rejected = [], [], {}
        for seed in range(seeds):
            env = gym.make(env_id(scenario), **env_kwargs_for(scenario, snr_db=snr))
            ctrl = make(env)
            traj = run_episode(env, ctrl, seed=seed)
            rms.append(episode_metrics(traj, env.unwrapped.model)["attitude_rms_after_100s_deg"])
            stats = traj.controller_stats or {}
            if "fallback_steps" in stats:
                share.append(stats["fallback_steps"] / stats["steps"])
                for reason, count in stats["rejected_by"].items():
                    rejected[reason] = rejected.get(reason, 0) + count
        extra = (f"   fallback flew {np.median(share):.0%} of steps; rejections {rejected}"
                 if share else "")
        print(f"  {name:<30}{np.median(rms):.4f} [{min(rms):.4f}, {max(rms):.4f}] deg{extra}")


if __name__ == "__main__":
    main()
