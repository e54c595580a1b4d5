"""The append-only result file of a sweep: one JSON line per finished task.

Only the driver process writes (the output directory is locked while a
sweep runs, see :mod:`spacecraft_lab.sweeps.runner`), one whole line per
``write`` followed by a flush and ``fsync``, so after an interruption the
file holds every task that finished and at most one truncated last line,
which :meth:`ResultStore.load` skips (and the next append starts on a fresh
line). Any line that is not a complete record (:func:`parse_record`: torn,
bad bytes, missing fields, or fields of the wrong type, :func:`record_problem`)
is treated the same way, so its task runs again, and
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

from spacecraft_lab.sweeps.tasks import METRIC_TYPES

__all__ = ["ResultStore", "parse_record", "record_problem"]


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_json_scalar(value: Any) -> bool:
    return value is None or isinstance(value, (bool, int, float, str))


_CHECKS = {
    "number": lambda v: v is None or _is_number(v),
    "string": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, bool),
    "list": lambda v: isinstance(v, list) and all(_is_json_scalar(x) for x in v),
    "mapping": lambda v: isinstance(v, dict) and all(isinstance(k, str) and _is_number(x)
                                                     for k, x in v.items()),
}


def record_problem(record: Any) -> str | None:
    """What makes ``record`` not a finished task's record, or None if it is one.

    The schema: a ``task_id`` and a ``kind`` (strings), a ``params`` table
    whose ``seed`` (if any) is an int, and a ``status`` of ``"error"`` (with
    an ``error`` string) or ``"ok"`` with a non-empty ``metrics`` table and
    an optional ``timings`` table of numbers. A built-in kind's metrics have
    the types its task writes (numbers or null, except those of
    :data:`spacecraft_lab.sweeps.tasks.METRIC_TYPES`); a custom kind's are
    JSON scalars or lists of them.

    Returns
    -------
    str or None
        A sentence naming the problem, or None.
    """
    if not isinstance(record, dict):
        return "not a JSON object"
    for key in ("task_id", "kind"):
        if not isinstance(record.get(key), str):
            return f"{key} is not a string"
    params = record.get("params")
    if not isinstance(params, dict):
        return "params is not a table"
    seed = params.get("seed")
    if "seed" in params and not (isinstance(seed, int) and not isinstance(seed, bool)):
        return f"params.seed is {seed!r}, not an int"
    status = record.get("status")
    if status == "error":
        return None if isinstance(record.get("error", ""), str) else "error is not a string"
    if status != "ok":
        return f"status is {status!r}, not 'ok' or 'error'"
    metrics = record.get("metrics")
    if not isinstance(metrics, dict) or not metrics:
        return "metrics is not a non-empty table"
    types = METRIC_TYPES.get(record["kind"])
    for name, value in metrics.items():
        if types is None:
            ok = _is_json_scalar(value) or _CHECKS["list"](value)
        else:
            ok = _CHECKS[types.get(name, "number")](value)
        if not ok:
            return f"metric {name!r} has the wrong type ({value!r})"
    timings = record.get("timings", {})
    if not isinstance(timings, dict) or not all(_CHECKS["number"](v) for v in timings.values()):
        return "timings is not a table of numbers"
    return None


def parse_record(line: bytes) -> dict[str, Any] | None:
    """The record on one line of ``results.jsonl``, or None if the line is not one.

    A line counts as a record only if it is valid UTF-8 and JSON and passes
    :func:`record_problem`. Anything else (a line torn by an interrupted
    write, a bad byte, a hand-edited or wrong-typed entry) is not a finished
    task.

    Parameters
    ----------
    line : bytes
        One line of the file, with or without its newline.

    Returns
    -------
    dict or None
        The record, or None.
    """
    try:
        record = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    return record if record_problem(record) is None else None


class ResultStore:
    """``results.jsonl`` of a sweep directory.

    Parameters
    ----------
    path : path
        The JSON-lines file (created on first append).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        #: Lines the last read skipped (not complete records).
        self.n_skipped = 0

    def check_writable(self) -> None:
        """Fail now, in one line, if the file cannot take records (it is a directory or
        another non-file, or it cannot be opened for appending); nothing is created.

        Raises
        ------
        ValueError
            Naming the file and the reason.
        """
        if self.path.exists() and not self.path.is_file():
            raise ValueError(f"{self.path} is not a file (a results file is expected there)")
        if self.path.exists() or self.path.is_symlink():
            try:
                with open(self.path, "ab"):
                    pass
            except OSError as exc:
                raise ValueError(f"cannot write to {self.path}: {exc.strerror or exc}") from None

    def _lines(self) -> Iterator[tuple[int, bytes]]:
        if not self.path.exists():
            return
        if not self.path.is_file():
            raise ValueError(f"{self.path} is not a file (a results file is expected there)")
        with open(self.path, "rb") as fh:
            for lineno, line in enumerate(fh, 1):
                if line.strip():
                    yield lineno, line

    def __iter__(self) -> Iterator[dict[str, Any]]:
        """Every complete record in file order; anything else (see
        :func:`parse_record`) is skipped with a warning."""
        self.n_skipped = 0
        for lineno, line in self._lines():
            record = parse_record(line)
            if record is None:
                self.n_skipped += 1
                warnings.warn(f"{self.path}:{lineno}: skipping an incomplete record "
                              f"({self._why(line)}); its task runs again on resume",
                              RuntimeWarning, stacklevel=2)
                continue
            yield record

    @staticmethod
    def _why(line: bytes) -> str:
        try:
            return record_problem(json.loads(line.decode("utf-8"))) or "?"
        except (UnicodeDecodeError, json.JSONDecodeError):
            return "interrupted write or corrupt bytes"

    def load(self) -> dict[str, dict[str, Any]]:
        """Task id -> its last record.

        Returns
        -------
        dict
            Task id -> its last complete record.
        """
        return {r["task_id"]: r for r in self}

    def repair(self) -> int:
        """Move every line that is not a complete record to ``<file>.torn``.

        Returns how many. The rewrite goes through a temporary file and an
        atomic rename, so an interruption here loses nothing.

        Returns
        -------
        int
            The number of lines moved.
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
