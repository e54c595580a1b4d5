"""Sweep files: a grid of identification or control tasks declared in TOML or YAML.

A sweep file names a task kind, the parameters every task shares, the axes
of a Cartesian grid, optional *cases* (named parameter sets crossed with the
grid, e.g. one per method with its own settings) and the seeds. Example
(``configs/table5.toml`` is the paper's Table 5)::

    name = "table5"
    task = "identify"          # or "control", or "package.module:function"
    seeds = 30                 # 0..29; or a list; or {start = 100, count = 30}
    timeout_s = 600            # optional: per-task wall-clock limit

    [params]                   # shared by every task
    scenario = "docking"
    forgetting = 0.98

    [grid]                     # Cartesian product
    order = [22, 30, 38, 46]

    [[cases]]                  # crossed with the grid; "label" names the series
    label = "classical-rpbsid"
    method = "classical-rpbsid"

    [summary]                  # how `spacecraft sweep-summary` tabulates
    rows = "label"
    columns = "order"
    metrics = ["time_s", "test_error_attitude_pct"]

Inside ``[[cases]]`` two keys are not parameters: ``label`` (the series name
in summaries) and ``task`` (a different task kind for that case). A task
function's own ``task`` argument (the control environment's "slew" or
"regulation") is set in ``[params]`` or ``[grid]``.

Every task is ``function(**params, seed=seed)`` for the kind's function
(:data:`spacecraft_lab.sweeps.tasks.TASKS`); parameter names are checked against its
signature when the file is loaded, before anything runs. A task's identity
(:attr:`Task.task_id`) is a hash of its kind and parameters, so a sweep that
is resumed, extended with more seeds or re-ordered only runs what is new.
"""

from __future__ import annotations

import hashlib
import inspect
import itertools
import json
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from spacecraft_lab.sweeps.tasks import resolve_task

__all__ = ["MAX_TASKS", "Reference", "SummarySpec", "SweepConfig", "Task", "load_config"]

#: Largest number of tasks a sweep file may declare unless the caller raises the
#: limit (``max_tasks=``, ``spacecraft sweep --max-tasks``): checked before the
#: tasks are listed, so a typo in a seed count fails at once instead of
#: exhausting memory.
MAX_TASKS = 100_000

_TOP_KEYS = {"name", "task", "seeds", "params", "grid", "cases", "summary", "description",
             "timeout_s"}
_SUMMARY_KEYS = {"rows", "columns", "metrics", "ratio_to", "reference", "plot_rows"}


