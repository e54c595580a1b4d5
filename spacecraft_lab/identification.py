"""The paper's identification experiment (Sec. 4), run for every method.

``spacecraft identify --scenario docking --seeds 10 --out DIR`` calls
:func:`run_identification`: for each noise seed it simulates the ETS-VIII
truth model under identification torques (random-phase multisines, our
stand-in for the paper's Fig. 2), adds white measurement noise at the given
SNR per channel (paper: 40 dB), runs every identifier on the record, and
scores the identified time-varying sequence:

* test-response normalized error (%) per attitude and rate channel, the
  paper's Tables 3/4 metric (docs/design/evaluation.md): the paper's test
  torques from zero state through the true plant and through
  ``{A_k, B_k, C_k}``;
* one-step-ahead prediction VAF (%) on a held-out noisy record (new input
  and noise realization, same scenario), after convergence (t >= 50 s);
* wall time of the identification run.

Every identifier normalizes signals by the nominal sensor levels
(:mod:`spacecraft_conventions.sensors`) rather than by statistics of data
it has not seen yet.

It writes ``metrics.json``, ``table.md`` (our numbers beside the paper's),
``responses.png`` (true vs identified test responses, seed 0) and
``modal.png`` (identified vs true natural frequencies over time, seed 0).
"""

from __future__ import annotations

import functools
import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from tqdm import tqdm

from identifiers import (
    ClassicalRPBSID,
    ImprovedRPBSID,
    ModelSequence,
    MomentRefitRPBSID,
    OnlineIdentifier,
    PredictorRPBSID,
    WindowedPBSID,
    add_measurement_noise,
    identification_inputs,
    normalized_error,
    paper_test_inputs,
    vaf,
)
from spacecraft_conventions import NOMINAL_TORQUE, single_threaded_blas
from spacecraft_env import FlexibleSpacecraftModel, ets8_parameters
from spacecraft_lab.paper import PAPER_TABLES
from spacecraft_lab.plots import plot_identification_modal, plot_identification_responses
from spacecraft_lab.reporting import identification_table

__all__ = [
    "METHODS",
    "IdentificationScore",
    "identification_records",
    "identify_task",
    "make_identifier",
    "nominal_scales",
    "paper_test_response",
    "run_identification",
    "score_identifier",
]

#: Method name -> factory ``(n, p, forgetting, **kwargs) -> identifier``.
#: ``warmup=None`` keeps a method's own warm-up; the sliding-window SVD
#: method always keeps its own (the window fills first) and ignores it.
METHODS: dict[str, Callable[..., OnlineIdentifier]] = {
    "moment-refit": MomentRefitRPBSID,
    "predictor": PredictorRPBSID,
    "improved": ImprovedRPBSID,
    "classical": ClassicalRPBSID,
    "windowed-svd": lambda n, p, lam, regularization=0.0, warmup=None, **kw: WindowedPBSID(
        n, p, window=500, regularization=regularization, **kw),
}


def nominal_scales(truth: FlexibleSpacecraftModel) -> dict[str, np.ndarray]:
    """The identifiers' fixed normalization: the nominal level of every torque
    axis and output channel of ``truth``, known before any data."""
    return {"input_scale": np.full(truth.n_inputs, NOMINAL_TORQUE),
            "output_scale": truth.output_layout.scales()}


def make_identifier(name: str, n: int, p: int, forgetting: float,
                    **kwargs: Any) -> OnlineIdentifier:
    """Build a method of :data:`METHODS` by name (``kwargs``: scales,
    regularization, ``warmup`` (None: the method's default))."""
    if kwargs.get("warmup") is None:
        kwargs.pop("warmup", None)
    try:
        factory = METHODS[name]
    except KeyError:
        raise ValueError(f"unknown method {name!r}; expected one of {sorted(METHODS)}") from None
    return factory(n, p, forgetting, **kwargs)


