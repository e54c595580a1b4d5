"""Where sweep tasks run: in-process, a local process pool, or a Ray cluster.

Every backend is a context manager with one method,
``imap_unordered(fn, items)``, which yields ``(item, outcome)`` pairs as
tasks finish; ``outcome`` is ``fn(item)`` or the exception the backend met
running it (a dead worker, a lost node). ``fn`` is
:func:`spacecraft_lab.sweeps.tasks.execute`, which catches task errors itself.

* :class:`SerialBackend` runs in the calling process (debugging, baselines).
* :class:`LocalBackend` is a ``spawn`` process pool, one worker per core by
  default, each with single-threaded BLAS.
* :class:`RayBackend` submits the same function as Ray tasks (``num_cpus=1``)
  to ``ray.init(address=...)``, a new local instance when no address is
  given. Ray is an optional extra: ``pip install flexible-spacecraft[ray]``.
  Nodes of a remote cluster need this package installed, or
  ``ship_code=True`` to upload it with the job (its dependencies must then
  be on the nodes).
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from functools import partial
from typing import Any

import controllers
import identifiers
import spacecraft_conventions
import spacecraft_env
import spacecraft_lab
from spacecraft_conventions import exit_with_parent
from spacecraft_lab.sweeps.tasks import THREAD_ENV

__all__ = ["BACKENDS", "LocalBackend", "RayBackend", "SerialBackend", "check_workers",
           "make_backend", "map_in_order"]


def _top_up(pending: dict[Any, Any], source: Iterator[Any], limit: int,
            submit: Callable[[Any], Any]) -> None:
    """Submit items of ``source`` until ``limit`` are in flight (``pending``:
    handle -> item); ``pending`` stays empty once the source is exhausted."""
    for item in itertools.islice(source, max(limit - len(pending), 0)):
        pending[submit(item)] = item


def _init_worker(driver: int) -> None:
    os.environ.update(THREAD_ENV)
    exit_with_parent(parent=driver)


class SerialBackend:
    """Run tasks one after another in this process."""

    name = "serial"
    workers = 1

    def __enter__(self) -> SerialBackend:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def imap_unordered(self, fn: Callable[[Any], Any],
                       items: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, fn(item) or exception)`` as tasks finish.

        Yields
        ------
        (item, result)
            Each item with its result, in the order they finish.
        """
        for item in items:
            try:
                yield item, fn(item)
            except Exception as exc:
                yield item, exc


class LocalBackend:
    """A process pool on this machine.

    Parameters
    ----------
    workers : int, optional
        Worker processes (default: ``os.cpu_count()``).
    max_in_flight : int, optional
        Tasks submitted ahead of completion (default ``4 * workers``), so a
        grid of any size costs bounded memory and an interrupt loses little.
    """

    name = "local"

    def __init__(self, workers: int | None = None, max_in_flight: int | None = None) -> None:
        workers = (os.cpu_count() or 1) if workers is None else check_workers(workers)
        self.workers = workers
        self.max_in_flight = max_in_flight or 4 * workers
        self._pool: ProcessPoolExecutor | None = None

    def _start(self) -> None:
        self._pool = ProcessPoolExecutor(self.workers,
                                         mp_context=multiprocessing.get_context("spawn"),
                                         initializer=_init_worker,
                                         initargs=(os.getpid(),))

    def __enter__(self) -> LocalBackend:
        self._start()
        return self

    def __exit__(self, exc_type: type | None, *exc: object) -> None:
        if self._pool is None:
            return
        if exc_type is not None:  # interrupted: do not wait for running tasks
            for proc in list(getattr(self._pool, "_processes", {}).values()):
                proc.terminate()
        self._pool.shutdown(wait=exc_type is None, cancel_futures=True)
        self._pool = None

    def imap_unordered(self, fn: Callable[[Any], Any],
                       items: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, fn(item) or exception)`` as tasks finish.

        A worker that dies (segfault, out-of-memory kill) breaks the pool:
        every task in flight at that moment is yielded with the
        ``BrokenProcessPool`` error (re-run them with ``retry_errors``) and
        a fresh pool takes the remaining tasks.

        Yields
        ------
        (item, result)
            Each item with its result, in the order they finish.
        """
        if self._pool is None:
            raise RuntimeError("use LocalBackend as a context manager")
        pending: dict[Any, Any] = {}
        source = iter(items)
        while True:
            _top_up(pending, source, self.max_in_flight,
                    lambda item: self._pool.submit(fn, item))
            if not pending:
                return
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            broken = False
            for fut in done:
                item = pending.pop(fut)
                try:
                    yield item, fut.result()
                except BrokenProcessPool as exc:
                    broken = True
                    yield item, exc
                except Exception as exc:
                    yield item, exc
            if broken:
                for fut, item in list(pending.items()):
                    exc = fut.exception() if fut.done() else BrokenProcessPool(
                        "a worker process died")
                    yield item, exc
                pending.clear()
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._start()


class RayBackend:
    """Ray tasks on a cluster, or on a local instance when ``address`` is None.

    Parameters
    ----------
    address : str, optional
        ``ray.init`` address (``"auto"``, ``"ray://host:10001"``, ...); None
        starts a local instance with ``num_cpus`` CPUs.
    num_cpus : int, optional
        CPUs of the local instance (default: all); ignored with an address.
    max_in_flight : int, optional
        Tasks submitted ahead of completion (default ``4 *`` cluster CPUs).
    ship_code : bool
        Upload this project's packages with the job (``py_modules``), for
        cluster nodes that do not have it installed.
    """

    name = "ray"

    def __init__(self, address: str | None = None, num_cpus: int | None = None,
                 max_in_flight: int | None = None, ship_code: bool = False) -> None:
        if num_cpus is not None and (isinstance(num_cpus, bool) or not isinstance(num_cpus, int)
                                     or num_cpus < 1):
            raise ValueError(f"num_cpus must be a positive integer, got {num_cpus!r}")
        self.address = address
        self.num_cpus = num_cpus
        self.max_in_flight = max_in_flight
        self.ship_code = ship_code
        self.workers = num_cpus or 0
        self._ray: Any = None
        self._owns = False

    def __enter__(self) -> RayBackend:
        try:
            import ray
        except ImportError:
            raise ImportError("the ray backend needs Ray: pip install "
                              "'flexible-spacecraft[ray]'") from None
        self._ray = ray
        if not ray.is_initialized():
            runtime_env: dict[str, Any] = {"env_vars": dict(THREAD_ENV)}
            if self.ship_code:
                runtime_env["py_modules"] = [spacecraft_conventions, spacecraft_env, identifiers,
                                             controllers, spacecraft_lab]
            kwargs: dict[str, Any] = {"runtime_env": runtime_env, "include_dashboard": False,
                                      "log_to_driver": False, "configure_logging": False}
            if self.address is None:
                kwargs["num_cpus"] = self.num_cpus
            ray.init(address=self.address, **kwargs)
            self._owns = True
        self.workers = int(ray.cluster_resources().get("CPU", 1))
        return self

    def __exit__(self, *exc: object) -> None:
        if self._owns and self._ray is not None:
            self._ray.shutdown()
        self._owns = False

    def imap_unordered(self, fn: Callable[[Any], Any],
                       items: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, fn(item) or exception)`` as tasks finish.

        Yields
        ------
        (item, result)
            Each item with its result, in the order they finish.
        """
        ray = self._ray
        if ray is None:
            raise RuntimeError("use RayBackend as a context manager")
        remote = ray.remote(num_cpus=1, max_retries=1)(fn)
        limit = self.max_in_flight or 4 * max(self.workers, 1)
        pending: dict[Any, Any] = {}
        source = iter(items)
        try:
            while True:
                _top_up(pending, source, limit, remote.remote)
                if not pending:
                    return
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    item = pending.pop(ref)
                    try:
                        yield item, ray.get(ref)
                    except Exception as exc:  # worker or node lost
                        yield item, exc
        finally:
            for ref in pending:
                ray.cancel(ref, force=True)


