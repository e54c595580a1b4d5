"""The ceiling check: no controller of the package below the ceiling, every scenario and task.

Every controller of ``spacecraft control`` (the fixed, robust and scheduled LQG,
PD, the adaptive loops, the same-law and output-feedback oracles) and the two
ceilings fly the same seeds of every registered scenario on both tasks. Printed
per condition: the ceiling's whole-episode cost (median over seeds) and, per
controller, the median and the smallest per-seed ratio of its whole-episode cost
to the ceiling's, for the loops that fly the adaptive loop's start, the same
for the cost from the end of that start over the same-start ceiling's, and for
every controller (the other ceilings included) the cost from 100 s over the
window ceiling's (docs/design/evaluation.md). A ratio below 0.98 is a bug in the ceiling: the
script lists every one and exits with status 1. The full-state oracle reads the
true state, more than the ceiling knows: it is shown, not checked.

With ``--out FILE.json`` every per-seed cost is kept; ``--markdown FILE.json`` prints
the table of docs/results/control.md from such a file without flying anything;
``--extend FILE.json`` reads such a file and flies only the controllers it lacks (the
same seeds and steps), checking and writing the merged figures.

Usage: ``python benchmarks/bench_ceiling.py [--seeds 10] [--scenarios ...] [--tasks ...]
[--controllers KEY ...] [--steps N] [--workers N] [--out results/ceiling.json]
[--extend results/ceiling.json] [--markdown results/ceiling.json]``
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
    WINDOW_CEILING,
)
from spacecraft_lab.reporting import flies_the_start

#: A controller whose cost is below this share of a ceiling's has beaten the ceiling.
TOLERANCE = 0.98
#: Controllers that know more than the ceiling (the true state): shown, not checked.
KNOWS_MORE = ("full-state oracle",)


#: The costs kept per controller and seed.
KEYS = ("cost", "cost_after_start", "cost_after_100s")


def per_seed(table: dict, name: str, key: str) -> np.ndarray:
    return np.array(table[name][key], dtype=float)


def check(table: dict) -> tuple[list[str], list[str]]:
    """The report's lines and the violations of one condition's comparison (controller ->
    key of :data:`KEYS` -> per-seed costs)."""
    ceiling = per_seed(table, CEILING, "cost")
    start = per_seed(table, SAME_START_CEILING, "cost_after_start")
    window = per_seed(table, WINDOW_CEILING, "cost_after_100s")
    lines, bad = [f"  ceiling {np.median(ceiling):.4g}, window ceiling from 100 s "
                  f"{np.median(window):.4g}"], []
    for name in table:
        if name == WINDOW_CEILING:
            continue
        stationary = per_seed(table, name, "cost_after_100s") / window
        text = f"  {name:32s} from 100 s {np.median(stationary):8.4g} (least " \
               f"{stationary.min():8.4g})"
        if name not in KNOWS_MORE and stationary.min() < TOLERANCE:
            bad.append(f"{name}: from 100 s {stationary.min():.3f} of the window ceiling")
        if name in (CEILING, SAME_START_CEILING):
            lines.append(text)
            continue
        whole = per_seed(table, name, "cost") / ceiling
        text += f"  whole {np.median(whole):6.3f} (least {whole.min():6.3f})"
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
           ("adaptive LQG", "cost_after_100s", WINDOW_CEILING),
           ("ceiling", "cost_after_100s", WINDOW_CEILING),
           ("robust LQG", "cost", CEILING), ("PD", "cost", CEILING),
           ("oracle LQG", "cost", CEILING))


def _ratio_text(value: float) -> str:
    """Three decimals up to 100, three significant digits beyond."""
    return f"{value:.3f}" if value < 100 else f"{value:.3g}"


def markdown(report: dict) -> str:
    """The table of a ``--out`` file: per condition the ceiling's whole-episode cost, the
    paired median ratios of :data:`COLUMNS`, and the least per-seed ratio of any checked
    controller to its ceiling (the check: at least 0.98)."""
    head = ("| condition | ceiling, whole episode | adaptive LQG / ceiling | adaptive LQG from "
            "40 s / same-start ceiling | adaptive LQG from 100 s / window ceiling | ceiling "
            "from 100 s / window ceiling | robust LQG / ceiling | PD / ceiling "
            "| oracle LQG / ceiling | least ratio of any controller |")
    lines = [head, "|" + "---|" * 10]
    for condition, table in report["conditions"].items():
        def ratio(name: str, key: str, ref: str, tbl: dict = table) -> np.ndarray:
            return np.array(tbl[name][key]) / np.array(tbl[ref][key])
        cells = [f"{np.median(table[CEILING]['cost']):.4g}"]
        cells += [_ratio_text(np.median(ratio(name, key, ref)))
                  if name in table and ref in table else "-" for name, key, ref in COLUMNS]
        # the least ratio of any checked controller to the ceiling of each window
        ratios = [ratio(name, "cost", CEILING).min() for name in table
                  if name not in (CEILING, SAME_START_CEILING, WINDOW_CEILING, *KNOWS_MORE)]
        if WINDOW_CEILING in table:
            ratios += [ratio(name, "cost_after_100s", WINDOW_CEILING).min() for name in table
                       if name not in (WINDOW_CEILING, *KNOWS_MORE)]
        ratios += [ratio(name, "cost_after_start", SAME_START_CEILING).min() for name in table
                   if flies_the_start(name) and name != SAME_START_CEILING]
        least = min(ratios)
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
    parser.add_argument("--extend", type=Path, default=None,
                        help="a --out file: fly only the controllers it lacks")
    args = parser.parse_args(argv)
    if args.markdown is not None:
        print(markdown(json.loads(args.markdown.read_text())), end="")
        return 0
    stored: dict = {}
    if args.extend is not None:
        old = json.loads(args.extend.read_text())
        if (old["seeds"], old["steps"]) != (args.seeds, args.steps):
            parser.error(f"--extend {args.extend} holds {old['seeds']} seeds of "
                         f"{old['steps']} steps, not {args.seeds} of {args.steps}")
        stored = old["conditions"]
    factories = CONTROLLERS(LQRWeights())
    names = CONTROLLER_NAMES if args.controllers is None else \
        [CONTROLLER_KEYS[k] for k in args.controllers]
    chosen = {name: factories[name] for name in names
              if name not in (CEILING, SAME_START_CEILING, WINDOW_CEILING)}
    chosen[WINDOW_CEILING] = factories[WINDOW_CEILING]
    chosen[SAME_START_CEILING] = factories[SAME_START_CEILING]
    chosen[CEILING] = factories[CEILING]
    report, violations = {}, []
    for scenario in args.scenarios:
        for task in args.tasks:
            kwargs = {"task": task}
            if args.steps is not None:
                kwargs["max_episode_steps"] = args.steps
            make_env = partial(gym.make, env_id(scenario), **kwargs)
            table = dict(stored.get(f"{scenario}/{task}", {}))
            missing = {name: f for name, f in chosen.items() if name not in table}
            if missing:
                flown, _ = compare(missing, make_env, list(range(args.seeds)), progress=True,
                                   workers=args.workers)
                table.update({name: {key: [m[key] for m in flown[name]["per_seed"]]
                                     for key in KEYS} for name in flown})
            lines, bad = check(table)
            print(f"{scenario}, {task}, {args.seeds} seeds:")
            print("\n".join(lines), flush=True)
            violations += [f"{scenario}, {task}: {b}" for b in bad]
            report[f"{scenario}/{task}"] = table
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
