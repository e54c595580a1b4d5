"""The results pages, written by the commands they show: ``make results`` and its short mode.

A results page (:data:`PAGES`) holds its tables in *blocks*: the lines between
:data:`BEGIN` and :data:`END`. A block opens with a ``bash`` fence of the commands that
produce its table; what follows the fence down to :data:`END` is written by this module,
never by hand: the table, rendered from the data the commands wrote, and the date it was
printed. The data live in the repository (:data:`DATA`), so the tables can be rendered
again without flying anything:

- ``make results`` (``python -m spacecraft_lab.results_pages --run``) runs every block's
  commands (hours: every figure of the pages), keeps what its table needs in
  :data:`DATA`, dates it and writes the pages;
- ``make results-short`` (no ``--run``; CI's short mode) renders every block again from
  :data:`DATA` and writes the pages; ``--check`` only says which blocks differ from what
  it would write (``tests/test_results_pages.py`` runs it).

What a block's table is rendered from depends on its last command:

=========================================  =============================================
``spacecraft control ... --out DIR``       :func:`spacecraft_lab.reporting.control_brief`
                                           of ``DIR/metrics.json`` (its figures the brief
                                           reads, kept in ``DATA/control/``)
``spacecraft evaluate ... --out DIR``      :func:`spacecraft_lab.agents.evaluation_table`
                                           of ``DIR/evaluation.json`` (kept in
                                           ``DATA/evaluate/``)
``spacecraft identify ... --out DIR``      :func:`spacecraft_lab.reporting.identification_table`
                                           of ``DIR/metrics.json`` (its summaries, kept in
                                           ``DATA/identify/``)
``python benchmarks/X.py ... --markdown F``  what that command prints (``F`` in :data:`DATA`)
=========================================  =============================================
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from spacecraft_lab.agents import evaluation_table
from spacecraft_lab.reporting import control_brief, identification_table

__all__ = ["BEGIN", "DATA", "END", "PAGES", "ROOT", "WHOLLY_WRITTEN", "Block", "blocks", "check",
           "main", "render", "write_pages"]

#: The repository's root (the commands run from it).
ROOT = Path(__file__).resolve().parent.parent
#: The pages whose tables are written here.
PAGES = ("docs/results/control.md", "docs/results/identification.md", "docs/results/rl.md")
#: The pages every table of which is written here (identification.md's tracking tables
#: are not yet: they combine several runs of ``benchmarks/bench_tracking.py``).
WHOLLY_WRITTEN = ("docs/results/control.md", "docs/results/rl.md")
#: Where the figures the tables are rendered from are kept (committed).
DATA = Path("docs/results/data")
#: The date each block's data were printed, by data file.
PRINTED = DATA / "printed.json"
#: A block's first and last lines.
BEGIN = "<!-- results: written by make results -->"
END = "<!-- /results -->"
_FENCE = re.compile(r"```bash\n(.*?)\n```\n", re.S)


@dataclass(frozen=True)
class Block:
    """One block of a page.

    Attributes
    ----------
    page : str
        The page, relative to :data:`ROOT`.
    commands : tuple of str
        The commands of its ``bash`` fence, in order.
    body : str
        What follows the fence down to :data:`END` (the written part).
    """

    page: str
    commands: tuple[str, ...]
    body: str

    @property
    def kind(self) -> str:
        """``"control"``, ``"evaluate"``, ``"identify"`` or ``"markdown"``: what renders
        the table."""
        argv = shlex.split(self.commands[-1])
        if argv[:2] == ["spacecraft", "control"]:
            return "control"
        if argv[:2] == ["spacecraft", "evaluate"]:
            return "evaluate"
        if argv[:2] == ["spacecraft", "identify"]:
            return "identify"
        if argv[0] == "python" and "--markdown" in argv:
            return "markdown"
        raise ValueError(f"{self.page}: a block's last command must be `spacecraft control "
                         f"... --out DIR` (or evaluate, identify) or `python "
                         f"benchmarks/X.py ... --markdown FILE`, got {self.commands[-1]!r}")

    @property
    def data(self) -> Path:
        """The data file its table is rendered from, relative to :data:`ROOT`."""
        argv = shlex.split(self.commands[-1])
        if self.kind == "markdown":
            path = Path(argv[argv.index("--markdown") + 1])
            if DATA not in path.parents:
                raise ValueError(f"{self.page}: {self.commands[-1]!r} must read its data "
                                 f"from {DATA}/")
            return path
        if "--out" not in argv:
            raise ValueError(f"{self.page}: {self.commands[-1]!r} needs --out DIR")
        out = Path(argv[argv.index("--out") + 1])
        return DATA / self.kind / ("-".join(out.parts[1:] or out.parts) + ".json")

    @property
    def output(self) -> Path:
        """The directory the last command writes (``control``, ``evaluate`` and
        ``identify``)."""
        argv = shlex.split(self.commands[-1])
        return Path(argv[argv.index("--out") + 1])


def blocks(page: str, text: str | None = None) -> list[Block]:
    """The blocks of ``page`` (relative to :data:`ROOT`), in order.

    Parameters
    ----------
    page : str
    text : str, optional
        The page's text (default: read from disk).

    Returns
    -------
    list of Block

    Raises
    ------
    ValueError
        If a block does not open with a ``bash`` fence or is not closed.
    """
    text = (ROOT / page).read_text() if text is None else text
    found = []
    for chunk in text.split(BEGIN + "\n")[1:]:
        if END not in chunk:
            raise ValueError(f"{page}: a block opened by {BEGIN!r} is not closed by {END!r}")
        inside = chunk.split(END, 1)[0]
        fence = _FENCE.match(inside)
        if fence is None:
            raise ValueError(f"{page}: a block must open with a ```bash fence of its commands")
        commands = tuple(line.strip() for line in fence.group(1).splitlines() if line.strip())
        found.append(Block(page, commands, inside[fence.end():]))
    return found


def _printed() -> dict[str, str]:
    path = ROOT / PRINTED
    return json.loads(path.read_text()) if path.exists() else {}


def render(block: Block) -> str:
    """The written part of ``block``, from its data: the table and the date printed.

    Returns
    -------
    str
        The text between the block's fence and :data:`END`.

    Raises
    ------
    FileNotFoundError
        If its data file is missing (``make results`` writes it).
    """
    data = ROOT / block.data
    if not data.exists():
        raise FileNotFoundError(f"{block.page}: no data for {block.commands[-1]!r} at "
                                f"{block.data}; `make results` runs it")
    if block.kind == "control":
        table = "```text\n" + control_brief(json.loads(data.read_text())["controllers"]) + "```"
    elif block.kind == "evaluate":
        table = evaluation_table(json.loads(data.read_text())).rstrip("\n")
    elif block.kind == "identify":
        table = identification_table(json.loads(data.read_text())).rstrip("\n")
    else:
        table = _run(block.commands[-1], capture=True).rstrip("\n")
    date = _printed().get(str(block.data), "an unrecorded date")
    return f"\n{table}\n\nPrinted {date} by the command above.\n"


def _run(command: str, capture: bool = False) -> str:
    """Run one documented command from :data:`ROOT` (``spacecraft`` and ``python`` are this
    interpreter's); its stdout when ``capture``."""
    argv = shlex.split(command)
    if argv[0] == "spacecraft":
        argv = [sys.executable, "-m", "spacecraft_lab.cli", *argv[1:]]
    elif argv[0] == "python":
        argv = [sys.executable, *argv[1:]]
    else:
        raise ValueError(f"a block's command must start with spacecraft or python: {command!r}")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)}
    done = subprocess.run(argv, cwd=ROOT, env=env, check=True, text=True,
                          stdout=subprocess.PIPE if capture else None)
    return done.stdout if capture else ""


