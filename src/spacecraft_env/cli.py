"""The project's command line: ``spacecraft <command>``.

Commands
--------
``demo``
    Rendered rollout of a scenario (:func:`spacecraft_env.demo.run_demo`).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from spacecraft_env.scenarios import SCENARIOS

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with one sub-parser per command."""
    parser = argparse.ArgumentParser(prog="spacecraft", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="rendered rollout of a scenario")
    demo.add_argument("--scenario", choices=sorted(SCENARIOS), default="docking")
    demo.add_argument("--out", default="results/demo", help="output directory")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--steps", type=int, default=2500)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``spacecraft`` console script."""
    args = build_parser().parse_args(argv)
    if args.command == "demo":
        from spacecraft_env.demo import run_demo

        summary = run_demo(args.scenario, args.out, seed=args.seed, steps=args.steps)
        print(json.dumps(summary, indent=2))
        print(f"wrote {args.out}/summary.json, response.png, rollout.gif, frame.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