#: Backend name -> class.
BACKENDS = {"serial": SerialBackend, "local": LocalBackend, "ray": RayBackend}


def check_workers(workers: int | None) -> int | None:
    """``workers`` if it is None or a positive integer.

    Returns
    -------
    int or None
        ``workers``.

    Raises
    ------
    ValueError
        For anything else (zero, a negative number, a bool, a float).
    """
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool)
                                or workers < 1):
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    return workers


def map_in_order(fn: Callable[[Any], Any], items: Iterable[Any], workers: int | None = None,
                 on_done: Callable[[], Any] | None = None) -> list[Any]:
    """``[fn(item) for item in items]``, on a :class:`LocalBackend` of ``workers``
    processes (default: one per core, at most one per item), or in this process
    (:class:`SerialBackend`) for one. ``fn`` must be picklable (a module-level
    function or a :func:`functools.partial` of one). ``on_done`` is called as each
    item finishes (a progress bar). The first exception an item met is raised.

    Returns
    -------
    list
        The results, in the order of ``items``.
    """
    items = list(items)
    workers = min((os.cpu_count() or 1) if check_workers(workers) is None else workers,
                  max(len(items), 1))
    out: list[Any] = [None] * len(items)
    with (SerialBackend() if workers == 1 else LocalBackend(workers)) as backend:
        for i, outcome in backend.imap_unordered(partial(_apply_at, fn, items),
                                                 range(len(items))):
            if isinstance(outcome, BaseException):
                raise outcome
            out[i] = outcome
            if on_done is not None:
                on_done()
    return out


def _apply_at(fn: Callable[[Any], Any], items: list[Any], i: int) -> Any:
    """``fn(items[i])`` (positions keep equal items apart)."""
    return fn(items[i])


def make_backend(name: str, workers: int | None = None, address: str | None = None,
                 ship_code: bool = False) -> SerialBackend | LocalBackend | RayBackend:
    """A backend by name: ``"serial"``, ``"local"`` (``workers`` processes) or
    ``"ray"`` (``address``; ``workers`` CPUs of a local instance).

    Parameters
    ----------
    name : str
        A key of :data:`BACKENDS`: ``"serial"``, ``"local"`` or ``"ray"``.
    workers : int, optional
        Worker processes of ``"local"`` (default: one per core), or CPUs of
        a local Ray instance (default: all); ignored by ``"serial"``.
    address : str, optional
        ``ray.init`` address of a cluster (``"ray"`` only; None: a local
        instance).
    ship_code : bool
        Upload this project's packages with the Ray job (``"ray"`` only).

    Returns
    -------
    SerialBackend or LocalBackend or RayBackend
        A new backend, to be used as a context manager (a process pool or Ray
        starts on entry).

    Raises
    ------
    ValueError
        For an unknown name, or a ``workers`` that is not a positive integer.
    """
    if name == "serial":
        return SerialBackend()
    if name == "local":
        return LocalBackend(workers)
    if name == "ray":
        return RayBackend(address, num_cpus=workers, ship_code=ship_code)
    raise ValueError(f"backend must be one of {sorted(BACKENDS)}, got {name!r}")
