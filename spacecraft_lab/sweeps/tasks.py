"""Task kinds and the worker-side execution of one task.

A task kind is a function of keyword arguments (one of them ``seed``) that
returns ``{"metrics": {...}, "timings": {...}}``: metrics are deterministic
functions of the arguments, timings are wall-clock seconds. The built-in
kinds are

* ``"identify"``: :func:`spacecraft_lab.identification.identify_task` (one
  identifier on one seed's records: accuracy and run time);
* ``"control"``: :func:`spacecraft_lab.control.control_task` (one closed-loop
  episode: attitude error, vibration, effort, stability).

Any importable ``"package.module:function"`` with that contract is a kind
too; it must be importable on every worker. **A sweep file is trusted
input**: naming a custom kind imports its module, which runs that module's
top-level code (as Hydra's ``_target_`` does), even for ``--dry-run``. So
custom kinds are refused unless explicitly allowed
(``allow_custom_tasks=True``, ``spacecraft sweep --allow-custom-tasks``);
the built-in kinds need no permission.

:func:`execute` runs one task and never raises: an exception becomes an
``"error"`` record with its traceback, so a sweep goes on past a bad task.
A task's ``timeout_s`` is enforced with ``SIGALRM`` in the worker (POSIX;
tasks run on the main thread of every backend's workers): the task is
interrupted at its next Python bytecode and recorded as a ``TimeoutError``.
"""

from __future__ import annotations

import datetime as _dt
import importlib
import math
import os
import platform
import signal
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

from threadpoolctl import threadpool_limits

__all__ = ["METRIC_TYPES", "TASKS", "THREAD_ENV", "execute", "identity", "jsonable",
           "resolve_task"]

#: Built-in task kinds -> ``"module:function"``.
TASKS: dict[str, str] = {
    "identify": "spacecraft_lab.identification:identify_task",
    "control": "spacecraft_lab.control:control_task",
}

#: Metrics of the built-in kinds whose value is not a number (or null): their
#: JSON type. Every other metric of a built-in kind is a number or null (a
#: diverged run); a record that says otherwise was not written by the task
#: (see :func:`spacecraft_lab.sweeps.store.record_problem`).
METRIC_TYPES: dict[str, dict[str, str]] = {
    "identify": {},
    "control": {"verdict": "string", "stable": "bool", "settling_s": "list",
                "settled_before_event": "list", "fallback_causes_after_60s": "mapping"},
}

#: Environment of worker processes: one BLAS/OpenMP thread each, so that a
#: pool of one worker per core does not oversubscribe the machine and every
#: task computes bit-identical numbers wherever it runs.
THREAD_ENV: dict[str, str] = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
                              "MKL_NUM_THREADS": "1"}


def resolve_task(kind: str, allow_custom: bool = False) -> Callable[..., dict]:
    """The function of a task kind (a :data:`TASKS` key or ``"module:function"``).

    Parameters
    ----------
    kind : str
        A built-in kind (``"identify"``, ``"control"``) or
        ``"package.module:function"``.
    allow_custom : bool
        Permit ``"module:function"`` kinds, whose import runs code named by
        the sweep file (see the module docstring).

    Returns
    -------
    callable
        The task function: keyword arguments (the task's ``params``) ->
        ``{"metrics": {...}, "timings": {...}}``.

    Raises
    ------
    ValueError
        Unknown kind, a custom kind without permission, or a path that does
        not import.
    """
    path = TASKS.get(kind, kind)
    module, sep, name = path.partition(":")
    if not sep or not module or not name:
        raise ValueError(f"unknown task kind {kind!r}; expected one of {sorted(TASKS)} "
                         "or 'package.module:function'")
    if kind not in TASKS and not allow_custom:
        raise ValueError(f"task kind {kind!r} is not built in ({sorted(TASKS)}); a custom "
                         "'module:function' kind imports and runs that module's code, so it "
                         "needs explicit permission: --allow-custom-tasks on the command line, "
                         "allow_custom_tasks=True in Python")
    try:
        fn = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"task kind {kind!r}: cannot import {path} ({exc})") from exc
    if not callable(fn):
        raise ValueError(f"task kind {kind!r}: {path} is not callable")
    return fn


