"""The fault table: every fault kind on paddle rotation and docking, and false alarms.

Each fault of :data:`FAULTS` strikes at 120 s of a 250 s episode (the default slew
task). Per fault and scenario, over the seeds: the adaptive LQG, the oracle LQG and the
robust design fly the faulted plant, the adaptive LQG also the fault-free one (the same
seeds); printed are the stable verdicts, the adaptive loop's cost from 60 s after the
onset (180 s) over its own fault-free cost and over the oracle's on the faulted plant
(the oracle knows the nominal plant, not the fault: a reference, not a bound), and
what the loop reported: the share of seeds with a fault declared for the struck
channel and the median delay from the onset. Then the false alarms: the faults the
adaptive loop declares on fault-free episodes of every registered scenario, and those
the loop on the fast identifier (the RL agents' base) declares on five times as many
family draws.

With ``--out FILE.json`` every per-seed figure is kept; ``--markdown FILE.json`` prints
the table of docs/results/control.md from such a file without flying anything;
``--only TEXT --extend FILE.json`` flies again only the faults whose label holds the text
and replaces their rows of that file (for a change that acts only on them).

Usage: ``python benchmarks/bench_faults.py [--seeds 5] [--alarm-seeds 10] [--workers N]
[--out results/faults.json] [--markdown results/faults.json] [--only TEXT --extend FILE]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from controllers import LQRWeights, compare, stage_costs
from spacecraft_env import ENV_IDS, env_id, parse_fault
from spacecraft_lab.control import CONTROLLERS, FAST, _make_env

#: Onset of every fault, s, and the start of the window judged after it.
ONSET_S = 120.0
JUDGED_FROM_S = ONSET_S + 60.0
#: One fault of each kind (the command line's form, ``spacecraft control --fault``).
FAULTS = {
    "wheel at 10 % (roll)": f"loss_of_effectiveness,onset={ONSET_S},axis=0,value=0.1",
    "wheel stuck at 0.2 N m (pitch)": f"stuck_actuator,onset={ONSET_S},axis=1,value=0.2",
    "wheel bias 0.05 N m (yaw)": f"actuator_bias,onset={ONSET_S},axis=2,value=0.05",
    "star tracker out for 10 s": f"sensor_dropout,onset={ONSET_S},duration=10,group=attitude",
    "star tracker frozen for 10 s": f"stuck_sensor,onset={ONSET_S},duration=10,group=attitude",
    "gyro bias 0.01 deg/s (roll)": f"sensor_bias,onset={ONSET_S},group=rate,axis=0,"
                                   "value=1.745e-4",
    "gyro noise burst 10 s": f"noise_burst,onset={ONSET_S},duration=10,group=rate,value=1e-4",
}
#: The controllers flown on each faulted plant.
FLOWN = ("adaptive LQG", "oracle LQG", "robust LQG")
SCENARIOS = ("paddle_rotation", "docking")
#: Family draws the fast identifier's loop flies fault-free, per ``--alarm-seeds``.
FAMILY_DRAWS_PER_SEED = 5


def _late_costs(runs: list, model: Any) -> list[float]:
    """Each trajectory's mean stage cost from :data:`JUDGED_FROM_S` (inf if it crashed),
    on the scenario's truth ``model`` (the faults strike the env, not the model)."""
    out = []
    for traj in runs:
        if traj.terminated or not np.isfinite(traj.states).all():
            out.append(float("inf"))
            continue
        cost = stage_costs(traj, model)[:, :4].sum(axis=1)
        out.append(float(cost[traj.time >= JUDGED_FROM_S].mean()))
    return out


def _declared(metrics: dict) -> list[dict]:
    return list(metrics["controller_stats"].get("faults", []))


def fly(seeds: int, alarm_seeds: int, workers: int, only: str | None = None,
        report: dict | None = None) -> dict:
    """Every figure of the table, per seed; with ``only``, the faults whose label holds it
    alone (no false alarms), replacing their rows of ``report``."""
    factories = CONTROLLERS(LQRWeights())
    if report is None:
        report = {"seeds": seeds, "alarm_seeds": alarm_seeds, "faults": {},
                  "false_alarms": {}}
    loop = {"adaptive LQG": factories["adaptive LQG"]}
    for scenario in SCENARIOS:
        clean_env = partial(_make_env, env_id(scenario), (), {})
        env = clean_env()
        model = env.unwrapped.model
        env.close()
        _, runs = compare(loop, clean_env, list(range(seeds)), progress=True,
                          workers=workers)
        clean = _late_costs(runs["adaptive LQG"], model)
        for label, spec in FAULTS.items():
            if only is not None and only not in label:
                continue
            fault = parse_fault(spec)
            make_env = partial(_make_env, env_id(scenario), (fault,), {})
            table, runs = compare({name: factories[name] for name in FLOWN}, make_env,
                                  list(range(seeds)), progress=True, workers=workers)
            row = {"clean": clean}
            for name in FLOWN:
                row[name] = {
                    "late": _late_costs(runs[name], model),
                    "stable": [m["verdict"] == "stable" for m in table[name]["per_seed"]],
                    "verdict": [m["verdict"] for m in table[name]["per_seed"]]}
            row["declared"] = [_declared(m) for m in table["adaptive LQG"]["per_seed"]]
            report["faults"][f"{scenario}/{label}"] = row
            print(f"{scenario}, {label}: " + summary(row), flush=True)
    if only is not None:
        return report
    for scenario in sorted(ENV_IDS.values()):
        make_env = partial(_make_env, env_id(scenario), (), {})
        table, _ = compare(loop, make_env, list(range(alarm_seeds)), progress=True,
                           workers=workers)
        report["false_alarms"][scenario] = [_declared(m)
                                            for m in table["adaptive LQG"]["per_seed"]]
        alarms = sum(len(d) for d in report["false_alarms"][scenario])
        print(f"fault-free {scenario}, {alarm_seeds} seeds: {alarms} declared", flush=True)
    # the fast identifier's loop (the RL agents' base and comparator) on many family
    # draws: its slews command several N m through wheels and inertias off the nominal
    draws = FAMILY_DRAWS_PER_SEED * alarm_seeds
    make_env = partial(_make_env, env_id("family"), (), {})
    table, _ = compare({FAST: factories[FAST]}, make_env, list(range(draws)), progress=True,
                       workers=workers)
    report["false_alarms_fast_family"] = [_declared(m) for m in table[FAST]["per_seed"]]
    alarms = sum(len(d) for d in report["false_alarms_fast_family"])
    print(f"fault-free family, {FAST}, {draws} draws: {alarms} declared", flush=True)
    return report


