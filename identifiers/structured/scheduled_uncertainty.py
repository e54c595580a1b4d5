"""The drive-scheduled fit's uncertainty: the record's white-noise floor, and the
covariance of the fitted parameters (those the inertia ``J(a)`` depends on) from
the output-error fit's Jacobian (used by
:func:`~identifiers.structured.scheduled_fit.fit_scheduled_model`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from identifiers.structured.scheduled_model import ScheduledPhysicalModel

__all__ = ["noise_floor"]


def noise_floor(y: np.ndarray, weights: np.ndarray) -> float:
    """Weighted mean square of the outputs' white noise, ``mean_i (w_i sigma_i)^2``:
    ``sigma_i`` from the median absolute deviation of the second differences
    (``var(y_{t+1} - 2 y_t + y_{t-1}) = 6 sigma^2`` for white noise; the
    slow signals of a 0.1 s sample contribute little), rows with a non-finite
    entry left out."""
    good = y[np.all(np.isfinite(y), axis=1)]
    if good.shape[0] < 8:
        return 0.0
    second = np.diff(good, n=2, axis=0)
    mad = np.median(np.abs(second - np.median(second, axis=0)), axis=0)
    return float(np.mean((weights * 1.4826 * mad / np.sqrt(6.0)) ** 2))


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


def _gain_derivative(model: ScheduledPhysicalModel, angle: float) -> np.ndarray:
    """(9, 8 + 3 N) derivative of ``J(a)^-1``'s row-major entries at drive angle
    ``a`` (rad) with respect to the parameters of :func:`_inertia_parameters`
    (central differences)."""
    theta = _inertia_parameters(model)
    step = 1e-6 * np.maximum(np.abs(theta), 1.0)
    columns = []
    for i, h in enumerate(step):
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        columns.append((_with_inertia(model, up).gain(angle)
                        - _with_inertia(model, down).gain(angle)).ravel() / (2 * h))
    return np.column_stack(columns)


def _parameter_covariance(p: np.ndarray, jac: np.ndarray, residuals: np.ndarray
                          ) -> np.ndarray:
    """``sigma^2 (J^T J)^-1`` of the packed parameters (white residuals assumed)."""
    dof = max(residuals.size - p.size, 1)
    sigma2 = float(np.sum(residuals**2)) / dof
    return sigma2 * np.linalg.pinv(jac.T @ jac)


def _inertia_covariance(problem: Any, p: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """The packed parameters' covariance ``cov`` mapped to the parameters of
    :func:`_inertia_parameters` (central differences)."""
    step = 1e-6
    d = np.column_stack([(_inertia_parameters(problem.unpack(p + step * e)[0])
                          - _inertia_parameters(problem.unpack(p - step * e)[0])) / (2 * step)
                         for e in np.eye(p.size)])
    return d @ cov @ d.T
