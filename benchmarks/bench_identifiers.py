"""Identifier run time for a 2500-sample record at n = 22, 30, 38, 46.

Every method runs on the same data (docking scenario, 40 dB SNR) in one
process, BLAS limited to one thread. The paper's three methods (improved
RPBSID, classical RPBSID, sliding-window SVD) run at the paper's constants
(preset ``"paper"``: p = 15, forgetting 0.98); our moment-refit identifier
and the package default (rigid-flexible) run at their defaults.

Printed beside each other: seconds per record for every method; the ratio
improved/classical and improved/SVD measured here beside the paper's MATLAB
Table 5 ratios; the ratio default/classical (our default against the
classical method, same run); and the growth of the default's cost from the
smallest to the largest order beside the quadratic bound.

A second table gives microseconds per update beside its comparators, in
the same run: the improved RPBSID (paper preset) and the classical RPBSID
against a bare recursive least squares of the improved's VARX size
(``p (r + m)`` regressors, m outputs: the floor any RPBSID update pays),
with that bare update's flop count (``dsymv`` + ``dsyr`` + ``dger``: about
``4 d^2 + 4 m d``) and the rate it reaches.

Usage: ``python benchmarks/bench_identifiers.py [--orders 22 30 38 46] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from identifiers import add_measurement_noise, identification_inputs
from identifiers.core.rls import RecursiveLeastSquares
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import FlexibleSpacecraftModel, ets8_parameters
from spacecraft_lab.identification import make_identifier
from spacecraft_lab.paper import PAPER_TABLE5

#: Paper Table 5, MATLAB seconds per run: classical, improved, SVD-based.
PAPER = {n: (PAPER_TABLE5["classical-rpbsid"][n], PAPER_TABLE5["improved-rpbsid"][n],
             PAPER_TABLE5["windowed-pbsid"][n]) for n in PAPER_TABLE5["classical-rpbsid"]}
#: (method, preset) in print order.
METHODS = (("rigid-flexible", "recommended"), ("structured-rpbsid", "recommended"),
           ("moment-refit-rpbsid", "recommended"), ("improved-rpbsid", "paper"),
           ("classical-rpbsid", "paper"), ("windowed-pbsid", "paper"))


def run(orders, n_samples: int = 2500, repeats: int = 3) -> dict:
    out = {}
    for n in orders:
        modes = (n // 2 - 3) // 4
        truth = FlexibleSpacecraftModel(ets8_parameters(modes), scenario="docking")
        rng = np.random.default_rng(0)
        u = identification_inputs(n_samples, rng)
        y = add_measurement_noise(truth.simulate(u)[1], 40.0, rng)
        out[n] = {}
        for name, preset in METHODS:
            reps = 1 if name == "windowed-pbsid" else repeats
            best = np.inf
            for _ in range(reps):
                ident = make_identifier(name, truth, preset)
                start = time.perf_counter()
                for k in range(n_samples):
                    ident.update(u[k], y[k])
                best = min(best, time.perf_counter() - start)
            out[n][name] = best
    return out


def bare_rls_seconds(d: int, m: int, n_samples: int = 2500, repeats: int = 3) -> float:
    """Seconds per record of the bare RLS primitive with ``d`` regressors, ``m`` outputs."""
    rng = np.random.default_rng(0)
    phi = rng.standard_normal((n_samples, d))
    y = rng.standard_normal((n_samples, m))
    best = np.inf
    for _ in range(repeats):
        rls = RecursiveLeastSquares(m, d, 0.98, 1.0)
        start = time.perf_counter()
        for k in range(n_samples):
            rls.update(phi[k], y[k])
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orders", type=int, nargs="+", default=[22, 30, 38, 46])
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    with single_threaded_blas:
        times = run(args.orders)
    names = [m for m, _ in METHODS]
    print("seconds per 2500-sample record (preset in brackets)")
    print(f"{'n':>4}" + "".join(f"{f'{m} [{p}]':>30}" for m, p in METHODS))
    for n, row in times.items():
        print(f"{n:>4}" + "".join(f"{row[m]:>29.3f}s" for m in names))
    print(f"\n{'n':>4}{'improved/classical':>20}{'paper':>7}{'improved/SVD':>14}{'paper':>7}"
          f"{'rigid-flexible/classical':>26}{'structured/improved':>21}")
    for n, row in times.items():
        c, i, s = PAPER.get(n, (np.nan,) * 3)
        print(f"{n:>4}{row['improved-rpbsid'] / row['classical-rpbsid']:>20.2f}{i / c:>7.2f}"
              f"{row['improved-rpbsid'] / row['windowed-pbsid']:>14.3f}{i / s:>7.2f}"
              f"{row['rigid-flexible'] / row['classical-rpbsid']:>26.2f}"
              f"{row['structured-rpbsid'] / row['improved-rpbsid']:>21.2f}")

    print("\nmicroseconds per update (2500 updates; bare RLS: the improved's VARX, d "
          "regressors, m outputs)")
    print(f"{'n':>4}{'d':>5}{'MFLOP':>7}{'bare RLS':>10}{'GFLOP/s':>9}{'improved-rpbsid':>16}"
          f"{'impr/bare':>10}{'classical-rpbsid':>17}{'impr/class':>11}{'rigid-flexible':>15}")
    per_update = {}
    for n in args.orders:
        modes = (n // 2 - 3) // 4
        truth = FlexibleSpacecraftModel(ets8_parameters(modes), scenario="docking")
        ident = make_identifier("improved-rpbsid", truth, "paper")
        m, p = truth.n_outputs, ident.p
        d = p * (3 + m)
        with single_threaded_blas:
            bare = bare_rls_seconds(d, m) / 2500 * 1e6
        mflop = (4 * d * d + 4 * m * d) / 1e6
        row = {k: v / 2500 * 1e6 for k, v in times[n].items()}
        per_update[n] = {"d": d, "mflop": mflop, "bare_rls_us": bare, **row}
        print(f"{n:>4}{d:>5}{mflop:>7.2f}{bare:>10.1f}{mflop * 1e3 / bare:>9.2f}"
              f"{row['improved-rpbsid']:>16.1f}{row['improved-rpbsid'] / bare:>10.2f}"
              f"{row['classical-rpbsid']:>17.1f}"
              f"{row['improved-rpbsid'] / row['classical-rpbsid']:>11.2f}"
              f"{row['rigid-flexible']:>15.0f}")
    first, last = args.orders[0], args.orders[-1]
    growth = times[last]["rigid-flexible"] / times[first]["rigid-flexible"]
    print(f"default per-record cost growth n={first} -> n={last}: {growth:.2f}x "
          f"(bound (n ratio)^2 = {(last / first) ** 2:.2f}x)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"seconds": times, "paper_table5": PAPER,
                       "us_per_update": per_update}, fh, indent=2)


if __name__ == "__main__":
    main()
