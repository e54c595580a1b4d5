"""The drive-scheduled fit's uncertainty: the covariance of the parameters the
inertia ``J(a)`` depends on, from the output-error fit's Jacobian (used by
:class:`~identifiers.structured.scheduled_fit.ScheduledFit`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from identifiers.structured.scheduled_model import ScheduledPhysicalModel

__all__: list[str] = []


def _inertia_parameters(model: ScheduledPhysicalModel) -> np.ndarray:
    """``[S's upper triangle; anisotropy; couplings]`` (see
    :attr:`~identifiers.structured.scheduled_fit.ScheduledFit.inertia_covariance`)."""
    return np.concatenate([model.rest_inertia[np.triu_indices(3)], model.drive_anisotropy,
                           model.couplings.ravel()])


def _with_inertia(model: ScheduledPhysicalModel, theta: np.ndarray) -> ScheduledPhysicalModel:
    """``model`` with the parameters of :func:`_inertia_parameters` replaced (the rest
    inertia is not checked for definiteness: a finite-difference neighbour)."""
    rest = np.zeros((3, 3))
    rest[np.triu_indices(3)] = theta[:6]
    rest = rest + np.triu(rest, 1).T
    n = model.n_modes
    clone = object.__new__(ScheduledPhysicalModel)
    for name in ("frequencies_hz", "damping", "turning", "tips", "sensor_appendage",
                 "drive_axis"):
        object.__setattr__(clone, name, getattr(model, name))
    object.__setattr__(clone, "rest_inertia", rest)
    object.__setattr__(clone, "drive_anisotropy", theta[6:8])
    object.__setattr__(clone, "couplings", theta[8:8 + 3 * n].reshape(n, 3))
    return clone


def _inertia_covariance(problem: Any, p: np.ndarray, jac: np.ndarray,
                        residuals: np.ndarray) -> np.ndarray:
    """``sigma^2 (J^T J)^-1`` of the parameters mapped to those of
    :func:`_inertia_parameters` (central differences)."""
    dof = max(residuals.size - p.size, 1)
    sigma2 = float(np.sum(residuals**2)) / dof
    cov = sigma2 * np.linalg.pinv(jac.T @ jac)
    step = 1e-6
    d = np.column_stack([(_inertia_parameters(problem.unpack(p + step * e)[0])
                          - _inertia_parameters(problem.unpack(p - step * e)[0])) / (2 * step)
                         for e in np.eye(p.size)])
    return d @ cov @ d.T
