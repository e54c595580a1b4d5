"""Where the default identifier's update spends its time: microseconds per update, by part.

Runs the default (rigid-flexible) identifier over the same 2500-sample record as
``bench_identifiers.py`` (docking, 40 dB, n = 22), once plain (best of
``--repeats``) and once with a timer around each part, and prints, in one run:

* the plain update (us) beside the bare recursive least squares of the
  improved RPBSID's VARX size (``bench_identifiers.bare_rls_seconds``: the floor
  any RPBSID update pays) and their ratio, and the 250 s record's multiple of
  real time;
* the per-part table from the timed run (each part's outermost calls only;
  the timers add their own overhead, so the parts sum to more than the plain
  figure): the base class's screening, the data monitor and the health checks,
  the state filter, the filter bank's signals, the gains' regressions, the
  modal tracker, the change test, the export, and the batch mode searches and
  rebuilds (with their replays) amortized over the record.

With ``--behaviours`` it prints instead what each of the identifier's behaviours
costs: the default's update beside variants that each switch one off (the re-searches
of the modes after the warm-up's, the modal tracker, the change test, an export and a
refinement every 20 samples instead of 10) and beside the closed-loop settings
(``identifiers.CLOSED_LOOP_SETTINGS``), each the best of ``--repeats`` rounds that
time the bare RLS and every variant in turn, so that a slow stretch of the machine
weighs on all of them alike.

Usage: ``python benchmarks/bench_identifier_parts.py [--repeats 5] [--behaviours]
[--json out.json]``
"""

from __future__ import annotations

import argparse
import functools
import json
import time
from collections import defaultdict
from collections.abc import Callable

import numpy as np
from bench_identifiers import bare_rls_seconds

import identifiers.core.change_detection as change_detection
import identifiers.core.data_monitor as data_monitor
import identifiers.core.kalman as kalman
import identifiers.modal.modal_tracker as modal_tracker
import identifiers.modal.rigid_flexible as rigid_flexible
from identifiers import CLOSED_LOOP_SETTINGS, add_measurement_noise, identification_inputs
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import FlexibleSpacecraftModel, ets8_parameters
from spacecraft_lab.identification import make_identifier

N_SAMPLES = 2500