class IdentificationScore(NamedTuple):
    """One identifier scored on one seed (:func:`score_identifier`).

    Attributes
    ----------
    models : ModelSequence
        The identified sequence ``{A_k, B_k, C_k}``.
    test_error_pct : ndarray, shape (6,)
        Test-response normalized error per attitude and rate channel, %;
        ``inf`` where the identified response diverged.
    vaf_pct : ndarray, shape (n_outputs,)
        Held-out one-step-ahead VAF per output channel, %; ``-inf`` where
        the prediction diverged.
    time_s : float
        Wall time of the identification run (``fit``), s.
    """

    models: ModelSequence
    test_error_pct: np.ndarray
    vaf_pct: np.ndarray
    time_s: float


def identification_records(truth: FlexibleSpacecraftModel, seed: int, n_samples: int = 2500,
                           snr_db: float | None = 40.0) -> tuple[np.ndarray, ...]:
    """The identification and held-out records of one seed.

    Both are the truth model driven by random-phase multisine torques with
    white measurement noise at ``snr_db`` per channel, drawn in this order
    from ``np.random.default_rng(seed)``; the same seed gives the same
    records in any process.

    Returns
    -------
    u_id, y_id, u_ho, y_ho : ndarray
        Inputs ``(n_samples, 3)`` and noisy outputs ``(n_samples, n_outputs)``.
    """
    rng = np.random.default_rng(seed)
    u_id = identification_inputs(n_samples, rng, truth.dt)
    y_id = add_measurement_noise(truth.simulate(u_id)[1], snr_db, rng)
    u_ho = identification_inputs(n_samples, rng, truth.dt)
    y_ho = add_measurement_noise(truth.simulate(u_ho)[1], snr_db, rng)
    return u_id, y_id, u_ho, y_ho


def paper_test_response(truth: FlexibleSpacecraftModel,
                        n_samples: int = 2500) -> tuple[np.ndarray, np.ndarray]:
    """The paper's test torques and the true plant's noise-free response
    from rest, ``(n_samples, 3)`` and ``(n_samples, n_outputs)``."""
    u_test = paper_test_inputs(n_samples, truth.dt)
    return u_test, truth.simulate(u_test)[1]


def score_identifier(ident: OnlineIdentifier, records: Sequence[np.ndarray],
                     test: tuple[np.ndarray, np.ndarray], k_conv: int) -> IdentificationScore:
    """Run ``ident`` on an identification record and score it.

    Parameters
    ----------
    ident : OnlineIdentifier
        A fresh identifier.
    records : (u_id, y_id, u_ho, y_ho)
        From :func:`identification_records`.
    test : (u_test, y_test)
        From :func:`paper_test_response`.
    k_conv : int
        First sample of the held-out VAF window (convergence time / dt).
    """
    u_id, y_id, u_ho, y_ho = records
    u_test, y_test = test
    start = time.perf_counter()
    seq = ident.fit(u_id, y_id)
    elapsed = time.perf_counter() - start
    with np.errstate(all="ignore"):
        e = normalized_error(seq.simulate(u_test), y_test)
        yhat = seq.predict(u_ho, y_ho, start=k_conv)
        v = vaf(y_ho[k_conv:], yhat[k_conv:])
    return IdentificationScore(seq, np.where(np.isfinite(e), e, np.inf),
                               np.where(np.isfinite(v), v, -np.inf), elapsed)


def _finite(values: np.ndarray) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def _summary(values: np.ndarray) -> dict:
    """Mean, std, median over seeds (axis 0) with divergent runs counted."""
    arr = np.asarray(values, dtype=float)
    ok = np.all(np.isfinite(arr), axis=tuple(range(1, arr.ndim)))
    good = arr[ok]
    nan = np.full(arr.shape[1:], np.nan)
    return {
        "mean": _finite(good.mean(axis=0)) if good.size else _finite(nan),
        "std": _finite(good.std(axis=0)) if good.size else _finite(nan),
        "median": _finite(np.median(arr, axis=0)),
        "diverged_runs": int((~ok).sum()),
    }


