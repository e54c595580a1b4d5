"""Tracking a pole jump: the recursive RPBSIDs on a small closed-loop system.

A third-order, one-input, two-output system in innovation form (predictor
poles 0.1, 0.2, 0.3) runs under output feedback ``u = -0.2 y_1 + r`` with
white excitation ``r``. At sample 1000 its poles jump from
``{0.9, 0.8 e^{+-0.3j}}`` to ``{0.7, 0.85 e^{+-0.5j}}``. Each method runs
with p = 5 and forgetting 0.98; printed: the largest eigenvalue error
(poles matched one to one) in the median over samples 700-1000 (before) and
1300-2000 (300+ samples after the jump), median [min, max] over seeds,
beside the model frozen before the jump (what no forgetting gives) and a
batch PBSID on the 1000 samples after the jump (the ceiling).

Usage: ``python benchmarks/bench_pole_jump.py [--seeds 10] [--noise 0.1]``
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.signal import place_poles

from identifiers import ClassicalRPBSID, ImprovedRPBSID, pbsid
from spacecraft_conventions import single_threaded_blas

BEFORE = (0.9, 0.8 * np.exp(0.3j))
AFTER = (0.7, 0.85 * np.exp(0.5j))
JUMP = 1000


def system(poles: tuple[float, complex]) -> tuple[np.ndarray, ...]:
    """(A, B, C, K) with the given real pole and complex pair; A - K C has poles 0.1-0.3."""
    real, pair = poles
    a = np.zeros((3, 3))
    a[0, 0] = real
    a[1:, 1:] = [[pair.real, -pair.imag], [pair.imag, pair.real]]
    b = np.array([[1.0], [0.5], [1.0]])
    c = np.array([[1.0, 1.0, 0.0], [0.0, 0.5, 1.0]])
    k = place_poles(a.T, c.T, [0.1, 0.2, 0.3]).gain_matrix.T
    return a, b, c, k


def closed_loop_record(seed: int, n_samples: int = 2000, noise: float = 0.1
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Inputs (N, 1) and outputs (N, 2) of the jumping system under feedback."""
    rng = np.random.default_rng(seed)
    mats = {False: system(BEFORE), True: system(AFTER)}
    x = np.zeros(3)
    u_rec, y_rec = np.empty((n_samples, 1)), np.empty((n_samples, 2))
    for k in range(n_samples):
        a, b, c, gain = mats[k >= JUMP]
        e = noise * rng.normal(size=2)
        y = c @ x + e
        u = -0.2 * y[0] + rng.normal()
        u_rec[k], y_rec[k] = u, y
        x = a @ x + b[:, 0] * u + gain @ e
    return u_rec, y_rec


def eigenvalue_error(a: np.ndarray, poles: tuple[float, complex]) -> float:
    """Largest distance between the eigenvalues of ``a`` and ``poles``, matched one to one."""
    real, pair = poles
    true = np.array([real, pair, np.conj(pair)])
    cost = np.abs(np.linalg.eigvals(a)[:, None] - true[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())


#: The recursive methods at p = 5, forgetting 0.98 (our defaults otherwise), and the
#: paper's preset of its method.
METHODS = {
    "classical": lambda: ClassicalRPBSID(3, p=5, forgetting=0.98, warmup=100),
    "improved": lambda: ImprovedRPBSID(3, p=5, forgetting=0.98, warmup=100),
    "improved (paper preset)": lambda: ImprovedRPBSID.paper(3, p=5),
}


def run(seeds: int, noise: float) -> dict[str, dict[str, list[float]]]:
    out: dict[str, dict[str, list[float]]] = {name: {"before": [], "after": []}
                                              for name in [*METHODS, "frozen", "batch"]}
    for seed in range(seeds):
        u, y = closed_loop_record(seed, noise=noise)
        for name, make in METHODS.items():
            seq = make().fit(u, y)
            out[name]["before"].append(float(np.median(
                [eigenvalue_error(seq[k].A, BEFORE) for k in range(700, JUMP, 10)])))
            out[name]["after"].append(float(np.median(
                [eigenvalue_error(seq[k].A, AFTER) for k in range(JUMP + 300, len(u), 10)])))
        out["frozen"]["after"].append(eigenvalue_error(system(BEFORE)[0], AFTER))
        batch = pbsid(u[JUMP:], y[JUMP:], 3, 5, regularization=0.0)
        out["batch"]["after"].append(eigenvalue_error(batch.A, AFTER))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--noise", type=float, default=0.1)
    args = parser.parse_args()
    with single_threaded_blas:
        res = run(args.seeds, args.noise)
    fmt = lambda v: (f"{np.median(v):.4f} [{min(v):.4f}, {max(v):.4f}]"  # noqa: E731
                     if v else "-")
    print(f"largest eigenvalue error, median [min, max] over {args.seeds} seeds "
          f"(bar after the jump: 0.02)")
    print(f"{'method':>26} {'before the jump':>28} {'300+ samples after':>28}")
    for name, row in res.items():
        print(f"{name:>26} {fmt(row['before']):>28} {fmt(row['after']):>28}")


if __name__ == "__main__":
    main()
