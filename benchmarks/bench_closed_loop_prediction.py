"""How well the identifier predicts inside the adaptive loop, beside persistence.

Runs the adaptive LQG (default settings) on a scenario, records what its
identifier was fed (applied torque, measured outputs), refits the default
identifier on that record and on an open-loop record of the same plant
(1 N m identification inputs), and prints, beside the ceiling (the true
model run from the true state on the closed-loop record), the h-step-ahead prediction mean
square error from the identifier's own state (``identifiers.h_step_predictions``)
divided by persistence's (``y_{k+h} = y_k``), after t = 100 s, for attitude
and rate at 1, 3 and 10 s. Below 1 the model beats persistence.

This is the diagnosis behind the adaptive loop's fallback share: the
acceptance test asks for a 1 s rate prediction MSE at most 0.5x
persistence's (``GainAcceptance.max_prediction_error``).

Usage: ``python benchmarks/bench_closed_loop_prediction.py [--scenario NAME] [--seeds 3]``
"""

from __future__ import annotations

import argparse
import ast

import gymnasium as gym
import numpy as np

from controllers import AdaptiveLQG, run_episode
from identifiers import (
    add_measurement_noise,
    default_identifier,
    h_step_predictions,
    identification_inputs,
    persistence_predictions,
)
from identifiers.modal_basis import Resonator
from spacecraft_env import env_id
from spacecraft_lab.control import env_kwargs_for
from spacecraft_lab.identification import truth_sequence

HORIZONS = (10, 30, 100)
START = 1000          # t = 100 s


def mse_ratios(ident, u: np.ndarray, y: np.ndarray, layout) -> dict[tuple[str, int], float]:
    """h-step MSE of the identifier's predictions (or of a given model sequence)
    over persistence's, per group and h."""
    seq = ident.fit(u, y) if hasattr(ident, "fit") else ident
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paddle_rotation")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--snr-db", type=float, default=40.0,
                        help="sensor SNR, dB (a negative value: noise-free sensors)")
    parser.add_argument("--excitation", type=float, default=None,
                        help="steady excitation budget after warm-up, N m per axis "
                             "(default: the adaptive LQG's 0.1)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="identifier keyword for the refits (Python literal), e.g. "
                             "detect_changes=False; repeatable")
    args = parser.parse_args()
    options = {k: ast.literal_eval(v) for k, v in (o.split("=", 1) for o in args.option)}
    if options.pop("true_modes", False):     # the truth's modes as the prior, kept
        model0 = gym.make(env_id(args.scenario)).unwrapped.model
        freq, zeta = model0.modal(0.0)
        options.update(prior=[Resonator(f, z) for f, z in zip(freq, zeta, strict=True)],
                       rediscover=None)
    snr = None if args.snr_db < 0 else args.snr_db
    closed, opened, ceiling = [], [], []
    for seed in range(args.seeds):
        env = gym.make(env_id(args.scenario), **env_kwargs_for(args.scenario, snr_db=snr))
        ctrl = AdaptiveLQG(env.unwrapped)
        if args.excitation is not None:
            ctrl.excitation.amplitude = args.excitation
        traj = run_episode(env, ctrl, seed=seed)
        layout = ctrl.measured_layout
        # the identifier got (u_k, y_k): y_k observed before action k (observations[0]: reset)
        y = traj.observations[:-1][:, ctrl._meas_obs].astype(float)
        u = traj.torque
        closed.append(mse_ratios(default_identifier(layout, n=22, dt=0.1, **options), u, y,
                                 layout))
        # the ceiling: the true model of each step run from the true state, same record
        ceiling.append(mse_ratios(truth_sequence(env.unwrapped.model, traj.states),
                                  u, y, layout))
        rng = np.random.default_rng(seed)
        uo = identification_inputs(u.shape[0], rng)
        yo = add_measurement_noise(env.unwrapped.model.simulate(uo)[1], snr, rng)
        opened.append(mse_ratios(default_identifier(layout, n=22, dt=0.1, **options), uo, yo,
                                 layout))
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


if __name__ == "__main__":
    main()
