"""Shared test set-up.

Tests mirror the packages (``tests/<package>/test_*.py``) and are imported
with pytest's ``importlib`` mode, so test modules in different folders may
share a name. Every test runs with BLAS at its default thread count unless
it says otherwise: results must not depend on it.
"""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, so a test's random data never depend on test order."""
    return np.random.default_rng(12345)