def _canonical(value: Any, where: str) -> Any:
    """Plain JSON-able value (lists, not tuples); rejects other types."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        if value != value or value in (float("inf"), float("-inf")):
            raise ValueError(f"{where}: parameter values must be finite, got {value}")
        return float(value)
    if isinstance(value, Sequence):
        return [_canonical(v, where) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _canonical(v, where) for k, v in value.items()}
    raise TypeError(f"{where}: unsupported parameter type {type(value).__name__}")


@dataclass(frozen=True)
class Task:
    """One unit of work: ``function(**params)`` of a task kind.

    Attributes
    ----------
    kind : str
        A key of :data:`spacecraft_lab.sweeps.tasks.TASKS` or ``"module:function"``.
    params : dict
        Keyword arguments, including ``seed``; JSON values.
    label : str, optional
        Series name for summaries (a case's ``label``); not part of the
        identity.
    timeout_s : float, optional
        Wall-clock limit of one run, s (:func:`spacecraft_lab.sweeps.tasks.execute`); not
        part of the identity.
    """

    kind: str
    params: dict[str, Any]
    label: str | None = None
    timeout_s: float | None = None

    @property
    def task_id(self) -> str:
        """16 hex digits of SHA-1 over the canonical JSON of kind and params."""
        blob = json.dumps({"kind": self.kind, "params": self.params}, sort_keys=True,
                          separators=(",", ":"))
        return hashlib.sha1(blob.encode()).hexdigest()[:16]

    def to_dict(self) -> dict[str, Any]:
        """JSON form (what a worker receives).

        Returns
        -------
        dict
            The task's fields, JSON-ready.
        """
        return {"task_id": self.task_id, "kind": self.kind, "params": self.params,
                "label": self.label, "timeout_s": self.timeout_s}


@dataclass(frozen=True)
class Reference:
    """Published values shown beside a summary table.

    Attributes
    ----------
    row : str
        Row of the pivot table they belong to (e.g. ``"classical-rpbsid"``).
    metric : str
        Metric they compare with (e.g. ``"time_s"``).
    source : str
        Where they come from (e.g. ``"paper Table 5, MATLAB"``).
    values : dict
        Column value (as text) -> number.
    """

    row: str
    metric: str
    source: str
    values: dict[str, float]


@dataclass(frozen=True)
class SummarySpec:
    """How a sweep is tabulated and plotted (all optional).

    Attributes
    ----------
    rows : str, optional
        Parameter (or ``"label"``) whose values are the table rows and the
        plot series; default: the label if cases are labelled, else the
        varying parameters other than ``columns``.
    columns : str, optional
        Parameter on the table columns and plot x-axis; default the first
        varying numeric grid axis.
    metrics : tuple of str, optional
        Metrics to tabulate; default every scalar metric and timing.
    ratio_to : str, optional
        A row whose mean each row's mean is divided by, column by column
        (and the references by theirs), for the timings: speed ratios that
        compare across machines and languages.
    reference : tuple of Reference
    plot_rows : tuple of str, optional
        The rows ``summary.png`` draws, at most five (default: the first five;
        every row is in the tables).
    """

    rows: str | None = None
    columns: str | None = None
    metrics: tuple[str, ...] | None = None
    ratio_to: str | None = None
    reference: tuple[Reference, ...] = ()
    plot_rows: tuple[str, ...] | None = None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None) -> SummarySpec:
        """The summary settings of a sweep file's ``[summary]`` table (unknown keys
        refused).

        Returns
        -------
        SummarySpec
            The spec.
        """
        data = dict(data or {})
        unknown = set(data) - _SUMMARY_KEYS
        if unknown:
            raise ValueError(f"[summary]: unknown keys {sorted(unknown)}; expected "
                             f"{sorted(_SUMMARY_KEYS)}")
        refs = []
        for i, ref in enumerate(data.get("reference") or ()):
            try:
                refs.append(Reference(str(ref["row"]), str(ref["metric"]),
                                      str(ref.get("source", "reference")),
                                      {str(k): float(v) for k, v in ref["values"].items()}))
            except (KeyError, TypeError, AttributeError, ValueError) as exc:
                raise ValueError(f"[[summary.reference]] #{i}: needs row, metric and a "
                                 f"values table of numbers ({exc})") from None
        metrics = data.get("metrics")
        if metrics is not None and (isinstance(metrics, str) or not all(
                isinstance(m, str) for m in metrics)):
            raise TypeError("[summary] metrics must be a list of metric names")
        plot_rows = data.get("plot_rows")
        if plot_rows is not None and (isinstance(plot_rows, str) or not all(
                isinstance(r, str) for r in plot_rows) or not 1 <= len(plot_rows) <= 5):
            raise TypeError("[summary] plot_rows must be a list of one to five row names")
        return cls(rows=data.get("rows"), columns=data.get("columns"),
                   metrics=None if metrics is None else tuple(metrics),
                   ratio_to=data.get("ratio_to"), reference=tuple(refs),
                   plot_rows=None if plot_rows is None else tuple(plot_rows))

    def to_dict(self) -> dict[str, Any]:
        """JSON form (what a worker receives).

        Returns
        -------
        dict
            The spec's fields, JSON-ready.
        """
        return {"rows": self.rows, "columns": self.columns,
                "metrics": None if self.metrics is None else list(self.metrics),
                "ratio_to": self.ratio_to,
                "reference": [ref.__dict__ for ref in self.reference],
                "plot_rows": None if self.plot_rows is None else list(self.plot_rows)}


def _timeout(value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not value > 0 or value == float("inf"):
        raise ValueError(f"timeout_s must be a positive number of seconds, got {value!r}")
    return float(value)


def _seeds(value: Any) -> Sequence[int]:
    """The seeds of a sweep file's ``seeds`` entry; a count or a table gives a
    ``range`` (nothing materialized before the task count is checked)."""
    if isinstance(value, bool):
        raise ValueError(f"seeds must be a count, a list of integers or {{start, count}}, "
                         f"got {value!r}")
    if isinstance(value, int):
        if value < 1:
            raise ValueError(f"seeds must be a positive count, got {value}")
        return range(value)
    if isinstance(value, Mapping):
        start, count = value.get("start"), value.get("count")
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in (start, count)):
            raise ValueError("seeds as a table needs integer start and count, got "
                             f"{dict(value)!r}")
        if start < 0 or count < 1:
            raise ValueError(f"seeds: start >= 0 and count >= 1, got {start}, {count}")
        return range(start, start + count)
    if isinstance(value, Sequence) and not isinstance(value, str):
        if not value or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                for s in value):
            raise ValueError(f"seeds must be non-negative integers, got {value!r}")
        if len(set(value)) != len(value):
            raise ValueError(f"seeds must be distinct, got {value!r}")
        return tuple(int(s) for s in value)
    raise ValueError(f"seeds must be a count, a list of integers or {{start, count}}, "
                     f"got {value!r}")


@dataclass(frozen=True)
class SweepConfig:
    """A parsed sweep file (see the module docstring for the format).

    Attributes
    ----------
    name : str
    task : str
        Default task kind of every case.
    seeds : sequence of int
        A ``range`` or a tuple.
    params : dict
        Shared parameters.
    grid : dict
        Axis name -> tuple of values (Cartesian product).
    cases : tuple of dict
        Parameter sets crossed with the grid; may hold ``label`` and ``task``.
    summary : SummarySpec
    description : str
    timeout_s : float, optional
        Per-task wall-clock limit, s: a task that runs longer is recorded as
        a ``TimeoutError`` and the sweep goes on.
    """

    name: str
    task: str
    seeds: Sequence[int]
    params: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    cases: tuple[dict[str, Any], ...] = ({},)
    summary: SummarySpec = field(default_factory=SummarySpec)
    description: str = ""
    timeout_s: float | None = None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], name: str | None = None, *,
                  allow_custom_tasks: bool = False, validate: bool = True,
                  max_tasks: int = MAX_TASKS) -> SweepConfig:
        """Build and validate a configuration from a parsed file.

        Parameters
        ----------
        data : mapping
            The parsed file.
        name : str, optional
            Default sweep name (the file's stem).
        allow_custom_tasks : bool
            Accept ``"module:function"`` task kinds; their modules are
            imported (and their top-level code run) to check the parameter
            names. A sweep file is trusted input.
        validate : bool
            Check parameter names against the task functions (imports them)
            and their values with the kind's own check where it has one
            (``function.check_params``, e.g. an identification's scored
            window must start after the warm-up); False only re-reads a
            configuration this package wrote itself.
        max_tasks : int
            Refuse a sweep of more tasks (default :data:`MAX_TASKS`).

        Returns
        -------
        SweepConfig
            The configuration, checked.

        Raises
        ------
        ValueError, TypeError
            Unknown keys, an unknown task kind, a custom kind without
            permission, parameters the task function does not take or
            values it rejects, a parameter set twice, empty grid axes, bad
            seeds, more than ``max_tasks`` tasks.
        """
        if not isinstance(data, Mapping):
            raise TypeError("a sweep file must hold a table/mapping at the top level")
        unknown = set(data) - _TOP_KEYS
        if unknown:
            raise ValueError(f"unknown top-level keys {sorted(unknown)}; expected "
                             f"{sorted(_TOP_KEYS)}")
        if "task" not in data or "seeds" not in data:
            raise ValueError("a sweep file needs 'task' and 'seeds'")
        params = _canonical(dict(data.get("params") or {}), "[params]")
        grid: dict[str, tuple[Any, ...]] = {}
        for axis, values in dict(data.get("grid") or {}).items():
            if isinstance(values, str) or not isinstance(values, Sequence) or not values:
                raise ValueError(f"[grid] {axis}: an axis is a non-empty list of values")
            grid[str(axis)] = tuple(_canonical(list(values), f"[grid] {axis}"))
        raw_cases = data.get("cases") or [{}]
        if isinstance(raw_cases, Mapping) or not isinstance(raw_cases, Sequence):
            raise TypeError("cases must be a list of tables ([[cases]])")
        cases = tuple(_canonical(dict(c), f"[[cases]] #{i}") for i, c in enumerate(raw_cases))
        seeds = _seeds(data["seeds"])
        n_tasks = len(seeds) * len(cases) * math.prod(len(v) for v in grid.values())
        if n_tasks > max_tasks:
            raise ValueError(f"the sweep declares {n_tasks:,} tasks ({len(seeds):,} seeds x "
                             f"{len(cases)} cases x {math.prod(len(v) for v in grid.values())} "
                             f"grid points), more than the limit of {max_tasks:,}; raise it "
                             "with --max-tasks (max_tasks=) if you mean it")
        config = cls(name=str(data.get("name") or name or "sweep"), task=str(data["task"]),
                     seeds=seeds, params=params, grid=grid, cases=cases,
                     summary=SummarySpec.from_dict(data.get("summary")),
                     description=str(data.get("description", "")),
                     timeout_s=_timeout(data.get("timeout_s")))
        if validate:
            config._validate(allow_custom_tasks)
        return config

    def _validate(self, allow_custom_tasks: bool) -> None:
        for i, case in enumerate(self.cases):
            where = f"[[cases]] #{i}"
            own = {k for k in case if k not in ("label", "task")}
            for a, b, what in ((own, set(self.params), "[params]"),
                               (own, set(self.grid), "[grid]"),
                               (set(self.params), set(self.grid), "[grid]")):
                twice = a & b
                if twice:
                    raise ValueError(f"{where}: {sorted(twice)} also set in {what}")
            if "seed" in own | set(self.params) | set(self.grid):
                raise ValueError("'seed' is set by 'seeds', not as a parameter")
            kind = str(case.get("task", self.task))
            fn = resolve_task(kind, allow_custom_tasks)
            sig = inspect.signature(fn)
            takes_any = any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values())
            names = own | set(self.params) | set(self.grid) | {"seed"}
            if not takes_any:
                bad = names - set(sig.parameters)
                if bad:
                    raise ValueError(f"{where}: task {kind!r} takes no parameter(s) "
                                     f"{sorted(bad)}; it takes {sorted(sig.parameters)}")
            missing = {n for n, p in sig.parameters.items()
                       if p.default is p.empty and p.kind in (p.KEYWORD_ONLY,
                                                              p.POSITIONAL_OR_KEYWORD)} - names
            if missing:
                raise ValueError(f"{where}: task {kind!r} needs parameter(s) {sorted(missing)}")
            check = getattr(fn, "check_params", None)
            if callable(check):
                axes = list(self.grid)
                base = {k: v for k, v in case.items() if k not in ("label", "task")}
                for point in itertools.product(*(self.grid[a] for a in axes)):
                    values = {**self.params, **base, **dict(zip(axes, point, strict=True))}
                    try:
                        check(**values)
                    except (ValueError, TypeError) as exc:
                        shown = ", ".join(f"{k}={v!r}" for k, v in sorted(values.items()))
                        raise ValueError(f"{where}: task {kind!r} with {shown}: {exc}") from None
        ids = [t.task_id for t in self.tasks()]
        if len(set(ids)) != len(ids):
            raise ValueError("two cases give identical tasks; make their parameters differ")

    def tasks(self) -> list[Task]:
        """Every task, in order case -> grid point -> seed.

        Returns
        -------
        list of Task
            The tasks.
        """
        out = []
        axes = list(self.grid)
        for case in self.cases:
            kind = str(case.get("task", self.task))
            label = case.get("label")
            own = {k: v for k, v in case.items() if k not in ("label", "task")}
            for point in itertools.product(*(self.grid[a] for a in axes)):
                base = {**self.params, **own, **dict(zip(axes, point, strict=True))}
                for seed in self.seeds:
                    params = dict(sorted({**base, "seed": seed}.items()))
                    out.append(Task(kind, params, None if label is None else str(label),
                                    self.timeout_s))
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON form, written next to the results (``sweep.json``).

        Returns
        -------
        dict
            The configuration's fields, JSON-ready.
        """
        return {"name": self.name, "task": self.task, "description": self.description,
                "timeout_s": self.timeout_s,
                "seeds": list(self.seeds), "params": self.params,
                "grid": {k: list(v) for k, v in self.grid.items()},
                "cases": list(self.cases), "summary": self.summary.to_dict()}


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader, refusing a key given twice in one mapping (PyYAML keeps the
    last one silently; TOML refuses it)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep)