def _keep(block: Block) -> None:
    """After a block's commands ran: what its table needs, into :data:`DATA`, dated."""
    if block.kind == "markdown":          # the command wrote its data file itself
        _date(block)
        return
    target = ROOT / block.data
    target.parent.mkdir(parents=True, exist_ok=True)
    if block.kind == "control":
        metrics = json.loads((ROOT / block.output / "metrics.json").read_text())
        keys = ("cost", "cost_after_start", "cost_after_100s")
        kept = {name: {"median": {k: row["median"][k]
                                  for k in (*keys, "fallback_share_after_60s")},
                       "per_seed": [{k: m[k] for k in keys} for m in row["per_seed"]],
                       "verdicts": row["verdicts"], "runs": row["runs"]}
                for name, row in metrics["controllers"].items()}
        target.write_text(json.dumps({"command": block.commands[-1], "scenario":
                                      metrics["scenario"], "controllers": kept}, indent=1) + "\n")
    elif block.kind == "evaluate":
        target.write_text((ROOT / block.output / "evaluation.json").read_text())
    elif block.kind == "identify":
        metrics = json.loads((ROOT / block.output / "metrics.json").read_text())
        for method in metrics["methods"].values():   # the tables read the summaries
            method.pop("per_seed", None)
        target.write_text(json.dumps(metrics, indent=1) + "\n")
    _date(block)


