"""A Monte-Carlo sweep from Python: controllers x paddle angles x seeds, resumable.

The same grid as a TOML file runs with ``spacecraft sweep --config FILE``
(docs/sweeps.md); results land in ``OUT/results.jsonl`` (one record per task,
so an interrupted sweep resumes) with summary tables.

    python examples/sweep.py [--seeds 3] [--steps 1500] [--out results/example-sweep]
"""

import argparse
import json
from pathlib import Path

from spacecraft_lab.sweeps import run_sweep

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--seeds", type=int, default=3)
parser.add_argument("--steps", type=int, default=1500, help="episode length, env steps")
parser.add_argument("--out", default="results/example-sweep")
parser.add_argument("--backend", default="local", choices=("local", "serial", "ray"))
args = parser.parse_args()

out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
config = out / "sweep.toml"
config.write_text(f"""
name = "paddle-angle"
description = "Fixed and adaptive LQG across paddle angles"
task = "control"
seeds = {args.seeds}

[params]
scenario = "constant"
max_steps = {args.steps}

[grid]
controller = ["fixed-lqg", "adaptive-lqg"]
paddle_angle = [0.0, 120.0]

[summary]
rows = "controller"
columns = "paddle_angle"
metrics = ["cost_after_100s", "attitude_rms_deg"]
""")
report = run_sweep(config, out, backend=args.backend, progress=False)
print(f"{report.ok} tasks ran, {report.errors} failed, in {report.wall_s:.0f} s")
records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
print(f"{len(records)} records in {out / 'results.jsonl'}; summary tables in {out}")