def _paired(a: list[float], b: list[float]) -> float:
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.median(np.asarray(a) / np.asarray(b)))


def _detection(row: dict) -> tuple[int, float]:
    """Seeds whose loop declared a fault, and the median delay from the onset, s."""
    delays = [min(f["detected_s"] for f in d) - ONSET_S for d in row["declared"] if d]
    return len(delays), (float(np.median(delays)) if delays else float("nan"))


def summary(row: dict) -> str:
    n = len(row["clean"])
    found, delay = _detection(row)
    stable = {name: sum(row[name]["stable"]) for name in FLOWN}
    late = row["adaptive LQG"]["late"]
    return (f"stable {stable['adaptive LQG']}/{n} (oracle {stable['oracle LQG']}, robust "
            f"{stable['robust LQG']}); from {JUDGED_FROM_S:g} s "
            f"{_paired(late, row['clean']):.3g}x fault-free, "
            f"{_paired(late, row['oracle LQG']['late']):.3g}x the oracle; declared {found}/{n}"
            + (f", {delay:.1f} s after the onset" if found else ""))


def markdown(report: dict) -> str:
    """The table of a ``--out`` file."""
    lines = ["| scenario | fault | stable (adaptive / oracle / robust) | adaptive from 180 s / "
             "fault-free | adaptive / oracle from 180 s | robust / oracle from 180 s "
             "| declared | delay (s) |", "|" + "---|" * 8]
    for key, row in report["faults"].items():
        scenario, label = key.split("/", 1)
        n = len(row["clean"])
        found, delay = _detection(row)
        stable = " / ".join(str(sum(row[name]["stable"])) for name in FLOWN)
        kinds = sorted({f["kind"] for d in row["declared"] for f in d})
        lines.append(
            f"| {scenario} | {label} | {stable} (of {n}) | "
            f"{_paired(row['adaptive LQG']['late'], row['clean']):.3g} | "
            f"{_paired(row['adaptive LQG']['late'], row['oracle LQG']['late']):.3g} | "
            f"{_paired(row['robust LQG']['late'], row['oracle LQG']['late']):.3g} | "
            f"{found}/{n}" + (f" ({', '.join(kinds)})" if kinds else "") + " | "
            + (f"{delay:.1f}" if found else "-") + " |")
    alarms = ", ".join(f"{scenario} {sum(len(d) for d in declared)}"
                       for scenario, declared in report["false_alarms"].items())
    lines.append("")
    lines.append(f"Faults declared on fault-free episodes ({report['alarm_seeds']} seeds "
                 f"each): {alarms}.")
    fast = report.get("false_alarms_fast_family")
    if fast is not None:
        lines.append("")
        lines.append(f"Faults declared by the {FAST} on {len(fast)} fault-free family draws: "
                     f"{sum(len(d) for d in fast)}.")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--alarm-seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=None, help="JSON of every figure")
    parser.add_argument("--markdown", type=Path, default=None,
                        help="print the markdown table of a --out file and stop")
    parser.add_argument("--only", default=None,
                        help="fly only the faults whose label holds this text (no false "
                             "alarms); with --extend, replace their rows of that file")
    parser.add_argument("--extend", type=Path, default=None,
                        help="a --out file whose other rows and false alarms are kept")
    args = parser.parse_args(argv)
    if args.markdown is not None:
        print(markdown(json.loads(args.markdown.read_text())), end="")
        return 0
    if args.extend is not None and args.only is None:
        parser.error("--extend replaces the rows of --only")
    old = None if args.extend is None else json.loads(args.extend.read_text())
    if old is not None and old["seeds"] != args.seeds:
        parser.error(f"{args.extend} holds {old['seeds']} seeds, not {args.seeds}")
    report = fly(args.seeds, args.alarm_seeds, args.workers, args.only, old)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))
    print(markdown(report), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
