"""The project's command line: ``spacecraft <command>``.

Commands
--------
``demo``
    Rendered rollout of a scenario (:func:`spacecraft_env.demo.run_demo`).
``identify``
    The paper's identification experiment for every method
    (:func:`identifiers.experiment.run_identification`).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

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

    ident = sub.add_parser("identify", help="the paper's identification experiment")
    ident.add_argument("--scenario", choices=sorted(SCENARIOS), default="docking")
    ident.add_argument("--seeds", type=int, default=10, help="noise seeds 0..N-1")
    ident.add_argument("--out", default="results/identify", help="output directory")
    ident.add_argument("--methods", nargs="+", default=None,
                       help="subset of: improved improved-apsa classical windowed-svd")
    ident.add_argument("--snr-db", type=_snr, default=40.0,
                       help="measurement SNR per channel in dB, or 'none' (paper: 40)")
    ident.add_argument("--modes", type=int, default=2, help="modes per appendage (n = 6 + 8 k)")
    ident.add_argument("--p", type=int, default=15, help="past window (paper: 15)")
    ident.add_argument("--forgetting", type=float, default=0.98, help="paper: 0.98")
    return parser


def _snr(text: str) -> float | None:
    return None if text.lower() == "none" else float(text)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``spacecraft`` console script."""
    args = build_parser().parse_args(argv)
    if args.command == "demo":
        from spacecraft_env.demo import run_demo

        summary = run_demo(args.scenario, args.out, seed=args.seed, steps=args.steps)
        print(json.dumps(summary, indent=2))
        print(f"wrote {args.out}/summary.json, response.png, rollout.gif, frame.png")
    elif args.command == "identify":
        from identifiers.experiment import run_identification

        metrics = run_identification(args.scenario, args.seeds, args.out, methods=args.methods,
                                     snr_db=args.snr_db, n_modes=args.modes, p=args.p,
                                     forgetting=args.forgetting)
        print((Path(args.out) / "table.md").read_text())
        print(f"wrote {args.out}/metrics.json, table.md, responses.png, modal.png "
              f"({len(metrics['methods'])} methods, {args.seeds} seeds)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
