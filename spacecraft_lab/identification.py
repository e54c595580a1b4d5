"""The identification experiment: every method on the spacecraft, judged by what users need.

``spacecraft identify --scenario docking --seeds 10 --out DIR`` calls
:func:`run_identification`. For each seed it simulates the ETS-VIII truth
model under identification torques (random-phase multisines, a stand-in
for the paper's Fig. 2), adds white measurement noise at the given SNR per
channel (paper: 40 dB), runs every identifier on the record and scores it
(docs/design/evaluation.md):

* **h-step-ahead prediction VAF** (h = 0.1, 1, 5, 10 s) from the
  identifier's own state and model at each sample, driven by the true
  future torques, against the noise-free outputs, from ``convergence_s``
  on; beside **persistence** (``y_{k+h} = y_k``, the trivial baseline) and
  the **true model frozen at k with the true state** (the ceiling);
* the **rigid-body gain** ``J(t)^-1`` read from the identified model, before
  the first docking and from 20 s after each one;
* the **frequencies of the dominant flexible modes** (those the torques
  excite: the first paddle and antenna modes) against the truth's;
* the **share of models with a pole outside** ``|z| = 1.001``;
* the paper's **test-response error** (Sec. 4.3, Tables 3-4);
* one-step-ahead VAF on a held-out record (a column, never the headline:
  persistence scores 99 % there);
* run time.

``preset="paper"`` runs the recursive PBSID methods with the source
paper's constants (their ``paper()`` preset) to reproduce its tables.

It writes ``metrics.json``, ``table.md``, and figures: ``prediction.png``
(VAF against horizon, median and spread over seeds), ``gain.png``
(identified vs true inverse inertia over time, seed 0), ``modal.png``
(identified vs true modal frequencies, zoomed to the modes, seed 0) and
``responses.png`` (test responses, seed 0).
"""

from __future__ import annotations

import functools
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from tqdm import tqdm

from identifiers import (
    HORIZONS,
    ClassicalRPBSID,
    ImprovedRPBSID,
    ModelSequence,
    MomentRefitRPBSID,
    OnlineIdentifier,
    PredictorRPBSID,
    ScheduledPhysicalIdentifier,
    StructuredRPBSID,
    WindowedPBSID,
    add_measurement_noise,
    default_identifier,
    h_step_predictions,
    identification_inputs,
    modal_errors,
    normalized_error,
    paper_test_inputs,
    persistence_predictions,
    prediction_vaf,
    relative_gain_error,
    rigid_body_gain,
    unstable_share,
    vaf,
)
from spacecraft_conventions import NOMINAL_TORQUE, single_threaded_blas
from spacecraft_env import (
    SCENARIOS,
    FlexibleSpacecraftEnv,
    FlexibleSpacecraftModel,
    check_parameter,
    ets8_parameters,
)
from spacecraft_lab.paper import PAPER_SNR_DB, PAPER_TABLES
from spacecraft_lab.plots import (
    plot_identification_modal,
    plot_identification_responses,
    plot_prediction_horizons,
    plot_rigid_gain,
)
from spacecraft_lab.reporting import identification_table
from spacecraft_lab.sweeps.backends import check_workers, map_in_order

__all__ = [
    "BASELINES",
    "METHODS",
    "PRESETS",
    "IdentificationRecord",
    "dominant_modes",
    "drive_angles",
    "env_record",
    "identification_records",
    "identify_task",
    "make_identifier",
    "nominal_scales",
    "paper_test_response",
    "run_identification",
    "score_identifier",
    "truth_sequence",
]

#: Method presets: the settings we recommend (what no option gives), or the source paper's
#: constants.
PRESETS = ("recommended", "paper")
#: Rows that are not identifiers: the trivial baseline and the ceiling.
BASELINES = ("persistence", "truth frozen at k")
#: Sampling period (samples) of the gain and modal tracks.
TRACK_EVERY = 10


def nominal_scales(truth: FlexibleSpacecraftModel) -> dict[str, np.ndarray]:
    """The identifiers' fixed normalization: the nominal level of every torque
    axis and output channel of ``truth``, known before any data.

    Returns
    -------
    dict of str to ndarray
        "u" (3,), N m, and "y" (m,), the outputs' units.
    """
    return {"input_scale": np.full(truth.n_inputs, NOMINAL_TORQUE),
            "output_scale": truth.output_layout.scales()}