def run_identification(scenario: str = "docking", seeds: int = 10, out: str | Path = "results",
                       *, methods: Sequence[str] | None = None, snr_db: float | None = 40.0,
                       n_modes: int = 2, p: int = 15, forgetting: float = 0.98,
                       n_samples: int = 2500, convergence_s: float = 50.0,
                       regularization: float = 0.0, warmup: int | None = None,
                       progress: bool = True) -> dict:
    """Run the identification experiment and write its artefacts.

    Parameters
    ----------
    scenario : str
        Truth-model scenario (``"docking"``, ``"solar_rotation"``, ...).
    seeds : int
        Noise/input seeds 0 .. seeds-1.
    out : path
        Output directory.
    methods : sequence of str, optional
        Subset of :data:`METHODS` (default all).
    snr_db : float or None
        Measurement SNR per channel (paper: 40 dB); None for noiseless.
    n_modes : int
        Modes per appendage (order n = 2 (3 + 4 n_modes)).
    p, forgetting : int, float
        Past window and forgetting factor (paper: 15 and 0.98).
    n_samples : int
        Record length (paper: 2500 = 250 s).
    convergence_s : float
        Start of the held-out VAF window, s.
    regularization : float
        VARX Tikhonov floor as a fraction of the effective memory (0: the
        paper's algorithms; see ``RecursivePBSIDBase``), for every method.
    warmup : int, optional
        Warm-up samples of the recursive methods (default: theirs).

    Returns
    -------
    dict
        The content of ``metrics.json``.
    """
    methods = list(methods or METHODS)
    for name in methods:
        if name not in METHODS:
            raise ValueError(f"unknown method {name!r}; expected one of {sorted(METHODS)}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    truth = FlexibleSpacecraftModel(ets8_parameters(n_modes), scenario=scenario)
    n = truth.n
    dt = truth.dt
    u_test, y_test = paper_test_response(truth, n_samples)
    k_conv = round(convergence_s / dt)
    scales = {**nominal_scales(truth), "regularization": regularization, "warmup": warmup}

    err = {m: [] for m in methods}
    vafs = {m: [] for m in methods}
    times = {m: [] for m in methods}
    seed0: dict[str, ModelSequence] = {}
    bar = tqdm(total=seeds * len(methods), desc=f"identify {scenario}", disable=not progress)
    with single_threaded_blas:
        for seed in range(seeds):
            records = identification_records(truth, seed, n_samples, snr_db)
            for name in methods:
                ident = make_identifier(name, n, p, forgetting, **scales)
                score = score_identifier(ident, records, (u_test, y_test), k_conv)
                err[name].append(score.test_error_pct)
                vafs[name].append(score.vaf_pct)
                times[name].append(score.time_s)
                if seed == 0:
                    seed0[name] = score.models
                bar.update()
    bar.close()

    labels = truth.output_labels
    results = {}
    for name in methods:
        e = np.array(err[name])
        v = np.array(vafs[name])
        results[name] = {
            "test_error_pct": {"attitude": _summary(e[:, :3]), "rate": _summary(e[:, 3:6])},
            "one_step_vaf_pct": {
                "attitude": _summary(v[:, :3]), "rate": _summary(v[:, 3:6]),
                "deflection": _summary(v[:, 6:]),
            },
            "run_time_s": {"mean": float(np.mean(times[name])),
                           "std": float(np.std(times[name]))},
        }
    metrics = {
        "scenario": scenario, "seeds": seeds, "snr_db": snr_db, "order_n": n, "p": p,
        "forgetting": forgetting, "regularization": regularization, "warmup": warmup,
        "n_samples": n_samples,
        "dt": dt,
        "convergence_s": convergence_s, "output_labels": list(labels),
        "methods": results, "paper": PAPER_TABLES.get(scenario),
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    (out / "table.md").write_text(identification_table(metrics))
    plot_identification_responses(out / "responses.png", u_test, y_test, seed0, scenario, dt)
    plot_identification_modal(out / "modal.png", truth, seed0, scenario)
    return metrics


@functools.lru_cache(maxsize=4)
def _truth(scenario: str, n_modes: int) -> FlexibleSpacecraftModel:
    return FlexibleSpacecraftModel(ets8_parameters(n_modes), scenario=scenario)


@functools.lru_cache(maxsize=8)
def _records(scenario: str, n_modes: int, seed: int, n_samples: int,
             snr_db: float | None) -> tuple[np.ndarray, ...]:
    truth = _truth(scenario, n_modes)
    out = (*identification_records(truth, seed, n_samples, snr_db),
           *paper_test_response(truth, n_samples))
    for arr in out:
        arr.setflags(write=False)
    return out


@single_threaded_blas
def identify_task(*, method: str, seed: int, scenario: str = "docking",
                  order: int | None = None, n_modes: int = 2, p: int = 15,
                  forgetting: float = 0.98, snr_db: float | None = 40.0,
                  n_samples: int = 2500, convergence_s: float = 50.0,
                  regularization: float = 0.0, warmup: int | None = None) -> dict:
    """One identification run: one method on one seed (a sweep task).

    The same keywords as :func:`run_identification`, for a single method and
    seed; the records are those of :func:`identification_records`, so the
    result is a function of the arguments alone: bit-identical in any
    process and whatever the caller's BLAS threads (the whole task runs
    single-threaded). The truth model and records are cached per process,
    so tasks sharing a seed share the simulation.

    Parameters
    ----------
    method : str
        A key of :data:`METHODS`.
    seed : int
        Input and noise seed.
    order : int, optional
        System order n = 22, 30, 38, 46, ... (``6 + 8 k``); overrides
        ``n_modes`` (k modes per appendage) when given.

    Returns
    -------
    dict
        ``{"metrics": {...}, "timings": {"time_s": ...}}``. Metrics:
        ``order_n``; ``test_error_attitude_pct`` / ``test_error_rate_pct``
        (channel means of the test-response error, None if diverged);
        ``vaf_attitude_pct`` / ``vaf_rate_pct`` / ``vaf_deflection_pct``
        (channel means of the held-out one-step VAF, None if diverged);
        ``nonfinite`` (the identified test response or prediction overflowed);
        ``within_5pct`` (every attitude and rate test-response error below
        5 %, the paper's accuracy level); and the per-channel lists
        ``test_error_pct``,
        ``vaf_pct``. ``time_s`` is the wall time of ``fit``.
    """
    if order is not None:
        k, rem = divmod(int(order) - 6, 8)
        if rem or k < 1 or int(order) != order:
            raise ValueError(f"order must be 6 + 8 k for k >= 1 (14, 22, 30, 38, 46, ...), "
                             f"got {order!r}")
        n_modes = k
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {sorted(METHODS)}")
    truth = _truth(scenario, int(n_modes))
    *records, u_test, y_test = _records(scenario, int(n_modes), int(seed), int(n_samples),
                                        None if snr_db is None else float(snr_db))
    ident = make_identifier(method, truth.n, int(p), float(forgetting), **nominal_scales(truth),
                            regularization=float(regularization),
                            warmup=None if warmup is None else int(warmup))
    score = score_identifier(ident, records, (u_test, y_test), round(convergence_s / truth.dt))
    e, v = score.test_error_pct, score.vaf_pct

    def channel_mean(x: np.ndarray) -> float | None:
        m = float(np.mean(x))
        return m if np.isfinite(m) else None

    metrics = {
        "order_n": truth.n,
        "test_error_attitude_pct": channel_mean(e[:3]),
        "test_error_rate_pct": channel_mean(e[3:6]),
        "vaf_attitude_pct": channel_mean(v[:3]),
        "vaf_rate_pct": channel_mean(v[3:6]),
        "vaf_deflection_pct": channel_mean(v[6:]),
        "nonfinite": bool(not (np.all(np.isfinite(e)) and np.all(np.isfinite(v)))),
        "within_5pct": bool(np.all(e[:6] < 5.0)),
        "test_error_pct": _finite(e),
        "vaf_pct": _finite(v),
    }
    return {"metrics": metrics, "timings": {"time_s": score.time_s}}