# YAML 1.1 (PyYAML) reads ``1.0e9`` and ``1e9`` as strings; YAML 1.2, TOML and JSON as
# numbers. Sweep files follow the latter.
_UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                |[-+]?\.(?:inf|Inf|INF)
                |\.(?:nan|NaN|NAN))$""", re.VERBOSE),
    list("-+0123456789."))


def _yaml_unique(text: str) -> Any:
    return yaml.load(text, Loader=_UniqueKeyLoader)


def _json_unique(text: str) -> Any:
    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        keys = [k for k, _ in items]
        twice = sorted({k for k in keys if keys.count(k) > 1})
        if twice:
            raise ValueError(f"duplicate key(s) {twice}")
        return dict(items)

    return json.loads(text, object_pairs_hook=pairs)


def load_config(path: str | Path, *, allow_custom_tasks: bool = False,
                max_tasks: int = MAX_TASKS) -> SweepConfig:
    """Read a sweep file (``.toml``, ``.yaml``/``.yml`` or ``.json``).

    A sweep file is trusted input: with ``allow_custom_tasks`` it may name
    any importable ``"module:function"``, whose module is imported here.

    Parameters
    ----------
    path : str or Path
        The sweep file; its stem is the sweep's name.
    allow_custom_tasks : bool
        Permit custom ``"module:function"`` task kinds.
    max_tasks : int
        Largest number of tasks the grid may expand to (default
        :data:`MAX_TASKS`).

    Returns
    -------
    SweepConfig
        The parsed and validated sweep.

    Raises
    ------
    FileNotFoundError
    ValueError
        Unsupported extension, a parse error, an invalid sweep (of any kind:
        a wrong type is reported as a ValueError too), a custom task kind
        without ``allow_custom_tasks``, or more than ``max_tasks`` tasks.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".yaml", ".yml", ".json"):
        raise ValueError(f"sweep file must be .toml, .yaml, .yml or .json, got {path.name}")
    text = path.read_text()
    parse = {".toml": tomllib.loads, ".json": _json_unique}.get(suffix, _yaml_unique)
    try:
        data = parse(text)
    except Exception as exc:  # TOMLDecodeError, JSONDecodeError, yaml.YAMLError
        raise ValueError(f"{path}: cannot parse: {' '.join(str(exc).split())}") from None
    try:
        return SweepConfig.from_dict(data, name=path.stem, allow_custom_tasks=allow_custom_tasks,
                                     max_tasks=max_tasks)
    except TypeError as exc:
        raise ValueError(f"{path}: {exc}") from None
