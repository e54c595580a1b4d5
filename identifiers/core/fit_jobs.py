"""The worker side of the fits off the control path: a fit on its own thread.

A :class:`FitJob` runs one fit on a fork of an identifier in a daemon thread
(single-threaded BLAS held for the whole fit, so its result does not depend on
timing), then replays on the fork the samples the caller handed it until its due
sample. The process keeps a registry of the running fits: :func:`cancel_fits` ends
them, and a fit nobody wants stops at its next :func:`cancellation_point`
(:class:`FitCancelled`). The identifier's side is
:class:`identifiers.core.background.BackgroundFits`.
"""

from __future__ import annotations

import gc
import math
import queue
import threading
import time
from concurrent.futures import Future
from typing import Any

import numpy as np

from spacecraft_conventions import single_threaded_blas

__all__ = ["FitCancelled", "FitJob", "cancel_fits", "cancellation_point"]

#: The background fit the current thread runs (a worker's), if any.
_current = threading.local()
#: The fits running in this process, each with its thread.
_running: dict[FitJob, threading.Thread] = {}
_running_lock = threading.Lock()
#: What a worker's replay takes from its queue when its fit is cancelled.
_STOP = object()


class FitCancelled(Exception):
    """A background fit whose result nobody will take (its identifier was reset or is
    gone) stopped at a :func:`cancellation_point`."""


def cancellation_point() -> None:
    """Stop a background fit that has been cancelled (raises :class:`FitCancelled`).

    The fitting code calls it once per model simulation (every function evaluation
    of an output-error fit); on any thread but a fit's worker, or for a fit still
    wanted, it only reads a thread-local attribute.
    """
    job = getattr(_current, "job", None)
    if job is not None and job.cancelled:
        raise FitCancelled


def cancel_fits(timeout: float = 10.0) -> int:
    """Cancel every fit running in the background in this process and wait for their
    threads.

    A fit's worker holds BLAS at one thread while it runs (its results do not depend
    on timing); at the end of a program, or between tests, this ends them.

    Parameters
    ----------
    timeout : float
        Seconds to wait for the threads in all.

    Returns
    -------
    int
        How many fits were running.
    """
    with _running_lock:
        running = list(_running.items())
    for job, _ in running:
        job.cancel()
    deadline = time.monotonic() + timeout
    for _, thread in running:
        thread.join(max(0.0, deadline - time.monotonic()))
    return len(running)


class FitJob:
    """A fit running on a worker thread: its fork, the samples received since, its due.

    The main thread hands each sample received while the fit runs to the worker
    (:meth:`receive`); once the fit is done, the worker replays on the fork the
    samples up to the due one, so the fork has caught up when the main thread takes
    it over, and the replay costs the control path nothing.
    """

    def __init__(self, action: str, sample: int, due: int | None) -> None:
        self.action = action
        self.sample = sample
        self.due = due
        self.cancelled = False
        self.future: Future = Future()
        self._queue: queue.SimpleQueue = queue.SimpleQueue()

    def receive(self, u: np.ndarray, y: np.ndarray, context: tuple) -> None:
        self._queue.put((u, y, context))

    def remaining(self) -> list[tuple[np.ndarray, np.ndarray, tuple]]:
        """The samples received that the worker's replay did not take (those past the due
        one: a measured charge's fit adopted later than its due sample).

        Returns
        -------
        list of (u, y, schedule)
            The samples, oldest first, each as it was received.
        """
        items = []
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return items
            if item is not _STOP:
                items.append(item)

    def cancel(self) -> None:
        """Nobody will take the result: stop at the next cancellation point."""
        self.cancelled = True
        self._queue.put(_STOP)

    def release(self) -> None:
        """Forget the identifier's finalizer (the fit is taken over or dropped)."""
        finalizer = self.__dict__.pop("finalizer", None)
        if finalizer is not None:
            finalizer.detach()

    def start(self, fork: Any, dt: float, name: str) -> None:
        thread = threading.Thread(target=self.run, args=(fork, dt), name=name, daemon=True)
        with _running_lock:
            _running[self] = thread
        thread.start()

    def run(self, fork: Any, dt: float) -> None:
        """The fit on ``fork``, then the replay of the samples until the due one (on the
        worker thread; the result, ``(fork, cpu_s, error)``, in :attr:`future`)."""
        _current.job = self
        try:
            self._run(fork, dt)
        finally:
            _current.job = None
            with _running_lock:
                _running.pop(self, None)

    def _run(self, fork: Any, dt: float) -> None:
        with single_threaded_blas:
            start = time.thread_time()
            try:
                getattr(fork, self.action)()
            except Exception as exc:      # reported by the caller, never raised there
                self.future.set_result((None, time.thread_time() - start, exc))
                return
            cpu = time.thread_time() - start
            if self.due is None:          # measured: its own CPU time, in samples
                self.due = self.sample + max(1, math.ceil(cpu / dt))
            fork._clock = self.due
            try:
                for _ in range(self.due - self.sample):
                    item = self._queue.get()
                    if item is _STOP:
                        raise FitCancelled
                    u, y, context = item
                    fork._restore_context(context)
                    fork.update(u, y)
            except Exception as exc:
                self.future.set_result((None, cpu, exc))
                return
            finally:
                fork._clock = 0
        gc.collect()                      # the fork's garbage, collected off the control path
        self.future.set_result((fork, cpu, None))

    def __getstate__(self) -> dict:
        raise TypeError("an identifier whose fit runs in the background cannot be copied "
                        "or pickled until the fit's model is taken over")