def record(n: int = 22) -> tuple[FlexibleSpacecraftModel, np.ndarray, np.ndarray]:
    """bench_identifiers.py's record: docking, identification inputs, 40 dB."""
    truth = FlexibleSpacecraftModel(ets8_parameters((n // 2 - 3) // 4), scenario="docking")
    rng = np.random.default_rng(0)
    u = identification_inputs(N_SAMPLES, rng)
    return truth, u, add_measurement_noise(truth.simulate(u)[1], 40.0, rng)


#: The variants of ``--behaviours``: label -> overrides of the default's settings.
BEHAVIOURS = {
    "default": {},
    "no re-search after the warm-up's": {"rediscover": None},
    "no modal tracker": {"track_modes": False},
    "no change test": {"detect_changes": False},
    "export and refinement every 20 samples": {"refresh": 20},
    "closed-loop settings": dict(CLOSED_LOOP_SETTINGS),
}


def record_seconds(truth, u, y, **overrides) -> float:
    """Wall time of a new default identifier (its settings overridden by ``overrides``)
    over the record ``(u, y)``, single-threaded BLAS."""
    ident = make_identifier("rigid-flexible", truth, "recommended", **overrides)
    with single_threaded_blas:
        start = time.perf_counter()
        for k in range(len(u)):
            ident.update(u[k], y[k])
        return time.perf_counter() - start


def behaviours(truth, u, y, repeats: int) -> tuple[float, dict[str, float]]:
    """The bare RLS's and each variant's seconds per record ``(u, y)``, best of ``repeats``
    rounds."""
    bare, best = np.inf, dict.fromkeys(BEHAVIOURS, np.inf)
    bare_rls_seconds(195, 10, n_samples=10, repeats=1)    # its compiled kernel loaded, untimed
    for _ in range(repeats):
        with single_threaded_blas:
            bare = min(bare, bare_rls_seconds(195, 10, n_samples=len(u), repeats=1))
        for label, overrides in BEHAVIOURS.items():
            best[label] = min(best[label], record_seconds(truth, u, y, **overrides))
    return bare, best


def plain_seconds(truth, u, y, repeats: int) -> float:
    return min(record_seconds(truth, u, y) for _ in range(repeats))


class _Timers:
    """Wall time of the outermost calls of each wrapped method, by label and by the
    context (live sample, batch search, rebuild) it ran in."""

    def __init__(self) -> None:
        self.seconds: dict[tuple[str, str], float] = defaultdict(float)
        self._context = "live"
        self._depth: dict[str, int] = defaultdict(int)
        self._undo: list[Callable[[], None]] = []

    def wrap(self, owner: type, name: str, label: str, context: str | None = None) -> None:
        original = vars(owner)[name]

        @functools.wraps(original)
        def timed(*args, **kwargs):
            outer = self._context
            self._context = context or outer
            self._depth[label] += 1
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                if self._depth[label] == 1:
                    self.seconds[outer, label] += time.perf_counter() - start
                self._depth[label] -= 1
                self._context = outer

        setattr(owner, name, timed)
        self._undo.append(lambda: setattr(owner, name, original))

    def restore(self) -> None:
        for undo in reversed(self._undo):
            undo()

    def live(self, label: str) -> float:
        return self.seconds["live", label]

    def anywhere(self, label: str) -> float:
        return sum(v for (_, lab), v in self.seconds.items() if lab == label)


def parts(truth, u, y) -> list[tuple[str, float]]:
    """The per-part table, us per update."""
    rf = ob = rigid_flexible.RigidFlexibleIdentifier
    timers = _Timers()
    for owner, name, label, context in (
            (ob, "update", "update", None), (ob, "_validate", "validate", None),
            (rf, "_admissible", "guard", None), (ob, "_check_health", "health", None),
            (data_monitor.DataMonitor, "observe", "monitor", None),
            (rf, "_step", "step", None), (rf, "_sample", "sample", None),
            (rf, "_find_resonators", "search", "search"), (rf, "_rebuild", "rebuild", "rebuild"),
            (rf, "_maybe_rediscover", "rediscover", None),
            (kalman.KalmanPredictor, "update", "filter", None),
            (rf, "_process_noise", "filter", None), (rf, "_measurement_noise", "filter", None),
            (rf, "_learn", "regressions", None),
            (change_detection.RegressionGLR, "update", "change test", None),
            (modal_tracker.ModalTracker, "update", "tracker moments", None),
            (rf, "_refine_modes", "tracker refine", None), (rf, "_export", "export", None)):
        # the class of the identifier's MRO (the identifier, its parts, the base class)
        # that defines the method
        definer = next((c for c in owner.__mro__ if name in vars(c)), None)
        if definer is not None:
            timers.wrap(definer, name, label, context)
    try:
        with single_threaded_blas:
            ident = make_identifier("rigid-flexible", truth, "recommended")
            for k in range(N_SAMPLES):
                ident.update(u[k], y[k])
    finally:
        timers.restore()
    live = timers.live
    inner = ("filter", "regressions", "change test", "tracker moments", "tracker refine",
             "export")
    rows = [
        ("input validation", live("validate")),
        ("outlier guard", live("guard")),
        ("data monitor", live("monitor")),
        ("health checks (every 100 samples)", live("health")),
        ("base class, the rest (scaling, screening, counters)",
         live("update") - live("step") - live("validate") - live("guard") - live("health")
         - live("monitor")),
        ("state filter (Kalman filter, process and sensor noise)", live("filter")),
        ("gains' regressions (3 sensor groups)", live("regressions")),
        ("modal tracker: moments", live("tracker moments")),
        ("modal tracker: refine (every 10 samples)", live("tracker refine")),
        ("change test", live("change test")),
        ("model export (every 10 samples)", live("export")),
        ("filter bank signals and the rest of a sample",
         live("sample") - live("rediscover") - sum(live(p) for p in inner)),
        ("batch mode searches (warm-up and re-searches)", timers.anywhere("search")),
        ("rebuilds, with the replay of the kept record", timers.anywhere("rebuild")),
    ]
    return [(name, 1e6 * seconds / N_SAMPLES) for name, seconds in rows]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--behaviours", action="store_true",
                        help="what each behaviour costs instead of the per-part table")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    truth, u, y = record()
    if args.behaviours:
        bare, best = behaviours(truth, u, y, args.repeats)
        print(f"us per update, best of {args.repeats} rounds; bare RLS (195 regressors, "
              f"10 outputs) {1e6 * bare / N_SAMPLES:.1f} us; bars: 5x the bare RLS, 1000x "
              "real time")
        width = max(map(len, best))
        print(f"  {'variant':<{width}}  {'us':>7}  {'/ bare':>6}  {'x real time':>11}")
        for label, seconds in best.items():
            print(f"  {label:<{width}}  {1e6 * seconds / N_SAMPLES:7.1f}  "
                  f"{seconds / bare:6.2f}  {250 / seconds:11.0f}")
        if args.json:
            with open(args.json, "w") as fh:
                json.dump({"bare_us": 1e6 * bare / N_SAMPLES,
                           "us": {k: 1e6 * v / N_SAMPLES for k, v in best.items()}}, fh, indent=2)
        return
    plain = plain_seconds(truth, u, y, args.repeats)
    bare = bare_rls_seconds(195, 10) / N_SAMPLES
    table = parts(truth, u, y)
    per_update = plain / N_SAMPLES
    print(f"default identifier: {1e6 * per_update:.0f} us per update; bare RLS of the improved "
          f"RPBSID's size (195 regressors, 10 outputs): {1e6 * bare:.1f} us; ratio "
          f"{per_update / bare:.1f} (bar 5); a 250 s record in {plain:.2f} s = "
          f"{250 / plain:.0f}x real time (bar 1000x)")
    print("\nper part, us per update (timed run; the timers add overhead):")
    width = max(len(name) for name, _ in table)
    for name, us in table:
        print(f"  {name:<{width}}  {us:7.1f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"plain_us": 1e6 * per_update, "bare_us": 1e6 * bare,
                       "parts_us": dict(table)}, fh, indent=2)


if __name__ == "__main__":
    main()