def _recursive(cls: type) -> Callable[..., OnlineIdentifier]:
    def build(truth: FlexibleSpacecraftModel, preset: str, **options: Any) -> OnlineIdentifier:
        kwargs = {**nominal_scales(truth), "dt": truth.dt, **options}
        return cls.paper(truth.n, **kwargs) if preset == "paper" else cls(truth.n, **kwargs)
    return build


def _rigid_flexible(truth: FlexibleSpacecraftModel, preset: str,
                    **options: Any) -> OnlineIdentifier:
    return default_identifier(truth.output_layout, n=truth.n, dt=truth.dt, **options)


def _structured(truth: FlexibleSpacecraftModel, preset: str,
                **options: Any) -> OnlineIdentifier:
    kwargs = {**nominal_scales(truth), "dt": truth.dt, **options}
    build = StructuredRPBSID.paper if preset == "paper" else StructuredRPBSID
    return build(truth.output_layout, n=truth.n, **kwargs)


def _scheduled_physical(truth: FlexibleSpacecraftModel, preset: str,
                        **options: Any) -> OnlineIdentifier:
    """The adaptive LQG's identifier (:func:`controllers.scheduled_identifier` builds the same
    from an env): told which appendages the drive turns and fed the drive's angle at
    every sample (:func:`score_identifier`); it has no paper preset."""
    return ScheduledPhysicalIdentifier(truth.output_layout, turning=truth.appendage_turns,
                                       sensor_appendage=truth.sensor_appendage,
                                       drive_axis=truth.drive_axis, dt=truth.dt, **options)


def _windowed(truth: FlexibleSpacecraftModel, preset: str, **options: Any) -> OnlineIdentifier:
    kwargs = {**nominal_scales(truth), "dt": truth.dt, **options}
    if preset != "paper":
        kwargs.setdefault("regularization", 1e-4)
    return WindowedPBSID(truth.n, 15, **kwargs)


#: Method name (the class's name in kebab case) -> builder ``(truth, preset, **options) ->
#: identifier``. The paper's method is ``improved-rpbsid`` (its "improved RPBSID").
METHODS: dict[str, Callable[..., OnlineIdentifier]] = {
    "scheduled-physical": _scheduled_physical,
    "rigid-flexible": _rigid_flexible,
    "moment-refit-rpbsid": _recursive(MomentRefitRPBSID),
    "predictor-rpbsid": _recursive(PredictorRPBSID),
    "improved-rpbsid": _recursive(ImprovedRPBSID),
    "structured-rpbsid": _structured,
    "classical-rpbsid": _recursive(ClassicalRPBSID),
    "windowed-pbsid": _windowed,
}
#: Methods run when none are named (the sliding-window SVD takes ~30 s a run).
DEFAULT_METHODS = ("scheduled-physical", "rigid-flexible", "structured-rpbsid",
                   "moment-refit-rpbsid", "predictor-rpbsid", "improved-rpbsid",
                   "classical-rpbsid")


def make_identifier(name: str, truth: FlexibleSpacecraftModel, preset: str = "recommended",
                    **options: Any) -> OnlineIdentifier:
    """Build a method of :data:`METHODS` for ``truth``'s outputs.

    Returns
    -------
    OnlineIdentifier
        A new identifier.

    Raises
    ------
    ValueError
        For an unknown method or preset.
    """
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; expected one of {sorted(METHODS)}")
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {PRESETS}, got {preset!r}")
    return METHODS[name](truth, preset, **options)


class IdentificationRecord(NamedTuple):
    """One seed's data.

    Attributes
    ----------
    u : (N, 3) ndarray
        Identification torques, N m.
    y : (N, m) ndarray
        Noisy outputs.
    y_clean : (N, m) ndarray
        Noise-free outputs (the targets of the h-step VAF).
    states : (N + 1, n) ndarray
        True states.
    u_held_out, y_held_out : ndarray
        A second record (new input and noise) for the one-step VAF.
    """

    u: np.ndarray
    y: np.ndarray
    y_clean: np.ndarray
    states: np.ndarray
    u_held_out: np.ndarray
    y_held_out: np.ndarray


