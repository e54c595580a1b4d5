"""The append-only result file of a sweep: one JSON line per finished task.

Only the driver process writes (the output directory is locked while a
sweep runs, see :mod:`spacecraft_lab.sweeps.runner`), one whole line per
``write`` followed by a flush and ``fsync``, so after an interruption the
file holds every task that finished and at most one truncated last line,
which :meth:`ResultStore.load` skips (and the next append starts on a fresh
line). Any line that is not a complete record (:func:`parse_record`: torn,
bad bytes, missing fields) is treated the same way, and
:meth:`ResultStore.repair`, called when a sweep starts, moves such lines to
``<name>.torn`` so the file is clean again. When a task appears more than
once (retried after an error), the last record wins.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["ResultStore", "parse_record"]


def parse_record(line: bytes) -> dict[str, Any] | None:
    """The record on one line of ``results.jsonl``, or None if the line is not one.

    A line counts as a record only if it is valid UTF-8 and JSON, and holds
    a ``task_id``, a ``kind``, a ``params`` table and a ``status`` of
    ``"ok"`` (with a ``metrics`` table) or ``"error"``. Anything else (a
    line torn by an interrupted write, a bad byte, a hand-edited entry) is
    not a finished task.
    """
    try:
        record = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not (isinstance(record, dict) and isinstance(record.get("task_id"), str)
            and isinstance(record.get("kind"), str) and isinstance(record.get("params"), dict)):
        return None
    status = record.get("status")
    if status == "ok" and isinstance(record.get("metrics"), dict):
        return record
    if status == "error":
        return record
    return None


class ResultStore:
    """``results.jsonl`` of a sweep directory.

    Parameters
    ----------
    path : path
        The JSON-lines file (created on first append).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def _lines(self) -> Iterator[tuple[int, bytes]]:
        if not self.path.exists():
            return
        with open(self.path, "rb") as fh:
            for lineno, line in enumerate(fh, 1):
                if line.strip():
                    yield lineno, line

    def __iter__(self) -> Iterator[dict[str, Any]]:
        """Every complete record in file order; anything else (see
        :func:`parse_record`) is skipped with a warning."""
        for lineno, line in self._lines():
            record = parse_record(line)
            if record is None:
                warnings.warn(f"{self.path}:{lineno}: skipping an incomplete record "
                              "(interrupted write or corrupt entry)", RuntimeWarning,
                              stacklevel=2)
                continue
            yield record

    def load(self) -> dict[str, dict[str, Any]]:
        """Task id -> its last record."""
        return {r["task_id"]: r for r in self}

    def repair(self) -> int:
        """Move every line that is not a complete record to ``<file>.torn``.

        Returns how many. The rewrite goes through a temporary file and an
        atomic rename, so an interruption here loses nothing.
        """
        good, torn = [], []
        for _, line in self._lines():
            if parse_record(line) is None:
                torn.append(line.rstrip(b"\n") + b"\n")
            else:
                good.append(line if line.endswith(b"\n") else line + b"\n")
        if torn:
            with open(self.path.with_name(self.path.name + ".torn"), "ab") as fh:
                fh.writelines(torn)
            tmp = self.path.with_name(self.path.name + ".tmp")
            with open(tmp, "wb") as fh:
                fh.writelines(good)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
            warnings.warn(f"{self.path}: moved {len(torn)} incomplete record(s) (interrupted "
                          f"run or corrupt entry) to {self.path.name}.torn", RuntimeWarning,
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
