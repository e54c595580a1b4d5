"""Shared test set-up.

Tests mirror the packages (``tests/<package>/test_*.py``) and are imported
with pytest's ``importlib`` mode, so test modules in different folders may
share a name. Every test runs with BLAS at its default thread count unless
it says otherwise: results must not depend on it.
"""

from __future__ import annotations

import importlib.util
import inspect
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

#: The repository's benchmark scripts (not a package: loaded by path).
BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _load_benchmark(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` executed as a new module (each call a fresh one)."""
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def load_benchmark() -> Callable[[str], ModuleType]:
    """A function that loads a benchmark script by name, e.g.
    ``load_benchmark("bench_tracking")``, as a fresh module."""
    return _load_benchmark


@pytest.fixture(autouse=True)
def _no_fit_outlives_its_test():
    """Cancel the fits a test left running in the background (an adaptive loop's refit
    that fell due near the end of its episode): their workers hold BLAS at one thread,
    so a later test's result must not depend on them."""
    yield
    from identifiers import cancel_fits

    cancel_fits()


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, so a test's random data never depend on test order."""
    return np.random.default_rng(12345)


def pytest_make_parametrize_id(config: pytest.Config, val: object, argname: str) -> str | None:
    """Readable test ids: ``kwargs={'task': 'dance'}`` becomes ``task='dance'`` and a
    ``lambda: ImprovedRPBSID(0, 8)`` becomes ``ImprovedRPBSID(0, 8)``."""
    if isinstance(val, dict):
        return ",".join(f"{k}={v!r}" for k, v in val.items())[:60] or "empty"
    if callable(val) and getattr(val, "__name__", "") == "<lambda>":
        try:
            source = inspect.getsource(val).strip()
        except OSError:
            return None
        body = source.split("lambda", 1)[1].split(":", 1)[1]
        return " ".join(_expression(body).split())[:60]
    return None


def _expression(text: str) -> str:
    """The leading expression of ``text``: up to a top-level comma or an unmatched bracket."""
    depth = 0
    for i, ch in enumerate(text):
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
            if depth < 0:
                return text[:i].strip()
        elif ch in ",#\n" and depth == 0:
            return text[:i].strip()
    return text.strip()


@pytest.fixture(autouse=True)
def _private_score_cache(tmp_path_factory: pytest.TempPathFactory,
                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test its own cache of the comparators' scores
    (:mod:`spacecraft_lab.score_cache`, also for the commands it runs as
    subprocesses): nothing is read from or written to the user's cache, and no
    test sees what another stored, whatever the order."""
    monkeypatch.setenv("SPACECRAFT_CACHE_DIR", str(tmp_path_factory.mktemp("score-cache")))