def identification_records(truth: FlexibleSpacecraftModel, seed: int, n_samples: int = 2500,
                           snr_db: float | None = PAPER_SNR_DB) -> IdentificationRecord:
    """The identification and held-out records of one seed.

    Both are the truth model driven by random-phase multisine torques with
    white measurement noise at ``snr_db`` per channel (relative to the
    channel's RMS, as in the paper), drawn in this order from
    ``np.random.default_rng(seed)``: the same seed gives the same records in
    any process.

    Returns
    -------
    IdentificationRecord
        The torques, outputs, drive angles and the truth's model sequence.
    """
    rng = np.random.default_rng(seed)
    u = identification_inputs(n_samples, rng, truth.dt)
    states, y_clean = truth.simulate(u)
    y = add_measurement_noise(y_clean, snr_db, rng)
    u_ho = identification_inputs(n_samples, rng, truth.dt)
    y_ho = add_measurement_noise(truth.simulate(u_ho)[1], snr_db, rng)
    return IdentificationRecord(u, y, y_clean, states, u_ho, y_ho)


def env_record(scenario: str, seed: int, snr_db: float | None, rms: float = 1.0,
               steps: int = 2500) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                          FlexibleSpacecraftModel]:
    """A record of the public environment driven open-loop (the tracking benchmark's).

    The env of ``scenario`` (regulation task; its sensor noise fixed in physical
    units, ``snr_db`` of the nominal levels or None for noise-free), reset with
    ``seed`` and driven by random-phase multisine torques of RMS ``rms`` (N m)
    drawn from ``np.random.default_rng(1000 + seed)``.

    Returns
    -------
    u : (steps, 3) ndarray
        The torques (N m).
    y, y_clean : (steps, m) ndarray
        The measured and noise-free outputs (the env's first ``m`` observation
        channels, ``m`` the truth model's outputs: 10; the noise-free ones from its
        true state).
    model : FlexibleSpacecraftModel
        The env's truth model.
    """
    env = FlexibleSpacecraftEnv(scenario, snr_db=snr_db, task="regulation")
    obs, info = env.reset(seed=seed)
    u = identification_inputs(steps, np.random.default_rng(1000 + seed), rms=rms)
    ys, xs = [obs], [info["state"]]
    for k in range(steps - 1):
        obs, _, _, _, info = env.step((u[k] / env.max_torque).astype(np.float32))
        ys.append(obs)
        xs.append(info["state"])
    model = env.unwrapped.model
    n_outputs = model.C.shape[0]                # the observation's leading channels
    return u, np.array(ys)[:, :n_outputs].astype(float), np.array(xs) @ model.C.T, model



def drive_angles(model: FlexibleSpacecraftModel, steps: int) -> np.ndarray:
    """The drive's angle at each of the first ``steps`` samples of a record of
    ``model`` (rad; the env's ``info["paddle_angle"]``), the schedule
    :class:`identifiers.ScheduledPhysicalIdentifier` is fed.

    Returns
    -------
    (steps,) ndarray
        The angles, rad.
    """
    return np.array([model.scenario.paddle_angle(k * model.dt) for k in range(steps)])

def paper_test_response(truth: FlexibleSpacecraftModel,
                        n_samples: int = 2500) -> tuple[np.ndarray, np.ndarray]:
    """The paper's test torques and the true plant's noise-free response
    from rest, ``(n_samples, 3)`` and ``(n_samples, n_outputs)``.

    Returns
    -------
    (u, y) : ndarrays
        (n_samples, 3) torques, N m, and the true model's (n_samples, m) outputs.
    """
    u_test = paper_test_inputs(n_samples, truth.dt)
    return u_test, truth.simulate(u_test)[1]


def truth_sequence(truth: FlexibleSpacecraftModel, states: np.ndarray) -> ModelSequence:
    """The ceiling: the true model of each sample with the true next state
    ``x_{k+1}`` (what an identifier's ``x_{k+1|k}`` estimates).

    Returns
    -------
    ModelSequence
        The true models, one per sample.
    """
    n_samples = states.shape[0] - 1
    mats = [truth.discrete(k * truth.dt) for k in range(n_samples)]
    a = np.array([m.A for m in mats])
    b = np.array([m.B for m in mats])
    c = np.broadcast_to(truth.C, (n_samples, *truth.C.shape))
    d = np.zeros((n_samples, truth.n_outputs, truth.n_inputs))
    k = np.zeros((n_samples, truth.n, truth.n_outputs))
    return ModelSequence(a, b, c, d, k, np.ones(n_samples, dtype=bool), truth.dt,
                         states=states[1:])


