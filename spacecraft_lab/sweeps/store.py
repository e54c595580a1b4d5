"""The append-only result file of a sweep: one JSON line per finished task.

Only the driver process writes, one whole line per ``write`` followed by a
flush and ``fsync``, so after an interruption the file holds every task that
finished and at most one truncated last line, which :meth:`ResultStore.load`
skips (and the next append starts on a fresh line); :meth:`ResultStore.repair`,
called when a sweep starts, moves such lines to ``<name>.torn`` so the file
is clean again. When a task appears more than once (retried after an
error), the last record wins.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["ResultStore"]


class ResultStore:
    """``results.jsonl`` of a sweep directory.

    Parameters
    ----------
    path : path
        The JSON-lines file (created on first append).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        """Every complete record in file order (a truncated line is skipped
        with a warning)."""
        if not self.path.exists():
            return
        with open(self.path, encoding="utf-8") as fh:
            for lineno, line in enumerate(fh, 1):
                if not line.strip():
                    continue
                try:
                    record = json.loads(line)
                except json.JSONDecodeError:
                    warnings.warn(f"{self.path}:{lineno}: skipping an incomplete record "
                                  "(interrupted write)", RuntimeWarning, stacklevel=2)
                    continue
                if isinstance(record, dict) and "task_id" in record:
                    yield record

    def load(self) -> dict[str, dict[str, Any]]:
        """Task id -> its last record."""
        return {r["task_id"]: r for r in self}

    def repair(self) -> int:
        """Move incomplete lines to ``<file>.torn``; returns how many.

        The rewrite goes through a temporary file and an atomic rename, so
        an interruption here loses nothing.
        """
        if not self.path.exists():
            return 0
        good, torn = [], []
        with open(self.path, encoding="utf-8") as fh:
            for line in fh:
                if not line.strip():
                    continue
                try:
                    json.loads(line)
                    good.append(line if line.endswith("\n") else line + "\n")
                except json.JSONDecodeError:
                    torn.append(line.rstrip("\n") + "\n")
        if torn:
            with open(self.path.with_name(self.path.name + ".torn"), "a",
                      encoding="utf-8") as fh:
                fh.writelines(torn)
            tmp = self.path.with_name(self.path.name + ".tmp")
            with open(tmp, "w", encoding="utf-8") as fh:
                fh.writelines(good)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
            warnings.warn(f"{self.path}: moved {len(torn)} incomplete record(s) of an "
                          f"interrupted run to {self.path.name}.torn", RuntimeWarning,
                          stacklevel=2)
        return len(torn)

    def append(self, record: dict[str, Any]) -> None:
        """Write one record as one line, durably.

        Raises
        ------
        ValueError
            If the record is not strict JSON (NaN/inf must be None already).
        """
        line = json.dumps(record, allow_nan=False, separators=(",", ":")) + "\n"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.path, "a+b") as fh:
            fh.seek(0, os.SEEK_END)
            if fh.tell() > 0:
                fh.seek(-1, os.SEEK_END)
                if fh.read(1) != b"\n":  # a previous run died mid-line
                    fh.write(b"\n")
            fh.write(line.encode("utf-8"))
            fh.flush()
            os.fsync(fh.fileno())
