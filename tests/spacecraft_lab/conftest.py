"""Sweep tests run helper task functions (``sweep_tasks``) in spawned workers:
this folder must be importable there, so it is put on ``sys.path`` (inherited
by ``spawn`` children) and on ``PYTHONPATH`` (for subprocesses)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = str(Path(__file__).resolve().parent)
if HERE not in sys.path:
    sys.path.insert(0, HERE)
os.environ["PYTHONPATH"] = os.pathsep.join(
    p for p in (HERE, os.environ.get("PYTHONPATH", "")) if p)