def dominant_modes(truth: FlexibleSpacecraftModel, t: float,
                   min_weight: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and damping of the modes the torques excite (input-output
    weight >= ``min_weight``; the first paddle and antenna modes here).

    Returns
    -------
    (frequencies, damping) : ndarrays
        The dominant modes' frequencies (Hz) and damping ratios.
    """
    freq, zeta, weight = truth.modal_residues(t)
    keep = weight >= min_weight
    return freq[keep], zeta[keep]


@dataclass
class IdentificationScore:
    """One identifier (or baseline) scored on one seed (:func:`score_identifier`).

    Attributes
    ----------
    h_step_vaf : dict
        Horizon (samples) -> per-channel VAF (%), ``-inf`` where diverged.
    test_error_pct : ndarray or None
        Paper's test-response error per attitude and rate channel (%).
    held_out_vaf : ndarray or None
        One-step VAF on the held-out record per channel (%).
    gain_track : (K, 2) ndarray or None
        ``(time, relative error of J^-1)`` every :data:`TRACK_EVERY` samples.
    gain_history : (K, 4) ndarray or None
        ``(time, G_xx, G_yy, G_zz)`` of the identified inverse inertia.
    modal_track : (K, 2) ndarray or None
        ``(time, largest relative frequency error of the dominant modes)``.
    frequency_history : list
        ``(time, identified frequencies)`` pairs (seed-0 plots).
    unstable_share : float
    time_s : float
    events : tuple of float
        Times of the changes the identifier detected, s.
    models : ModelSequence or None
    """

    h_step_vaf: dict[int, np.ndarray]
    test_error_pct: np.ndarray | None = None
    held_out_vaf: np.ndarray | None = None
    gain_track: np.ndarray | None = None
    gain_history: np.ndarray | None = None
    modal_track: np.ndarray | None = None
    frequency_history: list = field(default_factory=list)
    unstable_share: float = float("nan")
    time_s: float = float("nan")
    events: tuple[float, ...] = ()
    models: ModelSequence | None = None


def _tracks(seq: ModelSequence, truth: FlexibleSpacecraftModel,
            start: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    rate = truth.output_layout.slice("rate")
    gains, history, modal, freqs = [], [], [], []
    for k in range(start, len(seq), TRACK_EVERY):
        if not seq.valid[k]:
            continue
        t = k * truth.dt
        model = seq[k]
        with np.errstate(all="ignore"):
            g = rigid_body_gain(model, rate)
        gains.append((t, relative_gain_error(g, np.linalg.inv(truth.inertia(t)))))
        history.append((t, *np.diag(g)))
        f_true, z_true = dominant_modes(truth, t)
        errors, _ = modal_errors(model, f_true, z_true)
        modal.append((t, float(np.nanmax(errors)) if np.isfinite(errors).any() else np.inf))
        freqs.append((t, model.modal()[0]))
    return (np.array(gains).reshape(-1, 2), np.array(history).reshape(-1, 4),
            np.array(modal).reshape(-1, 2), freqs)


def score_identifier(ident: OnlineIdentifier, record: IdentificationRecord,
                     truth: FlexibleSpacecraftModel, test: tuple[np.ndarray, np.ndarray],
                     k_conv: int, horizons: Sequence[int] = HORIZONS) -> IdentificationScore:
    """Run a fresh ``ident`` on ``record`` and score it (see the module docstring).

    Returns
    -------
    IdentificationScore
        The identifier's scores on the record.
    """
    # the drive-scheduled fit is told the drive's angle at every sample, as the env tells it
    schedule = ({"schedule": drive_angles(truth, len(record.u))}
                if isinstance(ident, ScheduledPhysicalIdentifier) else {})
    start = time.perf_counter()
    seq = ident.fit(record.u, record.y, **schedule)
    elapsed = time.perf_counter() - start
    u_test, y_test = test
    with np.errstate(all="ignore"):
        h_vaf = prediction_vaf(record.y_clean, h_step_predictions(seq, record.u, horizons),
                               k_conv)
        err = normalized_error(seq.simulate(u_test), y_test)[:6]
        yhat = seq.predict(record.u_held_out, record.y_held_out, start=k_conv)
        held = vaf(record.y_held_out[k_conv:], yhat[k_conv:])
    first = int(np.flatnonzero(seq.valid)[0]) if seq.valid.any() else len(seq)
    gain, history, modal, freqs = _tracks(seq, truth, first)
    events = tuple(e.time for e in getattr(ident, "events", ()))
    return IdentificationScore(h_vaf, np.where(np.isfinite(err), err, np.inf),
                               np.where(np.isfinite(held), held, -np.inf), gain, history,
                               modal, freqs, unstable_share(seq, first), elapsed, events, seq)


def _baselines(record: IdentificationRecord, truth: FlexibleSpacecraftModel, k_conv: int,
               horizons: Sequence[int]) -> dict[str, IdentificationScore]:
    pers = prediction_vaf(record.y_clean, persistence_predictions(record.y, horizons), k_conv)
    ceiling = prediction_vaf(record.y_clean,
                             h_step_predictions(truth_sequence(truth, record.states), record.u,
                                                horizons), k_conv)
    return {"persistence": IdentificationScore(pers),
            "truth frozen at k": IdentificationScore(ceiling, unstable_share=0.0)}


def _window_stats(track: np.ndarray, windows: Sequence[tuple[float, float]]) -> dict[str, Any]:
    if track is None or not len(track):
        return {"median": None, "p90": None}
    mask = np.zeros(len(track), dtype=bool)
    for lo, hi in windows:
        mask |= (track[:, 0] >= lo) & (track[:, 0] < hi)
    vals = track[mask, 1]
    if not vals.size:
        return {"median": None, "p90": None}
    with np.errstate(invalid="ignore"):
        return {"median": _finite(np.median(vals)), "p90": _finite(np.percentile(vals, 90))}


def _finite(values: Any) -> Any:
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0:
        return float(arr) if np.isfinite(arr) else None
    return [float(v) if np.isfinite(v) else None for v in arr]


def summarize_score(score: IdentificationScore, truth: FlexibleSpacecraftModel,
                    end_s: float, convergence_s: float) -> dict[str, Any]:
    """Scalar metrics of one score (JSON-able): VAF by horizon and output group,
    gain error before the first event and from 20 s after each, dominant-mode
    frequency error, unstable share, test error, held-out VAF, run time.

    Returns
    -------
    dict
        The score's numbers over the window, JSON-ready.
    """
    layout = truth.output_layout
    groups = {name: rows for name, rows in layout}
    out: dict[str, Any] = {"h_step_vaf": {
        str(h): {g: _finite(np.mean(v[rows])) for g, rows in groups.items()}
        for h, v in score.h_step_vaf.items()}}
    events = list(truth.scenario.event_times())
    if score.gain_track is not None:
        before = [(events[0] - 20.0, events[0])] if events else [(convergence_s, end_s)]
        after = [(ev + 20.0, nxt) for ev, nxt in zip(events, [*events[1:], end_s],
                                                     strict=False)]
        out["gain_error_before_event"] = _window_stats(score.gain_track, before)
        out["gain_error_after_events"] = _window_stats(score.gain_track,
                                                       after or [(convergence_s, end_s)])
        out["modal_error"] = _window_stats(score.modal_track, [(convergence_s, end_s)])
        scored = score.modal_track[score.modal_track[:, 0] >= convergence_s, 1]
        out["modal_error"]["max"] = _finite(np.max(scored)) if scored.size else None
        out["test_error_pct"] = {"attitude": _finite(score.test_error_pct[:3]),
                                 "rate": _finite(score.test_error_pct[3:6])}
        out["held_out_vaf"] = {g: _finite(np.mean(score.held_out_vaf[rows]))
                               for g, rows in groups.items()}
        out["unstable_share"] = _finite(score.unstable_share)
        out["time_s"] = score.time_s
        out["events_s"] = list(score.events)
    return out


#: Summaries where lower is better: a diverged seed ranks as +inf there (elsewhere, in the
#: VAFs, as -inf), so it always counts as the worst value.
_LOWER_IS_BETTER = frozenset({"test_error_pct"})


def _aggregate(per_seed: list[dict[str, Any]], worst: float = -np.inf) -> Any:
    """Median [min, max] over seeds of every numeric leaf; a diverged seed (None or
    non-finite) ranks as ``worst``."""
    first = per_seed[0]
    if isinstance(first, dict):
        return {k: _aggregate([s[k] for s in per_seed],
                              np.inf if k in _LOWER_IS_BETTER else worst)
                for k in first if k not in ("events_s",)}
    if isinstance(first, list):
        return [_aggregate([s[i] for s in per_seed], worst) for i in range(len(first))]
    vals = np.array([np.nan if v is None else v for v in per_seed], dtype=float)
    finite = vals[np.isfinite(vals)]
    if not finite.size:
        return {"median": None, "min": None, "max": None, "q25": None, "q75": None,
                "diverged": len(vals)}
    # a diverged seed counts as the worst value: it pulls the median and quartiles down
    # (the quartiles then take observed values, never an interpolation with -inf)
    ranked = np.where(np.isfinite(vals), vals, worst)
    finite_all = bool(np.all(np.isfinite(vals)))
    q25, q75 = (float(v) if np.isfinite(v) else None for v in np.percentile(
        ranked, [25, 75], method="linear" if finite_all else "inverted_cdf"))
    with np.errstate(invalid="ignore"):
        median = float(np.median(ranked))
    if not np.isfinite(median):      # most seeds diverged (strict JSON has no infinity)
        median = None
    return {"median": median, "min": float(finite.min()), "max": float(finite.max()),
            "q25": q25, "q75": q75, "diverged": int(len(vals) - finite.size)}


@functools.lru_cache(maxsize=4)
def _truth(scenario: str, n_modes: int) -> FlexibleSpacecraftModel:
    return FlexibleSpacecraftModel(ets8_parameters(n_modes), scenario=scenario)


def run_identification(scenario: str = "docking", seeds: int = 10,
                       out: str | Path = "results/identify", *,
                       methods: Sequence[str] | None = None, preset: str = "recommended",
                       snr_db: float | None = PAPER_SNR_DB, n_modes: int = 2, n_samples: int = 2500,
                       convergence_s: float = 150.0, progress: bool = True,
                       workers: int | None = None) -> dict[str, Any]:
    """Run the identification experiment and write its artefacts.

    Parameters
    ----------
    scenario : str
        Truth-model scenario (``"docking"``, ``"solar_rotation"``, ...).
    seeds : int
        Input and noise seeds 0 .. seeds-1.
    out : path
        Output directory.
    methods : sequence of str, optional
        Subset of :data:`METHODS` (default :data:`DEFAULT_METHODS`).
    preset : {"recommended", "paper"}
        The methods' settings.
    snr_db : float or None
        Measurement SNR per channel (paper: 40 dB); None for noiseless.
    n_modes : int
        Modes per appendage (order n = 2 (3 + 4 n_modes)).
    n_samples : int
        Record length (paper: 2500 = 250 s).
    convergence_s : float
        Start of the scored window (prediction, gain, modes), s.
    progress : bool
        Show a progress bar.
    workers : int, optional
        Processes that run the seeds side by side (default: one per core, at
        most one per seed); the numbers do not depend on it (each seed's
        record and identifiers are built from the seed alone).

    Returns
    -------
    dict
        The content of ``metrics.json``.
    """
    methods = list(methods or DEFAULT_METHODS)
    for name in methods:
        if name not in METHODS:
            raise ValueError(f"unknown method {name!r}; expected one of {sorted(METHODS)}")
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {PRESETS}, got {preset!r}")
    if seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    check_workers(workers)
    for name in methods:             # every value checked before any work
        _task_setup(name, scenario, None, n_modes, preset, n_samples, convergence_s)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    truth = _truth(scenario, n_modes)
    test = paper_test_response(truth, n_samples)
    rows = [*BASELINES, *methods]
    per_seed: dict[str, list[dict[str, Any]]] = {name: [] for name in rows}
    raw: dict[str, list[IdentificationScore]] = {name: [] for name in rows}
    task = partial(_identify_seed, scenario, n_modes, n_samples, snr_db, tuple(methods), preset,
                   convergence_s)
    with tqdm(total=seeds * len(methods), desc=f"identify {scenario}",
              disable=not progress) as bar:
        done = map_in_order(task, range(seeds), workers, lambda: bar.update(len(methods)))
    for seed in range(seeds):
        summaries, scores = done[seed]
        for name in rows:
            per_seed[name].append(summaries[name])
            raw[name].append(scores[name])
    metrics = {
        "scenario": scenario, "seeds": seeds, "snr_db": snr_db, "preset": preset,
        "order_n": truth.n, "n_samples": n_samples, "dt": truth.dt,
        "convergence_s": convergence_s, "horizons_samples": list(HORIZONS),
        "output_labels": list(truth.output_labels), "events_s": list(truth.scenario.event_times()),
        "methods": {name: {"summary": _aggregate(per_seed[name]), "per_seed": per_seed[name]}
                    for name in rows},
        "paper": PAPER_TABLES.get(scenario),
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    (out / "table.md").write_text(identification_table(metrics))
    seed0 = {name: raw[name][0] for name in methods}
    plot_prediction_horizons(out / "prediction.png", metrics, raw, truth.output_layout)
    plot_rigid_gain(out / "gain.png", truth, seed0, scenario)
    plot_identification_modal(out / "modal.png", truth, seed0, scenario)
    plot_identification_responses(out / "responses.png", *test,
                                  {n: s.models for n, s in seed0.items()}, scenario, truth.dt)
    return metrics


@single_threaded_blas
def _identify_seed(scenario: str, n_modes: int, n_samples: int, snr_db: float | None,
                   methods: tuple[str, ...], preset: str, convergence_s: float,
                   seed: int) -> tuple[dict[str, dict[str, Any]], dict[str, IdentificationScore]]:
    """One seed of :func:`run_identification`: the summaries of every row and the
    scores the figures need (all of seed 0's, only the prediction VAF of the others)."""
    truth = _truth(scenario, n_modes)
    test = paper_test_response(truth, n_samples)
    k_conv = round(convergence_s / truth.dt)
    end_s = n_samples * truth.dt
    record = identification_records(truth, seed, n_samples, snr_db)
    scores = _baselines(record, truth, k_conv, HORIZONS)
    for name in methods:
        scores[name] = score_identifier(make_identifier(name, truth, preset), record, truth,
                                        test, k_conv)
    summaries = {name: summarize_score(score, truth, end_s, convergence_s)
                 for name, score in scores.items()}
    if seed != 0:                       # keep only what the figures need
        scores = {name: IdentificationScore(score.h_step_vaf) for name, score in scores.items()}
    return summaries, scores


@functools.lru_cache(maxsize=8)
def _cached_records(scenario: str, n_modes: int, seed: int, n_samples: int,
                    snr_db: float | None) -> tuple[IdentificationRecord,
                                                   tuple[np.ndarray, np.ndarray]]:
    truth = _truth(scenario, n_modes)
    return (identification_records(truth, seed, n_samples, snr_db),
            paper_test_response(truth, n_samples))


def _scalar(metrics: dict[str, Any]) -> dict[str, Any]:
    """The flat scalar metrics a sweep tabulates."""
    flat: dict[str, Any] = {}
    for h, groups in metrics["h_step_vaf"].items():
        for g, v in groups.items():
            flat[f"vaf_h{h}_{g}"] = v
    for key in ("gain_error_before_event", "gain_error_after_events", "modal_error"):
        for stat, v in metrics.get(key, {}).items():
            flat[f"{key}_{stat}"] = v
    test = metrics.get("test_error_pct", {})
    for g in ("attitude", "rate"):
        vals = [v for v in test.get(g, []) if v is not None]
        flat[f"test_error_{g}_pct"] = float(np.mean(vals)) if len(vals) == 3 else None
    flat["unstable_share"] = metrics.get("unstable_share")
    for g, v in metrics.get("held_out_vaf", {}).items():
        flat[f"held_out_vaf_{g}"] = v
    return flat


def _task_setup(method: str, scenario: str, order: int | None, n_modes: int, preset: str,
                n_samples: int, convergence_s: float) -> tuple[FlexibleSpacecraftModel,
                                                               OnlineIdentifier]:
    """The truth model and the identifier of an identify task, with its values checked.

    Raises
    ------
    ValueError
        An unknown method, preset or scenario, an order that is not ``6 + 8 k``, or a
        scored window that starts before the identifier's warm-up ends or after the
        record does.
    """
    if order is not None:
        k, rem = divmod(int(order) - 6, 8)
        if rem or k < 1 or int(order) != order:
            raise ValueError(f"order must be 6 + 8 k for k >= 1 (14, 22, 30, 38, 46, ...), "
                             f"got {order!r}")
        n_modes = k
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    truth = _truth(scenario, int(n_modes))
    ident = make_identifier(method, truth, preset)
    warmup_s = ident.warmup * truth.dt
    end_s = int(n_samples) * truth.dt
    if not warmup_s <= convergence_s < end_s:
        raise ValueError(f"convergence_s = {convergence_s:g} s must lie between the end of "
                         f"the {method!r} identifier's warm-up ({warmup_s:g} s) and the end of "
                         f"the record ({end_s:g} s)")
    return truth, ident


def _check_identify(*, method: str, seed: int | None = None, scenario: str = "docking",
                    order: int | None = None, n_modes: int = 2, preset: str = "recommended",
                    snr_db: float | None = PAPER_SNR_DB, n_samples: int = 2500,
                    convergence_s: float = 150.0, baselines: bool = False) -> None:
    """:func:`identify_task`'s values checked without running it (a sweep file is checked
    with it before any task runs)."""
    if snr_db is not None:
        check_parameter("snr_db", snr_db)
    check_parameter("max_steps", n_samples, "n_samples")
    _task_setup(method, scenario, order, n_modes, preset, n_samples, convergence_s)


@single_threaded_blas
def identify_task(*, method: str, seed: int, scenario: str = "docking",
                  order: int | None = None, n_modes: int = 2, preset: str = "recommended",
                  snr_db: float | None = PAPER_SNR_DB, n_samples: int = 2500,
                  convergence_s: float = 150.0, baselines: bool = False) -> dict[str, Any]:
    """One identification run: one method on one seed (a sweep task).

    The result is a function of the arguments alone: bit-identical in any
    process and whatever the caller's BLAS threads (the whole task runs
    single-threaded). Records are cached per process, so tasks sharing a
    seed share the simulation.

    Parameters
    ----------
    method : str
        A key of :data:`METHODS`.
    seed : int
        Input and noise seed.
    order : int, optional
        System order n = 14, 22, 30, 38, 46, ... (``6 + 8 k``); overrides
        ``n_modes`` (k modes per appendage).
    preset : {"recommended", "paper"}
    baselines : bool
        Also score persistence and the frozen truth on the same record
        (prefixed ``persistence_`` and ``ceiling_``).

    Returns
    -------
    dict
        ``{"metrics": {...}, "timings": {"time_s": ...}}`` with the flat
        metrics of :func:`summarize_score` (``vaf_h{h}_{group}``,
        ``gain_error_*``, ``modal_error_*``, ``test_error_*_pct``,
        ``unstable_share``, ``held_out_vaf_*``) plus ``order_n``.
    """
    truth, ident = _task_setup(method, scenario, order, n_modes, preset, n_samples,
                               convergence_s)
    record, test = _cached_records(scenario, int(n_modes), int(seed), int(n_samples),
                                   None if snr_db is None else float(snr_db))
    k_conv = round(convergence_s / truth.dt)
    end_s = n_samples * truth.dt
    score = score_identifier(ident, record, truth, test, k_conv)
    metrics = {"order_n": truth.n, **_scalar(summarize_score(score, truth, end_s,
                                                             convergence_s))}
    if baselines:
        for name, base in _baselines(record, truth, k_conv, HORIZONS).items():
            prefix = "persistence_" if name == "persistence" else "ceiling_"
            for key, v in _scalar(summarize_score(base, truth, end_s, convergence_s)).items():
                if key.startswith("vaf_h"):
                    metrics[prefix + key] = v
    return {"metrics": metrics, "timings": {"time_s": score.time_s}}


identify_task.check_params = _check_identify      # type: ignore[attr-defined]
