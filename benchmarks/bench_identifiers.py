"""Identifier run time for a 2500-sample record at n = 22, 30, 38, 46.

Every method runs on the same data (docking scenario, 40 dB SNR, p = 15,
forgetting 0.98) in one process, BLAS limited to one thread; the ratios
improved/classical and improved/SVD are printed beside the paper's MATLAB
Table 5 ratios.

Printed beside each other: seconds per record for every method, the ratios
ours/classical and ours/SVD (ours: the moment-refit identifier, the
package default's class) beside the paper's improved/classical and
improved/SVD ratios, and the growth of our cost from the smallest to the
largest order beside the quadratic bound.

Usage: ``python benchmarks/bench_identifiers.py [--orders 22 30 38 46] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from identifiers import add_measurement_noise, identification_inputs
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import FlexibleSpacecraftModel, ets8_parameters
from spacecraft_lab.identification import make_identifier, nominal_scales
from spacecraft_lab.paper import PAPER_TABLE5

#: Paper Table 5, MATLAB seconds per run: classical, improved, SVD-based.
PAPER = {n: (PAPER_TABLE5["classical"][n], PAPER_TABLE5["improved"][n],
             PAPER_TABLE5["windowed-svd"][n]) for n in PAPER_TABLE5["classical"]}
METHODS = ("moment-refit", "predictor", "improved", "classical", "windowed-svd")


def run(orders, n_samples: int = 2500, repeats: int = 3) -> dict:
    out = {}
    for n in orders:
        modes = (n // 2 - 3) // 4
        truth = FlexibleSpacecraftModel(ets8_parameters(modes), scenario="docking")
        rng = np.random.default_rng(0)
        u = identification_inputs(n_samples, rng)
        y = add_measurement_noise(truth.simulate(u)[1], 40.0, rng)
        out[n] = {}
        for name in METHODS:
            reps = 1 if name == "windowed-svd" else repeats
            best = np.inf
            for _ in range(reps):
                ident = make_identifier(name, n, 15, 0.98, **nominal_scales(truth))
                start = time.perf_counter()
                for k in range(n_samples):
                    ident.update(u[k], y[k])
                best = min(best, time.perf_counter() - start)
            out[n][name] = best
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--orders", type=int, nargs="+", default=[22, 30, 38, 46])
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    with single_threaded_blas:
        times = run(args.orders)
    print(f"{'n':>4}" + "".join(f"{m:>21}" if len(m) > 14 else f"{m:>15}" for m in METHODS)
          + f"{'ours/cls':>10}{'paper':>8}{'ours/SVD':>10}{'paper':>8}")
    for n, row in times.items():
        c, i, s = PAPER.get(n, (np.nan,) * 3)
        print(f"{n:>4}" + "".join(f"{row[m]:>20.3f}s" if len(m) > 14 else f"{row[m]:>14.3f}s"
                                  for m in METHODS)
              + f"{row['moment-refit'] / row['classical']:>10.3f}{i / c:>8.2f}"
              + f"{row['moment-refit'] / row['windowed-svd']:>10.4f}{i / s:>8.2f}")
    first, last = args.orders[0], args.orders[-1]
    growth = times[last]["moment-refit"] / times[first]["moment-refit"]
    print(f"moment-refit per-step cost growth n={first} -> n={last}: {growth:.2f}x "
          f"(bound (n ratio)^2 = {(last / first) ** 2:.2f}x)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"seconds": times, "paper_table5": PAPER}, fh, indent=2)


if __name__ == "__main__":
    main()
