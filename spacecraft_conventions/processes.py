"""Worker processes that do not outlive their driver, and a driver that stops on SIGTERM.

Both the closed-loop comparison (:func:`controllers.compare`) and the sweeps run
seeds on a ``spawn`` process pool. A pool's workers wait on a pipe for their
next task; when the driver dies without shutting the pool down (``kill``,
a batch scheduler's SIGTERM or SIGKILL, a crash) they used to stay behind as
orphans. :func:`exit_with_parent`, a pool initializer, ends each worker
within a second of its parent's death; :func:`sigterm_as_interrupt` makes
SIGTERM unwind a driver like Ctrl-C, so it stops its pool and keeps what it
finished; :func:`exit_now` ends a driver whose pool thread cannot be joined.
"""

from __future__ import annotations

import contextlib
import multiprocessing.util
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from typing import NoReturn

__all__ = ["exit_now", "exit_with_parent", "sigterm_as_interrupt"]


def _watch(parent: int, period: float) -> None:
    while True:
        time.sleep(period)
        if os.getppid() != parent:        # re-parented: the driver is gone
            os._exit(1)


def exit_with_parent(period: float = 1.0, parent: int | None = None) -> None:
    """Pool initializer: end this process (``os._exit(1)``) once its parent has died,
    by whatever means (a daemon thread polls the parent process id).

    Parameters
    ----------
    period : float
        Seconds between polls: the process ends at most this long after its parent.
    parent : int, optional
        The driver's process id, passed by the driver
        (``initargs=(period, os.getpid())``). A worker whose driver dies while it
        is still starting up (a ``spawn`` worker imports for seconds before its
        initializer runs) is already re-parented when it gets here, so the id it
        would read now is not its driver's and it would never notice; given the
        driver's id, it ends at once. Default: the parent at the time of the call.
    """
    parent = os.getppid() if parent is None else int(parent)
    if os.getppid() != parent:            # the driver died while this worker started
        os._exit(1)
    threading.Thread(target=_watch, args=(parent, float(period)), daemon=True,
                     name="exit-with-parent").start()


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While inside, SIGTERM raises ``KeyboardInterrupt`` in the main thread (as
    Ctrl-C does); outside the main thread, or when a SIGTERM handler is already
    installed, it changes nothing.

    Returns
    -------
    contextlib.AbstractContextManager
        A context manager; the default SIGTERM disposition is restored on exit.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL):
        yield
        return

    def handler(signum: int, frame: object) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def exit_now(status: int, message: str = "") -> NoReturn:
    """End this process at once with ``status``, ``message`` the last line on stderr.

    For a driver whose stopped pool left a thread blocked for good (a normal exit
    would join it and hang). Nothing is joined, but multiprocessing's own
    non-blocking exit work runs first: the semaphores of the pool's queues are
    unlinked, so its resource tracker does not print a "leaked semaphore
    objects" warning after ``message``.

    Parameters
    ----------
    status : int
        The exit status (130 after an interrupt).
    message : str
        Written to stderr as is (end it with a newline) after stdout is flushed.

    Returns
    -------
    NoReturn
        Never: the process ends (``os._exit``).
    """
    # the finalizers of priority >= 0 are what multiprocessing's exit runs before it
    # joins anything: queues closed, semaphores unlinked and unregistered. Private
    # to multiprocessing, so a Python without it only loses the tidy-up
    run_finalizers = getattr(multiprocessing.util, "_run_finalizers", None)
    if run_finalizers is not None:
        with contextlib.suppress(Exception):
            run_finalizers(0)
    sys.stdout.flush()
    sys.stderr.write(message)
    sys.stderr.flush()
    os._exit(status)
