"""Single-threaded BLAS around the library's small, per-sample kernels.

Every kernel of this project works on small matrices (at most a few hundred
rows) many times per second: an identifier update, a Riccati re-design, a
matrix exponential of the truth model. Multi-threaded BLAS does not pay off
there; worse, with OpenBLAS's threaded ``dger``/``dgemv`` a 200-wide rank-1
update costs 16-20 ms instead of 10 us on a busy 2-core machine, a 10-80x
slowdown, and threaded and unthreaded runs differ in the last bits. So the
library limits BLAS to one thread itself, for the duration of each such
call, and restores the user's setting afterwards: no user has to know.

:data:`single_threaded_blas` is a reentrant context manager and decorator.
Entering it costs a few microseconds (one ``get``/``set`` pair per loaded
BLAS library); nested entries cost a counter increment. The user's thread
count is restored when the outermost entry exits.

Opt-out: ``single_threaded_blas.enabled = False`` (or the environment
variable ``SPACECRAFT_BLAS_THREADS=keep`` at import) leaves BLAS threading
alone, e.g. to measure the difference.
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable
from typing import Any, TypeVar

from threadpoolctl import ThreadpoolController

__all__ = ["SingleThreadedBLAS", "single_threaded_blas"]

F = TypeVar("F", bound=Callable[..., Any])


class SingleThreadedBLAS:
    """Limit every loaded BLAS library to one thread while inside.

    Attributes
    ----------
    enabled : bool
        When False, entering does nothing (BLAS keeps the user's threads).
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = bool(enabled)
        self._lock = threading.Lock()
        self._local = threading.local()   # per thread: did each open entry count?
        self._depth = 0
        self._libraries: list[Any] | None = None
        self._saved: list[tuple[Any, int]] = []

    def _blas_libraries(self) -> list[Any]:
        """The loaded BLAS libraries' controllers (found once; numpy's and scipy's
        are loaded by the time any kernel of this project runs)."""
        if self._libraries is None:
            self._libraries = [lib for lib in ThreadpoolController().lib_controllers
                               if lib.user_api == "blas"]
        return self._libraries

    def __enter__(self) -> SingleThreadedBLAS:
        entries = self._local.__dict__.setdefault("entries", [])
        entries.append(self.enabled)
        if not self.enabled:
            return self
        with self._lock:
            if self._depth == 0:
                saved = []
                for lib in self._blas_libraries():
                    threads = lib.get_num_threads()
                    if threads != 1:
                        lib.set_num_threads(1)
                        saved.append((lib, threads))
                self._saved = saved
            self._depth += 1
        return self

    def __exit__(self, *exc: object) -> None:
        if not self._local.entries.pop():
            return
        with self._lock:
            self._depth -= 1
            if self._depth == 0:
                for lib, threads in self._saved:
                    lib.set_num_threads(threads)
                self._saved = []

    def __call__(self, func: F) -> F:
        """Decorate ``func`` so that it runs single-threaded."""

        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            with self:
                return func(*args, **kwargs)

        return wrapper  # type: ignore[return-value]

    def __reduce__(self) -> str:
        return "single_threaded_blas"   # pickles as the module-level instance


#: The project-wide instance: ``with single_threaded_blas: ...`` or
#: ``@single_threaded_blas`` on a method.
single_threaded_blas = SingleThreadedBLAS(
    enabled=os.environ.get("SPACECRAFT_BLAS_THREADS", "").lower() != "keep")