def _date(block: Block) -> None:
    """Record today as the date ``block``'s data were printed."""
    printed = _printed()
    printed[str(block.data)] = datetime.date.today().isoformat()
    (ROOT / PRINTED).write_text(json.dumps(dict(sorted(printed.items())), indent=1) + "\n")


def _rewrite(page: str, new_bodies: dict[int, str]) -> str:
    """``page``'s text with the written parts of the blocks numbered in ``new_bodies``."""
    text = (ROOT / page).read_text()
    head, *chunks = text.split(BEGIN + "\n")
    out = [head]
    for i, chunk in enumerate(chunks):
        inside, rest = chunk.split(END, 1)
        fence = _FENCE.match(inside)
        body = new_bodies.get(i, inside[fence.end():])
        out.append(inside[:fence.end()] + body + END + rest)
    return (BEGIN + "\n").join(out)


def write_pages(pages: Sequence[str] = PAGES, run: bool = False,
                only: str | None = None) -> list[str]:
    """Write the blocks of ``pages``: rendered from :data:`DATA`, after running their
    commands first when ``run``.

    Parameters
    ----------
    pages : sequence of str
    run : bool
        Run every block's commands (the full ``make results``) before rendering.
    only : str, optional
        Only the blocks whose commands contain this text.

    Returns
    -------
    list of str
        The blocks written, as ``page: last command``.
    """
    written = []
    for page in pages:
        bodies = {}
        for i, block in enumerate(blocks(page)):
            if only is not None and not any(only in c for c in block.commands):
                continue
            if run:
                print(f"{page}: {len(block.commands)} command(s) of block {i + 1}", flush=True)
                # a block's --markdown command is its rendering: run once, by render()
                flown = block.commands[:-1] if block.kind == "markdown" else block.commands
                for command in flown:
                    print(f"  $ {command}", flush=True)
                    _run(command)
                _keep(block)
            bodies[i] = render(block)
            written.append(f"{page}: {block.commands[-1]}")
        (ROOT / page).write_text(_rewrite(page, bodies))
    return written


def check(pages: Sequence[str] = PAGES) -> list[str]:
    """The blocks whose written part is not what :func:`render` writes from :data:`DATA`.

    Returns
    -------
    list of str
        ``page: last command`` per differing block (empty: the pages are their data's).
    """
    return [f"{block.page}: {block.commands[-1]}" for page in pages for block in blocks(page)
            if block.body != render(block)]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m spacecraft_lab.results_pages [--run] [--only TEXT] [--check]``.

    Returns
    -------
    int
        0, or 1 when ``--check`` finds a block that differs.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", action="store_true",
                        help="run every block's commands first (hours), then write")
    parser.add_argument("--only", default=None,
                        help="only the blocks whose commands contain this text")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; list the blocks that differ from their data")
    args = parser.parse_args(argv)
    if args.check:
        stale = check()
        for line in stale:
            print(f"differs from its data: {line}")
        return 1 if stale else 0
    for line in write_pages(run=args.run, only=args.only):
        print(f"wrote {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
