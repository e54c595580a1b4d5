"""Monte-Carlo sweeps of identification and control experiments.

Declare a grid in a TOML/YAML file (:mod:`.config`), run it on this
machine's cores or a Ray cluster (:mod:`.backends`) with resumable JSON-lines
results (:mod:`.store`, :mod:`.runner`), and tabulate mean and spread over
seeds (:mod:`.summary`)::

    spacecraft sweep --config configs/table5.toml --backend local --out results/table5
    spacecraft sweep-summary results/table5
"""

from spacecraft_lab.sweeps.backends import (
    BACKENDS,
    LocalBackend,
    RayBackend,
    SerialBackend,
    make_backend,
)
from spacecraft_lab.sweeps.config import (
    MAX_TASKS,
    Reference,
    SummarySpec,
    SweepConfig,
    Task,
    load_config,
)
from spacecraft_lab.sweeps.runner import SweepLockedError, SweepReport, pending_tasks, run_sweep
from spacecraft_lab.sweeps.store import ResultStore, parse_record
from spacecraft_lab.sweeps.summary import group_statistics, summarize
from spacecraft_lab.sweeps.tasks import TASKS, execute, resolve_task

__all__ = [
    "BACKENDS",
    "MAX_TASKS",
    "TASKS",
    "LocalBackend",
    "RayBackend",
    "Reference",
    "ResultStore",
    "SerialBackend",
    "SummarySpec",
    "SweepConfig",
    "SweepLockedError",
    "SweepReport",
    "Task",
    "execute",
    "group_statistics",
    "load_config",
    "make_backend",
    "parse_record",
    "pending_tasks",
    "resolve_task",
    "run_sweep",
    "summarize",
]
