"""Records the identifier tests share."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from identifiers import identification_inputs


def _rigid_body_record(inertia: np.ndarray, n_samples: int = 1500, dt: float = 0.1,
                       psi0: np.ndarray | None = None, omega0: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    g = np.linalg.inv(inertia)
    u = identification_inputs(n_samples, rng, dt)
    psi = np.zeros(3) if psi0 is None else np.asarray(psi0, dtype=float)
    omega = np.zeros(3) if omega0 is None else np.asarray(omega0, dtype=float)
    y = np.empty((n_samples, 6))
    for k in range(n_samples):
        y[k] = np.concatenate((psi, omega))
        psi = psi + dt * omega + 0.5 * dt * dt * g @ u[k]
        omega = omega + dt * g @ u[k]
    return u, y


@pytest.fixture
def rigid_body_record() -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``record(inertia, n_samples=1500, dt=0.1, psi0=0, omega0=0) -> (u, y)``: noise-free
    ZOH double integrators ``psi'' = J^-1 u`` (the rigid body alone) under multisine
    torques from ``np.random.default_rng(0)``; ``y`` is attitude (rad) then rate (rad/s)."""
    return _rigid_body_record
