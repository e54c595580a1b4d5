"""The ceiling check: no controller of the package below the ceiling, every scenario and task.

Every controller of ``spacecraft control`` (the fixed, robust and scheduled LQG,
PD, the adaptive loops, the same-law and output-feedback oracles) and the two
ceilings fly the same seeds of every registered scenario on both tasks. Printed
per condition: the ceiling's whole-episode cost (median over seeds) and, per
controller, the median and the smallest per-seed ratio of its whole-episode cost
to the ceiling's, and for the loops that fly the adaptive loop's start, the same
for the cost from the end of that start over the same-start ceiling's
(docs/design/evaluation.md). A ratio below 0.98 is a bug in the ceiling: the
script lists every one and exits with status 1. The full-state oracle reads the
true state, more than the ceiling knows: it is shown, not checked.

With ``--out FILE.json`` every per-seed cost is kept; ``--markdown FILE.json`` prints
the table of docs/results/control.md from such a file without flying anything.

Usage: ``python benchmarks/bench_ceiling.py [--seeds 10] [--scenarios ...] [--tasks ...]
[--controllers KEY ...] [--steps N] [--workers N] [--out results/ceiling.json]
[--markdown results/ceiling.json]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np

from controllers import LQRWeights, compare
from spacecraft_env import env_id
from spacecraft_lab.control import (
    CEILING,
    CONTROLLER_KEYS,
    CONTROLLER_NAMES,
    CONTROLLERS,
    SAME_START_CEILING,
    SCENARIO_NAMES,
)
from spacecraft_lab.reporting import flies_the_start

#: A controller whose cost is below this share of a ceiling's has beaten the ceiling.
TOLERANCE = 0.98
#: Controllers that know more than the ceiling (the true state): shown, not checked.
KNOWS_MORE = ("full-state oracle",)


def per_seed(table: dict, name: str, key: str) -> np.ndarray:
    return np.array([m[key] for m in table[name]["per_seed"]], dtype=float)


def check(table: dict) -> tuple[list[str], list[str]]:
    """The report's lines and the violations of one condition's comparison."""
    ceiling = per_seed(table, CEILING, "cost")
    start = per_seed(table, SAME_START_CEILING, "cost_after_start")
    lines, bad = [f"  ceiling {np.median(ceiling):.4g}"], []
    for name in table:
        if name in (CEILING, SAME_START_CEILING):
            continue
        whole = per_seed(table, name, "cost") / ceiling
        text = f"  {name:32s} whole {np.median(whole):6.3f} (least {whole.min():6.3f})"
        if name not in KNOWS_MORE and whole.min() < TOLERANCE:
            bad.append(f"{name}: whole episode {whole.min():.3f} of the ceiling")
        if flies_the_start(name):
            after = per_seed(table, name, "cost_after_start") / start
            text += f"  after start {np.median(after):6.3f} (least {after.min():6.3f})"
            if after.min() < TOLERANCE:
                bad.append(f"{name}: after the start {after.min():.3f} of the same-start "
                           "ceiling")
        lines.append(text)
    return lines, bad


#: The columns of the markdown table: controller, cost and the ceiling it is taken over.
COLUMNS = (("adaptive LQG", "cost", CEILING), ("adaptive LQG", "cost_after_start",
                                                 SAME_START_CEILING),
           ("robust LQG", "cost", CEILING), ("PD", "cost", CEILING),
           ("oracle LQG", "cost", CEILING))


def markdown(report: dict) -> str:
    """The table of a ``--out`` file: per condition the ceiling's whole-episode cost, the
    paired median ratios of :data:`COLUMNS`, and the least per-seed ratio of any checked
    controller to its ceiling (the check: at least 0.98)."""
    head = ("| condition | ceiling, whole episode | adaptive LQG / ceiling | adaptive LQG from "
            "40 s / same-start ceiling | robust LQG / ceiling | PD / ceiling "
            "| oracle LQG / ceiling | least ratio of any controller |")
    lines = [head, "|" + "---|" * 8]
    for condition, table in report["conditions"].items():
        def ratio(name: str, key: str, ref: str, tbl: dict = table) -> np.ndarray:
            return np.array(tbl[name][key]) / np.array(tbl[ref][key])
        cells = [f"{np.median(table[CEILING]['cost']):.4g}"]
        cells += [f"{np.median(ratio(name, key, ref)):.3f}" if name in table else "-"
                  for name, key, ref in COLUMNS]
        least = min(ratio(name, "cost", CEILING).min() for name in table
                    if name not in (CEILING, SAME_START_CEILING, *KNOWS_MORE))
        least = min(least, *(ratio(name, "cost_after_start", SAME_START_CEILING).min()
                             for name in table if flies_the_start(name)
                             and name != SAME_START_CEILING))
        lines.append(f"| {condition.replace('/', ', ')} | " + " | ".join(cells)
                     + f" | {least:.3f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--scenarios", nargs="+", default=sorted(SCENARIO_NAMES),
                        choices=sorted(SCENARIO_NAMES))
    parser.add_argument("--tasks", nargs="+", default=["slew", "regulation"],
                        choices=["slew", "regulation"])
    parser.add_argument("--controllers", nargs="+", default=None,
                        choices=sorted(CONTROLLER_KEYS),
                        help="keys of spacecraft control (default: its default comparison)")
    parser.add_argument("--steps", type=int, default=None,
                        help="episode length (default: the registered 2500)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=None, help="JSON of every figure")
    parser.add_argument("--markdown", type=Path, default=None,
                        help="print the markdown table of a --out file and stop")
    args = parser.parse_args(argv)
    if args.markdown is not None:
        print(markdown(json.loads(args.markdown.read_text())), end="")
        return 0
    factories = CONTROLLERS(LQRWeights())
    names = CONTROLLER_NAMES if args.controllers is None else \
        [CONTROLLER_KEYS[k] for k in args.controllers]
    chosen = {name: factories[name] for name in names
              if name not in (CEILING, SAME_START_CEILING)}
    chosen[SAME_START_CEILING] = factories[SAME_START_CEILING]
    chosen[CEILING] = factories[CEILING]
    report, violations = {}, []
    for scenario in args.scenarios:
        for task in args.tasks:
            kwargs = {"task": task}
            if args.steps is not None:
                kwargs["max_episode_steps"] = args.steps
            make_env = partial(gym.make, env_id(scenario), **kwargs)
            table, _ = compare(chosen, make_env, list(range(args.seeds)), progress=True,
                               workers=args.workers)
            lines, bad = check(table)
            print(f"{scenario}, {task}, {args.seeds} seeds:")
            print("\n".join(lines), flush=True)
            violations += [f"{scenario}, {task}: {b}" for b in bad]
            report[f"{scenario}/{task}"] = {
                name: {key: per_seed(table, name, key).tolist()
                       for key in ("cost", "cost_after_start", "cost_after_100s")}
                for name in table}
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"seeds": args.seeds, "steps": args.steps,
                                        "violations": violations, "conditions": report},
                                       indent=1))
    if violations:
        print("BEATEN:\n  " + "\n  ".join(violations))
        return 1
    print(f"no controller below {TOLERANCE} of a ceiling")
    return 0


if __name__ == "__main__":
    sys.exit(main())
