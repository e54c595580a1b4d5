"""Run a sweep: expand the grid, skip what is done, run the rest, record as it finishes.

``spacecraft sweep --config FILE --backend local|ray --out DIR`` calls
:func:`run_sweep`. The output directory holds

* ``sweep.json``: the configuration as parsed (rewritten on every run);
* ``results.jsonl``: one record per finished task (:mod:`spacecraft_lab.sweeps.store`),
  appended by this process as results arrive;
* ``summary.md``, ``summary.csv``, ``summary.json`` and ``summary.png`` from
  :func:`spacecraft_lab.sweeps.summary.summarize` at the end.

Running the same command again resumes: tasks with a record are skipped
(tasks that failed too, unless ``retry_errors``), so an interrupted sweep
only redoes the tasks that were in flight, and a sweep file extended with
more seeds or grid values only runs the new tasks.

One driver at a time: the directory is locked (``.sweep.lock``, an OS file
lock released even if the driver is killed) for the whole run, and a second
driver on the same directory stops at once with :class:`SweepLockedError`
instead of running every task again and racing the first on the results
file.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from filelock import FileLock, Timeout
from tqdm import tqdm

from spacecraft_conventions import sigterm_as_interrupt
from spacecraft_lab.sweeps.backends import make_backend
from spacecraft_lab.sweeps.config import SweepConfig, Task, load_config
from spacecraft_lab.sweeps.store import ResultStore
from spacecraft_lab.sweeps.summary import summarize as write_summary
from spacecraft_lab.sweeps.tasks import execute, identity

__all__ = ["LOCK_NAME", "SweepLockedError", "SweepReport", "pending_tasks", "run_sweep"]

#: Lock file of a sweep directory.
LOCK_NAME = ".sweep.lock"


class SweepLockedError(RuntimeError):
    """Another driver is running a sweep on the same output directory."""


@dataclass(frozen=True)
class SweepReport:
    """What one :func:`run_sweep` call did.

    Attributes
    ----------
    total : int
        Tasks in the grid.
    skipped : int
        Tasks already recorded before this call.
    ran, ok, errors : int
        Tasks run now, and how many of them succeeded / failed.
    wall_s : float
        Wall time of this call, s.
    backend : str
    workers : int
        Workers (processes or cluster CPUs) of the backend.
    out : Path
    """

    total: int
    skipped: int
    ran: int
    ok: int
    errors: int
    wall_s: float
    backend: str
    workers: int
    out: Path


def pending_tasks(tasks: list[Task], store: ResultStore,
                  retry_errors: bool = False) -> list[Task]:
    """The tasks without a record (or with an error record, if ``retry_errors``).

    Parameters
    ----------
    tasks : list of Task
        The sweep's tasks.
    store : ResultStore
        The sweep's results (read once; the last record of a task counts).
    retry_errors : bool
        Count tasks whose last record is not ``"ok"`` as pending too.

    Returns
    -------
    list of Task
        The pending tasks, in the order of ``tasks``.
    """
    done = store.load()
    return [t for t in tasks if t.task_id not in done
            or (retry_errors and done[t.task_id].get("status") != "ok")]


def run_sweep(config: SweepConfig | str | Path, out: str | Path, backend: str = "local", *,
              workers: int | None = None, address: str | None = None,
              retry_errors: bool = False, ship_code: bool = False, summarize: bool = True,
              progress: bool = True, allow_custom_tasks: bool = False) -> SweepReport:
    """Run every pending task of a sweep and record the results.

    Parameters
    ----------
    config : SweepConfig or path
        A configuration or a sweep file (:func:`spacecraft_lab.sweeps.config.load_config`).
    out : path
        Output directory; an existing one is resumed.
    backend : {"local", "ray", "serial"}
    workers : int, optional
        Local worker processes (default: all cores), or the CPUs of a new
        local Ray instance.
    address : str, optional
        Ray cluster address (``backend="ray"``).
    retry_errors : bool
        Run again the tasks whose record is an error.
    ship_code : bool
        Ray only: upload this package to the cluster with the job.
    summarize : bool
        Write the summary tables and plots at the end.
    progress : bool
        Show a progress bar.
    allow_custom_tasks : bool
        When ``config`` is a path: accept custom ``"module:function"`` task
        kinds (see :func:`spacecraft_lab.sweeps.config.load_config`).

    Returns
    -------
    SweepReport

    Raises
    ------
    SweepLockedError
        If another sweep is running on ``out``.
    """
    if not isinstance(config, SweepConfig):
        config = load_config(config, allow_custom_tasks=allow_custom_tasks)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    lock = FileLock(out / LOCK_NAME)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise SweepLockedError(f"another sweep is running on {out} (it holds {out / LOCK_NAME}); "
                               "wait for it to finish or use another output directory") from None
    try:
        return _run_locked(config, out, backend, workers, address, retry_errors, ship_code,
                           summarize, progress)
    finally:
        lock.release()


def _run_locked(config: SweepConfig, out: Path, backend: str, workers: int | None,
                address: str | None, retry_errors: bool, ship_code: bool, summarize: bool,
                progress: bool) -> SweepReport:
    store = ResultStore(out / "results.jsonl")
    store.check_writable()              # before any work: no result is computed to be lost
    (out / "sweep.json").write_text(json.dumps(config.to_dict(), indent=2))
    store.repair()
    tasks = config.tasks()
    todo = pending_tasks(tasks, store, retry_errors)
    start = time.perf_counter()
    ok = errors = 0
    runner = make_backend(backend, workers, address, ship_code)
    if todo:
        with sigterm_as_interrupt(), runner, tqdm(total=len(tasks), initial=len(tasks) - len(todo),
                          desc=f"sweep {config.name} ({backend})", unit="task",
                          disable=not progress) as bar:
            for item, outcome in runner.imap_unordered(execute, [t.to_dict() for t in todo]):
                if isinstance(outcome, BaseException):
                    outcome = {**identity(item), "status": "error",
                               "error": f"{type(outcome).__name__}: {outcome} (backend)"}
                outcome["backend"] = backend
                store.append(outcome)
                if outcome["status"] == "ok":
                    ok += 1
                else:
                    errors += 1
                bar.update()
                bar.set_postfix(errors=errors, refresh=False)
    report = SweepReport(total=len(tasks), skipped=len(tasks) - len(todo), ran=ok + errors,
                         ok=ok, errors=errors, wall_s=time.perf_counter() - start,
                         backend=backend, workers=runner.workers, out=out)
    if summarize:
        write_summary(out)
    return report
