"""Our identifiers against other packages' on the same spacecraft data, in one run.

Needs the optional peers (``pip install -e ".[peers]"``, or ``make bench-peers``,
which builds ``.venv-peers``): mdof (SRIM), SIPPY (N4SID, MOESP, CVA, PARSIM-K),
nfoursid (N4SID) and osysid (online least squares, used as an online ARX).

Batch, on the time-invariant spacecraft (scenario ``constant``, n = 22, 2500
samples of the identification torques, 40 dB noise per channel), each peer
used as its documentation shows:

* ``pbsid``: ours, called with its defaults, ``pbsid(U, Y, 22)``.
* ``srim``: ``mdof.sysid(inputs, outputs, method="srim", horizon=50, order=22)``
  on outputs scaled to unit RMS per channel (mdof works on raw arrays; without
  the scaling the angle and deflection channels, 1e-2 and 1e-2 apart, swamp
  the rates), converted back.
* ``sippy-n4sid``, ``-moesp``, ``-cva``, ``-parsim-k``:
  ``sippy_unipi.system_identification(y, u, method, SS_fixed_order=22)`` with
  the package's default horizons (``SS_f = SS_p = 20``), on the same scaled
  outputs.
* ``nfoursid``: ``NFourSID(frame, num_block_rows=15).subspace_identification()``
  then ``system_identification(rank=22)``; its noise covariance is
  ``[[R, S^T], [S, Q]]`` (measurement noise first, as its ``Kalman`` class
  documents), from which the predictor gain comes by the Riccati equation.

Scored: the paper's test-response error (Sec. 4.3: the simulated response to
the paper's test torques against the truth's, percent of its RMS), the
10 s-ahead prediction VAF on a held-out record from each model's own
predictor (the innovation form ``x+ = A x + B u + K (y - C x)``; SRIM gives no
noise model, so its state is the simulation from rest), and the run time with
its ratio to ``pbsid`` measured in the same process.

Online, on the docking record (the scenario of the paper): ``rigid-flexible``
(our default identifier), ``classical`` (classical RPBSID at its defaults) and
``osysid-arx`` (``osysid.OnlineModel`` fitted to the ARX regression
``y_k = M [y_{k-1..k-5}; u_{k-1..k-5}]`` with its forgetting ``alpha = 0.999``,
initialized with ``initialize()`` on the first 200 samples as its docs
suggest); 10 s-ahead VAF from t = 150 s beside persistence.

Usage: ``python benchmarks/bench_peers.py [--seeds 10] [--json out.json]``
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import logging
import time
import warnings
from collections.abc import Callable

import numpy as np
from scipy.linalg import solve_discrete_are

from identifiers import (
    ClassicalRPBSID,
    ModelSequence,
    StateSpaceModel,
    add_measurement_noise,
    default_identifier,
    h_step_predictions,
    identification_inputs,
    normalized_error,
    paper_test_inputs,
    pbsid,
    persistence_predictions,
    prediction_vaf,
    vaf,
)
from spacecraft_conventions import NOMINAL_TORQUE, STANDARD_OUTPUTS, single_threaded_blas
from spacecraft_env import FlexibleSpacecraftModel

ORDER = 22
HORIZON = 100                 # 10 s at dt = 0.1 s
START = 1500                  # online scoring from t = 150 s
GROUPS = {name: rows for name, rows in STANDARD_OUTPUTS}
ARX_LAGS = 5


# ----------------------------------------------------------------------------- data
def lti_record(truth: FlexibleSpacecraftModel, seed: int, n: int = 2500
               ) -> tuple[np.ndarray, ...]:
    """Identification and held-out records (noisy, and the held-out's noise-free outputs)."""
    rng = np.random.default_rng(seed)
    u = identification_inputs(n, rng, truth.dt)
    y = add_measurement_noise(truth.simulate(u)[1], 40.0, rng)
    u2 = identification_inputs(n, rng, truth.dt)
    y2_clean = truth.simulate(u2)[1]
    return u, y, u2, add_measurement_noise(y2_clean, 40.0, rng), y2_clean


# ----------------------------------------------------------------------------- batch peers
def _scaled(fit: Callable[[np.ndarray, np.ndarray], tuple], u: np.ndarray, y: np.ndarray
            ) -> StateSpaceModel:
    """Run ``fit`` on outputs scaled to unit RMS; return the model in physical units."""
    scale = np.sqrt(np.mean(y**2, axis=0))
    a, b, c, d, k = fit(u, y / scale)
    return StateSpaceModel(a, b, scale[:, None] * c, scale[:, None] * d,
                           np.zeros((a.shape[0], y.shape[1])) if k is None else k / scale,
                           0.1)


def _srim(u: np.ndarray, y: np.ndarray) -> tuple:
    import mdof
    a, b, c, d = mdof.sysid(u.T, y.T, method="srim", horizon=50, order=ORDER)
    return a, b, c, d, None


def _sippy(method: str) -> Callable[[np.ndarray, np.ndarray], tuple]:
    def fit(u: np.ndarray, y: np.ndarray) -> tuple:
        from sippy_unipi import system_identification
        with contextlib.redirect_stdout(io.StringIO()):       # it prints progress
            model = system_identification(y.T, u.T, method, SS_fixed_order=ORDER, tsample=0.1)
        k = getattr(model, "K", None)
        k = None if k is None or np.size(k) == 0 else np.asarray(k)
        return model.A, model.B, model.C, model.D, k
    return fit


def _nfoursid(u: np.ndarray, y: np.ndarray) -> tuple:
    import pandas as pd
    from nfoursid.nfoursid import NFourSID
    cols_u, cols_y = [f"u{i}" for i in range(u.shape[1])], [f"y{i}" for i in range(y.shape[1])]
    frame = pd.DataFrame(np.hstack([u, y]), columns=cols_u + cols_y)
    n4 = NFourSID(frame, output_columns=cols_y, input_columns=cols_u, num_block_rows=15)
    n4.subspace_identification()
    ss, cov = n4.system_identification(rank=ORDER)
    m = y.shape[1]
    r, s, q = cov[:m, :m], cov[m:, :m], cov[m:, m:]         # [[R, S^T], [S, Q]]
    p = solve_discrete_are(ss.a.T, ss.c.T, q, r, s=s)
    k = (ss.a @ p @ ss.c.T + s) @ np.linalg.inv(ss.c @ p @ ss.c.T + r)
    return ss.a, ss.b, ss.c, ss.d, k


BATCH: dict[str, Callable[[np.ndarray, np.ndarray], StateSpaceModel]] = {
    "pbsid": lambda u, y: pbsid(u, y, ORDER),
    "srim": lambda u, y: _scaled(_srim, u, y),
    "sippy-n4sid": lambda u, y: _scaled(_sippy("N4SID"), u, y),
    "sippy-moesp": lambda u, y: _scaled(_sippy("MOESP"), u, y),
    "sippy-cva": lambda u, y: _scaled(_sippy("CVA"), u, y),
    "sippy-parsim-k": lambda u, y: _scaled(_sippy("PARSIM-K"), u, y),
    "nfoursid": lambda u, y: _scaled(_nfoursid, u, y),
}


def batch_scores(model: StateSpaceModel, test: tuple[np.ndarray, np.ndarray],
                 held_out: tuple[np.ndarray, np.ndarray, np.ndarray]) -> dict[str, float]:
    """Paper test error (attitude, rate) and held-out 10 s-ahead VAF by group."""
    u_test, y_test = test
    u2, y2, y2_clean = held_out
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        err = normalized_error(model.simulate(u_test), y_test)
        states = _predictor_states(model, u2, y2)
        n = len(u2)
        rep = lambda mat: np.repeat(mat[None], n, axis=0)  # noqa: E731
        seq = ModelSequence(rep(model.A), rep(model.B), rep(model.C), rep(model.D),
                            rep(model.K), np.ones(n, dtype=bool), model.dt, states=states)
        v = prediction_vaf(y2_clean, h_step_predictions(seq, u2, (HORIZON,)), 200)[HORIZON]
    out = {"test_error_attitude": float(np.mean(err[:3])),
           "test_error_rate": float(np.mean(err[3:6]))}
    out.update({f"vaf_h{HORIZON}_{g}": float(np.mean(v[rows])) for g, rows in GROUPS.items()})
    return out


def _predictor_states(model: StateSpaceModel, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``x_{k+1|k}`` of the model's innovation-form predictor over a record."""
    x = np.zeros(model.n)
    out = np.empty((len(u), model.n))
    for k in range(len(u)):
        e = y[k] - model.C @ x - model.D @ u[k]
        x = model.A @ x + model.B @ u[k] + model.K @ e
        if not np.all(np.isfinite(x)) or np.abs(x).max() > 1e12:
            x = np.full(model.n, np.nan)
        out[k] = x
    return out


# ----------------------------------------------------------------------------- online peers
def _arx_online_predictions(u: np.ndarray, y: np.ndarray, alpha: float = 0.999,
                            every: int = 10) -> np.ndarray:
    """osysid's OnlineModel as an online ARX; 10 s-ahead predictions every ``every`` samples."""
    from osysid import OnlineModel
    su = np.full(u.shape[1], NOMINAL_TORQUE)
    sy = STANDARD_OUTPUTS.scales()
    un, yn = u / su, y / sy
    lags = ARX_LAGS
    dim = lags * (un.shape[1] + yn.shape[1])

    def regressor(k: int, yy: np.ndarray, uu: np.ndarray) -> np.ndarray:
        return np.concatenate([yy[k - lags:k][::-1].ravel(), uu[k - lags:k][::-1].ravel()])

    # its `initialize` does not mark the model ready, so reading M warns until the
    # first update: those warnings are silenced
    logging.getLogger("osysid").setLevel(logging.ERROR)
    model = OnlineModel(dim, yn.shape[1], alpha)
    init = 200
    xs = np.array([regressor(k, yn, un) for k in range(lags, init)]).T
    model.initialize(xs, yn[lags:init].T)
    pred = np.full_like(y, np.nan)
    for k in range(init, len(u)):
        if (k - init) % every == 0 and k + HORIZON < len(u):
            yy = yn[:k].copy()
            for j in range(HORIZON + 1):
                step = model.M @ regressor(k + j, yy, un) if j < HORIZON else None
                if step is not None:
                    yy = np.vstack([yy, step])
            pred[k + HORIZON - 1] = yy[k + HORIZON - 1] * sy
        model.update(regressor(k, yn, un), yn[k])
    return pred


def online_scores(seed: int) -> dict[str, dict[str, float]]:
    truth = FlexibleSpacecraftModel(scenario="docking")
    rng = np.random.default_rng(seed)
    u = identification_inputs(2500, rng, truth.dt)
    y_clean = truth.simulate(u)[1]
    y = add_measurement_noise(y_clean, 40.0, rng)
    out: dict[str, dict[str, float]] = {}
    runs = {
        "rigid-flexible": lambda: default_identifier(),
        "classical": lambda: ClassicalRPBSID(
            ORDER, input_scale=np.full(3, NOMINAL_TORQUE),
            output_scale=STANDARD_OUTPUTS.scales()),
    }
    for name, make in runs.items():
        start = time.perf_counter()
        seq = make().fit(u, y)
        elapsed = time.perf_counter() - start
        with np.errstate(all="ignore"):
            v = prediction_vaf(y_clean, h_step_predictions(seq, u, (HORIZON,)), START)[HORIZON]
        out[name] = {g: float(np.mean(v[rows])) for g, rows in GROUPS.items()}
        out[name]["time_s"] = elapsed
    start = time.perf_counter()
    pred = _arx_online_predictions(u, y)
    elapsed = time.perf_counter() - start
    mask = np.isfinite(pred[:, 0])
    mask[:START] = False
    with np.errstate(all="ignore"):
        v = vaf(y_clean[mask], pred[mask])
    out["osysid-arx"] = {g: float(np.mean(v[rows])) for g, rows in GROUPS.items()}
    out["osysid-arx"]["time_s"] = elapsed
    pers = prediction_vaf(y_clean, persistence_predictions(y, (HORIZON,)), START)[HORIZON]
    out["persistence"] = {g: float(np.mean(pers[rows])) for g, rows in GROUPS.items()}
    return out


# ----------------------------------------------------------------------------- run
def run(seeds: int, methods: tuple[str, ...] = tuple(BATCH)) -> dict:
    truth = FlexibleSpacecraftModel(scenario="constant")
    u_test = paper_test_inputs(2500, truth.dt)
    test = (u_test, truth.simulate(u_test)[1])
    batch: dict[str, list[dict[str, float]]] = {name: [] for name in methods}
    online: list[dict[str, dict[str, float]]] = []
    for seed in range(seeds):
        u, y, u2, y2, y2_clean = lti_record(truth, seed)
        for name in methods:
            start = time.perf_counter()
            try:
                model = BATCH[name](u, y)
            except Exception as exc:                     # a peer that fails is reported
                batch[name].append({"error": f"{type(exc).__name__}: {exc}"})
                continue
            elapsed = time.perf_counter() - start
            scores = batch_scores(model, test, (u2, y2, y2_clean))
            batch[name].append({**scores, "time_s": elapsed})
        online.append(online_scores(seed))
    return {"batch": batch, "online": online}


def _summary(values: list[float]) -> str:
    v = np.array([x for x in values if x is not None], dtype=float)
    if not v.size:
        return "-"
    finite = v[np.isfinite(v)]
    med = np.median(np.where(np.isfinite(v), v, np.inf))
    if not finite.size or not np.isfinite(med) or abs(med) > 1e6:
        return "diverged"
    return f"{med:.3g} [{finite.min():.3g}, {finite.max():.3g}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    with single_threaded_blas:
        res = run(args.seeds)
    keys = ("test_error_attitude", "test_error_rate", "vaf_h100_attitude", "vaf_h100_rate",
            "vaf_h100_deflection", "time_s")
    print(f"Batch, time-invariant spacecraft, 40 dB, n = {ORDER}: median [min, max] over "
          f"{args.seeds} seeds")
    print(f"{'method':>16}" + "".join(f"{k:>26}" for k in (*keys, "time / pbsid")))
    pbsid_times = [r["time_s"] for r in res["batch"]["pbsid"]]
    for name, rows in res["batch"].items():
        errors = [r["error"] for r in rows if "error" in r]
        ok = [r for r in rows if "error" not in r]
        cells = [_summary([r[k] for r in ok]) for k in keys]
        ratio = _summary([r["time_s"] / t for r, t in zip(rows, pbsid_times, strict=True)
                          if "error" not in r])
        print(f"{name:>16}" + "".join(f"{c:>26}" for c in (*cells, ratio))
              + (f"  ({len(errors)} failed: {errors[0][:60]})" if errors else ""))
    print(f"\nOnline, docking, 40 dB: 10 s-ahead VAF from t = 150 s, median [min, max] over "
          f"{args.seeds} seeds")
    names = list(res["online"][0])
    print(f"{'method':>16}" + "".join(f"{g:>26}" for g in (*GROUPS, "time_s")))
    for name in names:
        rows = [r[name] for r in res["online"]]
        cells = [_summary([r.get(k) for r in rows]) for k in (*GROUPS, "time_s")]
        print(f"{name:>16}" + "".join(f"{c:>26}" for c in cells))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()