def jsonable(value: Any) -> Any:
    """``value`` as strict JSON: numpy scalars/arrays to Python, non-finite floats to None.

    Returns
    -------
    object
        ``value`` with every part JSON-serializable.
    """
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalar or array
        return jsonable(value.tolist())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    return repr(value)


class _Deadline:
    """Raise TimeoutError in this (main) thread after ``seconds``."""

    def __init__(self, seconds: float | None) -> None:
        self.seconds = seconds
        self._armed = (seconds is not None and hasattr(signal, "setitimer")
                       and threading.current_thread() is threading.main_thread())
        self._previous: Any = None

    def _expire(self, signum: int, frame: object) -> None:
        raise TimeoutError(f"task exceeded its {self.seconds:g} s limit")

    def __enter__(self) -> _Deadline:
        if self._armed:
            self._previous = signal.signal(signal.SIGALRM, self._expire)
            signal.setitimer(signal.ITIMER_REAL, float(self.seconds))
        return self

    def __exit__(self, *exc: object) -> None:
        if self._armed:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, self._previous)


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def identity(task: dict[str, Any]) -> dict[str, Any]:
    """The fields every record of ``task`` starts with: id, kind, label, params.

    Returns
    -------
    dict
        The fields.
    """
    return {"task_id": task["task_id"], "kind": task["kind"], "label": task.get("label"),
            "params": task["params"]}


def execute(task: dict[str, Any]) -> dict[str, Any]:
    """Run one task (the dict of :meth:`spacecraft_lab.sweeps.config.Task.to_dict`).

    BLAS is limited to one thread for the call. Returns the record appended
    to ``results.jsonl``: the task's id, kind, label and params; ``status``
    ``"ok"`` with ``metrics`` and ``timings``, or ``"error"`` with ``error``
    (type and message) and ``traceback``; ``wall_s``, ``host``, ``pid``,
    ``started`` and ``finished`` (UTC).

    Parameters
    ----------
    task : dict
        ``task_id``, ``kind`` and ``params`` (required), ``label`` and
        ``timeout_s`` (s; None: no limit) (optional). Custom
        ``"module:function"`` kinds are run without a permission check here:
        the driver checked the kind.

    Returns
    -------
    dict
        The record (JSON-ready: metrics and timings through :func:`jsonable`),
        ``wall_s`` in s, ``started`` and ``finished`` ISO 8601 strings. A
        failing task is a record with ``status`` ``"error"``, never an
        exception.

    Raises
    ------
    ValueError
        ``task`` is not a task dict (the driver's error, not the task's).
    """
    missing = [key for key in ("task_id", "kind", "params")
               if not isinstance(task, dict) or key not in task]
    if missing or not isinstance(task["params"], dict):
        raise ValueError(f"a task needs 'task_id', 'kind' and a 'params' dict; "
                         f"missing or wrong: {missing or ['params']}")
    record = {**identity(task), "host": platform.node(), "pid": os.getpid(), "started": _now()}
    start = time.perf_counter()
    try:
        fn = resolve_task(task["kind"], allow_custom=True)   # the driver checked the kind
        with _Deadline(task.get("timeout_s")), threadpool_limits(limits=1):
            out = fn(**task["params"])
        if not isinstance(out, dict) or not isinstance(out.get("metrics"), dict):
            raise TypeError(f"task {task['kind']!r} returned {type(out).__name__}; expected "
                            "{'metrics': {...}, 'timings': {...}}")
        record.update(status="ok", metrics=jsonable(out["metrics"]),
                      timings=jsonable(out.get("timings", {})))
    except Exception as exc:  # recorded, the sweep goes on
        record.update(status="error", error=f"{type(exc).__name__}: {exc}",
                      traceback=traceback.format_exc(limit=20))
    record.update(wall_s=time.perf_counter() - start, finished=_now())
    return record
