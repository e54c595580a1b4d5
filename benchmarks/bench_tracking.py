"""Does the default identifier track the plant as it changes? Env-driven records.

Each record is the public environment (its sensor noise fixed in physical
units: ``snr_db`` of the nominal levels, not of the signal) driven open-loop
by random-phase multisine torques of a given RMS. For every scenario and
condition, printed side by side, median [worst] over seeds:

* 10 s-ahead prediction VAF (%) per output group from t = 150 s, for
  persistence (the trivial baseline), the true model frozen before the
  change with a Kalman filter on it (what an identifier that holds scores)
  and the default identifier (its own state and model at each k);
* the error (%) of the identified pole nearest to the mode that changes most
  (docking: 0.0874 -> 0.0857 -> 0.0844 Hz; rotations: the mode the paddles
  move), from 20 s after each docking and from 100 s in the rotations,
  beside the frozen-before-change model's;
* the rigid-body gain's relative error (%) over the same windows, and the
  share of samples whose truth lies in the identifier's reported 2-sigma (95.45 %) confidence
  region, pooled over seeds (mean of the seeds' shares).

Usage: ``python benchmarks/bench_tracking.py [--seeds 3] [--first-seed 0]
[--scenarios ...] [--conditions 40:1 none:1 ...] [--identifier default|scheduled]
[--hold-through-changes] [--coupling-drift D] [--drift-reference V]
[--rediscover N|none] [--workers N] [--json out.json]``
(a condition is ``SNR:RMS``, SNR in dB of the env's nominal levels or ``none``, RMS in
N m; ``--drift-reference`` sets the default identifier's ``drift_reference``, the noise
level at which its drifts are stated; ``--coupling-drift`` overrides its modal couplings' random
walk, for the ablation in docs/history/identification-log.md; ``--rediscover`` its re-search
period in samples, ``none`` for no re-search after the warm-up's, for the cost ablation in
docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import time
from functools import partial

import numpy as np

from identifiers import (
    KalmanPredictor,
    ModelSequence,
    OnlineIdentifier,
    default_identifier,
    h_step_predictions,
    persistence_predictions,
    prediction_vaf,
    relative_gain_error,
)
from spacecraft_conventions import STANDARD_OUTPUTS, single_threaded_blas
from spacecraft_lab.identification import drive_angles, env_record
from spacecraft_lab.identification import make_identifier as identification_method
from spacecraft_lab.sweeps.backends import map_in_order

#: Index of the tracked mode among the truth's sorted modal frequencies.
TRACKED = {"docking": 1, "paddle_rotation": 3, "solar_rotation": 1}
#: Scored windows (s) of the tracking metrics, and the freezing time of the
#: frozen-before-change model for each window.
WINDOWS = {"docking": [((120.0, 180.0), 99.9), ((200.0, 250.0), 179.9)],
           "paddle_rotation": [((100.0, 250.0), 99.9)],
           "solar_rotation": [((100.0, 250.0), 99.9)]}
GROUPS = ("attitude", "rate", "deflection")


def frozen_sequence(model, u: np.ndarray, y: np.ndarray, snr_db: float | None,
                    freeze_s: list[float]) -> ModelSequence:
    """The true model, frozen at each window's freezing time from then on, with a
    Kalman filter on it: what an identifier that holds its pre-change model scores."""
    n, steps = model.n, len(u)
    level = 1e-6 if snr_db is None else 10 ** (-snr_db / 20)
    r = (STANDARD_OUTPUTS.scales() * level) ** 2
    kf = KalmanPredictor(n, initial_covariance=1e-4)
    a, b, x = np.empty((steps, n, n)), np.empty((steps, n, 3)), np.empty((steps, n))
    for k in range(steps):
        t = k * model.dt
        frozen = [f for f in freeze_s if f <= t]
        d = model.discrete(frozen[-1] if frozen else t)
        kf.update(d.A, d.B, model.C, 0.25 * d.B @ d.B.T, r, u[k], y[k])
        a[k], b[k], x[k] = d.A, d.B, kf.x
    c = np.broadcast_to(model.C, (steps, *model.C.shape))
    return ModelSequence(a, b, c, np.zeros((steps, 10, 3)), np.zeros((steps, n, 10)),
                         np.ones(steps, bool), model.dt, states=x)


def _vaf(pred: np.ndarray, y_clean: np.ndarray, start: int) -> list[float]:
    v = prediction_vaf(y_clean, {100: pred}, start)[100]
    return [float(np.mean(v[STANDARD_OUTPUTS.indices(g)])) for g in GROUPS]


def make_identifier(kind: str, model, **options) -> OnlineIdentifier:
    """The identifier under test: ``"default"`` (:func:`identifiers.default_identifier`,
    which needs no drive angle) or ``"scheduled"`` (the adaptive LQG's default,
    :class:`identifiers.ScheduledPhysicalIdentifier`, given the record's drive angles and
    the appendages' description the environments give it); ``options`` go to it."""
    if kind == "default":
        return default_identifier(**options)
    return identification_method("scheduled-physical", model, **options)


def run(ident: OnlineIdentifier, u: np.ndarray, y: np.ndarray,
        schedule: np.ndarray | None) -> tuple[ModelSequence, dict]:
    """``ident.fit`` over the record in stretches that end at every 10th sample: the
    models after each sample, and the rigid-body gain's estimate after samples 0, 10,
    20, ... (``fit`` keeps models, not bands)."""
    ends = [*range(0, len(u), 10), len(u) - 1]
    parts, bands, first = [], {}, 0
    for last in sorted(set(ends)):
        chunk = slice(first, last + 1)
        parts.append(ident.fit(u[chunk], y[chunk]) if schedule is None
                     else ident.fit(u[chunk], y[chunk], schedule=schedule[chunk]))
        if last % 10 == 0:
            bands[last] = ident.rigid_gain
        first = last + 1
    stack = [np.concatenate([getattr(p, name) for p in parts])
             for name in ("A", "B", "C", "D", "K", "states", "valid")]
    return ModelSequence(*stack[:5], stack[6], parts[-1].dt, parts[-1].consistent_basis,
                         states=stack[5]), bands


def score(scenario: str, seed: int, snr_db: float | None, rms: float,
          identifier: str = "default", **options) -> dict:
    """One record's figures; ``options`` go to the identifier (:func:`make_identifier`)."""
    u, y, y_clean, model = env_record(scenario, seed, snr_db, rms)
    dt = model.dt
    start = round(150.0 / dt)
    schedule = None if identifier == "default" else drive_angles(model, len(u))
    ident = make_identifier(identifier, model, **options)
    tic = time.perf_counter()
    seq, bands = run(ident, u, y, schedule)
    seconds = time.perf_counter() - tic
    windows = WINDOWS[scenario]
    frozen = frozen_sequence(model, u, y, snr_db, [f for _, f in windows])
    mode, mode_frozen, gain, covered = [], [], [], []
    for (lo, hi), freeze in windows:
        f_frozen = model.modal_residues(freeze)[0]
        for t in np.arange(lo, hi, 1.0):
            k = round(t / dt)
            f_true = model.modal_residues(t)[0][TRACKED[scenario]]
            mode_frozen.append(np.min(np.abs(f_frozen / f_true - 1.0)))
            if seq.valid[k]:
                f_id, z_id = seq[k].modal(unique=False)
                ok = (z_id > -0.05) & (z_id < 0.5)
                mode.append(np.min(np.abs(f_id[ok] / f_true - 1.0)) if ok.any() else np.nan)
            band = bands.get(k - k % 10)
            if band is not None:
                g_true = np.linalg.inv(model.inertia(t))
                gain.append(relative_gain_error(band.gain, g_true))
                covered.append(band.covers(g_true, 2.0))
    return {
        "vaf": {"persistence": _vaf(persistence_predictions(y, (100,))[100], y_clean, start),
                "frozen": _vaf(h_step_predictions(frozen, u, (100,))[100], y_clean, start),
                "identifier": _vaf(h_step_predictions(seq, u, (100,))[100], y_clean, start)},
        "mode_error_pct": 100 * float(np.nanmedian(mode)),
        "frozen_mode_error_pct": 100 * float(np.median(mode_frozen)),
        "gain_error_pct": 100 * float(np.median(gain)),
        "coverage": float(np.mean(covered)),
        "change_events": [round(e.time, 1) for e in getattr(ident, "events", [])
                          if e.confirmed is not False],
        "unconfirmed_alarms": [round(e.time, 1) for e in getattr(ident, "events", [])
                               if e.confirmed is False],
        "seconds": seconds,
    }


def _score_seed(scenario: str, snr_db: float | None, rms: float, identifier: str,
                options: dict, seed: int) -> dict:
    """:func:`score` of one seed with single-threaded BLAS (a pool's task)."""
    with single_threaded_blas:
        return score(scenario, seed, snr_db, rms, identifier, **options)


def _cell(values: list[float], worst: str) -> str:
    pick = min if worst == "min" else max
    return f"{np.median(values):.1f} [{pick(values):.1f}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--coupling-drift", type=float, default=None)
    parser.add_argument("--drift-reference", type=float, default=None)
    parser.add_argument("--rediscover", default=None,
                        help="the default identifier's re-search period, samples, or 'none'")
    parser.add_argument("--scenarios", nargs="+", default=list(TRACKED))
    parser.add_argument("--conditions", nargs="+",
                        default=["20:1", "40:1", "60:1", "none:1", "40:0.1"])
    parser.add_argument("--identifier", choices=("default", "scheduled"), default="default")
    parser.add_argument("--hold-through-changes", action="store_true",
                        help="the scheduled fit without its confirmed change test "
                             "(refit_on_change=False)")
    parser.add_argument("--json", default=None)
    parser.add_argument("--workers", type=int, default=None,
                        help="processes for the seeds (default: one per core); each "
                             "seed's figures are the serial run's, only s/run moves")
    args = parser.parse_args()
    options = {} if args.coupling_drift is None else {"coupling_drift": args.coupling_drift}
    if args.drift_reference is not None:
        options["drift_reference"] = args.drift_reference
    if args.rediscover is not None:
        options["rediscover"] = None if args.rediscover == "none" else int(args.rediscover)
    if args.hold_through_changes:
        options["refit_on_change"] = False
    if options and (args.identifier == "default") == args.hold_through_changes:
        parser.error("--coupling-drift, --drift-reference and --rediscover are the default "
                     "identifier's options, --hold-through-changes the scheduled one's")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    out = {}
    print("10 s-ahead VAF (%) attitude / rate / deflection from 150 s, median [worst] over "
          f"{args.seeds} seeds ({seeds.start}-{seeds.stop - 1}); mode and gain errors (%) over "
          f"the tracking windows; identifier: {args.identifier}"
          f"{', options ' + str(options) if options else ''}")
    header = (f"{'scenario':<16}{'SNR dB':>7}{'N m':>5}  {'persistence':<22}"
              f"{'frozen before change':<22}{'identifier':<22}{'mode err':>15}"
              f"{'frozen':>8}{'gain err':>15}{'2-sigma':>8}{'s/run':>7}")
    print(header)
    with single_threaded_blas:
        for scenario in args.scenarios:
            for cond in args.conditions:
                snr_text, rms_text = cond.split(":")
                snr = None if snr_text == "none" else float(snr_text)
                runs = map_in_order(partial(_score_seed, scenario, snr, float(rms_text),
                                            args.identifier, options), seeds, args.workers)
                out[f"{scenario} {cond}"] = runs
                vaf = {row: " / ".join(f"{np.median([r['vaf'][row][g] for r in runs]):.1f}"
                                       for g in range(3))
                       for row in ("persistence", "frozen", "identifier")}
                print(f"{scenario:<16}{snr_text:>7}{rms_text:>5}  {vaf['persistence']:<21} "
                      f"{vaf['frozen']:<21} {vaf['identifier']:<22}"
                      f"{_cell([r['mode_error_pct'] for r in runs], 'max'):>15}"
                      f"{np.median([r['frozen_mode_error_pct'] for r in runs]):>8.2f}"
                      f"{_cell([r['gain_error_pct'] for r in runs], 'max'):>15}"
                      f"{np.mean([r['coverage'] for r in runs]):>8.2f}"
                      f"{np.median([r['seconds'] for r in runs]):>7.2f}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
