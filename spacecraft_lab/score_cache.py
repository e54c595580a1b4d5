"""A disk cache of the comparison controllers' scores, keyed by everything they depend on.

Every ``spacecraft train`` run scores the same LQG comparators on the same
evaluation episodes before it trains (1.3-1.9 minutes for the five on ten
episodes on the 2-core machine with four runs at once: a quarter to a third of
an 800k-step PPO run without features). Those scores are a pure function of the scenario, the env's
arguments, the episode seeds, the comparator and the code and libraries that
ran them, so a second run with the same settings reads them from here.

The key is a SHA-256 of a JSON document with:

* the inputs: scenario, env arguments, episode seeds, comparator name;
* the code: every file of the project's packages (``spacecraft_conventions``,
  ``spacecraft_env``, ``identifiers``, ``controllers``, ``spacecraft_lab``);
  any edit to any of them is a new key, so a stale score is never read;
* the numerical libraries' versions (numpy, scipy, numba, gymnasium) and the
  Python version and machine type.

Entries are JSON files written atomically (a temporary file renamed), so
processes that share the directory never read a half-written score; an entry
that cannot be read is ignored and scored again.

Where: ``$SPACECRAFT_CACHE_DIR`` if set (an empty value turns the cache off),
else ``$XDG_CACHE_HOME/flexible-spacecraft``, else
``~/.cache/flexible-spacecraft``. ``spacecraft train --no-cache`` (and
``evaluate``, ``adapt``) scores everything again without reading or writing.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import importlib.util
import json
import os
import platform
import sys
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["CACHE_ENV", "PACKAGES", "ScoreCache", "code_fingerprint", "default_cache"]

#: Environment variable naming the cache directory (empty: no cache).
CACHE_ENV = "SPACECRAFT_CACHE_DIR"
#: The packages whose files the key covers.
PACKAGES = ("spacecraft_conventions", "spacecraft_env", "identifiers", "controllers",
            "spacecraft_lab")
#: Libraries whose versions the key covers.
_LIBRARIES = ("numpy", "scipy", "numba", "gymnasium")
#: Bumped when an entry's layout changes.
_FORMAT = 1


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 (hex) of the project's package files, the libraries' versions, Python's
    version and the machine type: what a comparator's score depends on besides its
    inputs. Computed once per process."""
    digest = hashlib.sha256()
    for package in PACKAGES:
        spec = importlib.util.find_spec(package)
        roots = list(spec.submodule_search_locations or []) if spec else []
        for root in map(Path, roots):
            for path in sorted(p for p in root.rglob("*")
                               if p.is_file() and "__pycache__" not in p.parts):
                digest.update(f"{package}/{path.relative_to(root).as_posix()}\0".encode())
                digest.update(path.read_bytes())
    versions = {name: _version(name) for name in _LIBRARIES}
    versions["python"] = sys.version.split()[0]
    versions["machine"] = platform.machine()
    digest.update(json.dumps(versions, sort_keys=True).encode())
    return digest.hexdigest()


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "absent"


class ScoreCache:
    """Scores of the comparison controllers on disk, one JSON file per key.

    Parameters
    ----------
    directory : str or Path
        Where the entries live (created on the first write).

    Examples
    --------
    >>> import tempfile
    >>> from spacecraft_lab.score_cache import ScoreCache
    >>> cache = ScoreCache(tempfile.mkdtemp())
    >>> inputs = {"scenario": "docking", "env_kwargs": {"task": "slew"},
    ...           "seeds": [1000, 1001], "controller": "oracle_lqg"}
    >>> cache.get(inputs) is None
    True
    >>> cache.put(inputs, {"cost_after_100s": 0.0031, "stable_share": 1.0})
    >>> cache.get(inputs)
    {'cost_after_100s': 0.0031, 'stable_share': 1.0}
    """

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)

    def __repr__(self) -> str:
        return f"ScoreCache({str(self.directory)!r})"

    def key(self, inputs: dict[str, Any]) -> str:
        """SHA-256 (hex) of ``inputs`` (JSON-serializable) with :func:`code_fingerprint`.

        Returns
        -------
        str
            The key, 64 hex digits.

        Raises
        ------
        TypeError
            If ``inputs`` cannot be written as JSON.
        """
        document = json.dumps({"format": _FORMAT, "code": code_fingerprint(), **inputs},
                              sort_keys=True)
        return hashlib.sha256(document.encode()).hexdigest()

    def _path(self, inputs: dict[str, Any]) -> Path:
        return self.directory / f"{self.key(inputs)}.json"

    def get(self, inputs: dict[str, Any]) -> dict[str, Any] | None:
        """The score stored for ``inputs``, or None (never stored, or unreadable).

        Returns
        -------
        dict or None
            The stored score, or None.
        """
        try:
            with open(self._path(inputs), encoding="utf-8") as fh:
                entry = json.load(fh)
        except (OSError, ValueError):
            return None
        return entry.get("score") if isinstance(entry, dict) else None

    def put(self, inputs: dict[str, Any], score: dict[str, Any]) -> None:
        """Store ``score`` for ``inputs`` (atomically: a reader sees the old entry, none,
        or this one whole).

        Raises
        ------
        TypeError
            If ``score`` cannot be written as JSON.
        """
        text = json.dumps({"inputs": inputs, "score": score})
        self.directory.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.directory, suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(text)
            os.replace(tmp, self._path(inputs))
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


def default_cache() -> ScoreCache | None:
    """The cache at ``$SPACECRAFT_CACHE_DIR`` (None when set empty), else under
    ``$XDG_CACHE_HOME`` or ``~/.cache``, in ``flexible-spacecraft``.

    Returns
    -------
    ScoreCache or None
        The cache, or None when disabled.
    """
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return ScoreCache(chosen) if chosen.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return ScoreCache(Path(base) / "flexible-spacecraft")
