"""How much the ETS-VIII model can be identified at 40 dB (docs/results/identification.md).

    python examples/identifiability_study.py

1. Batch PBSID (n = 22, p = 15) on LTI records of 500-5000 samples: one-step
   VAF on a held-out record, with two regularization strengths.
2. The VARX's first Markov parameters (rate rows) against the truth, with and
   without Tikhonov regularization.

The comparison with other packages (SRIM, N4SID, MOESP, online ARX) is
``benchmarks/bench_peers.py``.
"""

import numpy as np

from identifiers import add_measurement_noise, identification_inputs, pbsid, vaf
from identifiers.subspace.varx import predictor_product, regressor_matrix
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import FlexibleSpacecraftModel

truth = FlexibleSpacecraftModel(scenario="constant")
rng = np.random.default_rng(0)
u2 = identification_inputs(2500, np.random.default_rng(99))
y2 = add_measurement_noise(truth.simulate(u2)[1], 40.0, np.random.default_rng(98))

with single_threaded_blas:
    print("1. batch PBSID at 40 dB, held-out one-step VAF (%) by record length")
    print(f"{'samples':>8} {'ridge':>7} {'attitude':>9} {'rate':>7} {'deflection':>11}")
    for n_samples in (500, 1000, 1500, 2500, 5000):
        u = identification_inputs(n_samples, np.random.default_rng(0))
        y = add_measurement_noise(truth.simulate(u)[1], 40.0, np.random.default_rng(1))
        for ratio in (0.001, 0.01):
            model = pbsid(u, y, truth.n, 15, regularization=ratio * n_samples)
            with np.errstate(all="ignore"):
                v = vaf(y2[100:], model.predict(u2, y2)[100:])
            print(f"{n_samples:>8} {ratio:>7} {v[:3].mean():>9.2f} {v[3:6].mean():>7.2f} "
                  f"{v[6:].mean():>11.2f}")

    print("\n2. VARX Markov parameters C A^j B (rate rows), relative error, 2500 samples")
    d = truth.discrete(0.0)
    u = identification_inputs(2500, np.random.default_rng(0))
    y0 = truth.simulate(u)[1]
    for snr in (None, 60.0, 40.0):
        y = add_measurement_noise(y0, snr, np.random.default_rng(1))
        su, sy = u.std(0), y.std(0)
        z = np.hstack([u / su, y / sy])
        phi = regressor_matrix(z, 15)
        target = y[15:] / sy
        for delta in (0.0, 100.0):
            gram = phi.T @ phi + delta * np.eye(phi.shape[1])
            xi = np.linalg.lstsq(gram, phi.T @ target, rcond=None)[0].T
            lk = predictor_product(xi, 3, 6)
            errs = []
            for j in (0, 1, 5):
                est = sy[:, None] * lk[j * 10:(j + 1) * 10, :3] / su[None, :]
                true = d.C @ np.linalg.matrix_power(d.A, j) @ d.B
                errs.append(np.linalg.norm((est - true)[3:6]) / np.linalg.norm(true[3:6]))
            print(f"SNR {snr!s:>5} dB, ridge {delta:>5}: j = 0, 1, 5 -> "
                  + ", ".join(f"{e:.3g}" for e in errs))
