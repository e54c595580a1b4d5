"""The drive-scheduled fit's uncertainty: the record's white-noise floor, and the
covariance of the fitted parameters (those the inertia ``J(a)`` depends on) from
the output-error fit's Jacobian (used by
:func:`identifiers.physical.scheduled_fit.fit_scheduled_model`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from identifiers.physical.scheduled_model import (
    ScheduledPhysicalModel,
    drive_rotation,
    plane_basis,
)

__all__ = ["noise_floor"]


def noise_floor(y: np.ndarray, weights: np.ndarray) -> float:
    """Weighted mean square of the outputs' white noise, ``mean_i (w_i sigma_i)^2``:
    ``sigma_i`` from the median absolute deviation of the second differences
    (``var(y_{t+1} - 2 y_t + y_{t-1}) = 6 sigma^2`` for white noise; the
    slow signals of a 0.1 s sample contribute little), rows with a non-finite
    entry left out.

    Returns
    -------
    float
        The weighted mean square noise, in the weights' units squared (1 at the assumed
        noise level).
    """
    good = y[np.all(np.isfinite(y), axis=1)]
    if good.shape[0] < 8:
        return 0.0
    second = np.diff(good, n=2, axis=0)
    mad = np.median(np.abs(second - np.median(second, axis=0)), axis=0)
    return float(np.mean((weights * 1.4826 * mad / np.sqrt(6.0)) ** 2))


def _inertia_parameters(model: ScheduledPhysicalModel) -> np.ndarray:
    """``[S's upper triangle; anisotropy; couplings]`` (see
    :attr:`identifiers.physical.scheduled_fit.ScheduledFit.inertia_covariance`)."""
    return np.concatenate([model.rest_inertia[np.triu_indices(3)], model.drive_anisotropy,
                           model.couplings.ravel()])


def _gain_derivative(model: ScheduledPhysicalModel, angle: float) -> np.ndarray:
    """(9, 8 + 3 N) derivative of ``J(a)^-1``'s row-major entries at drive angle
    ``a`` (rad) with respect to the parameters of :func:`_inertia_parameters`, in
    closed form: ``d(J^-1) = -J^-1 dJ J^-1`` with ``J(a) = S + F(a) F(a)^T +
    R(a)^T (|P| Pi + P) R(a)`` linear in ``S``, quadratic in the couplings (each
    column of ``F`` is a coupling, turned by ``R(a)^T`` where the drive carries
    its appendage) and, through ``|P|``, not differentiable at ``P = 0`` (there
    the derivative of ``|P|`` is taken as 0, the central difference's value).
    Until 2026-11-28 central differences, 16 gains per call (13 ms, about a third
    of the adaptive loop's time between fits in a profile); the two agree to about 1e-8 relative."""
    gain = model.gain(angle)
    n = model.n_modes
    d_inertia = np.zeros((8 + 3 * n, 3, 3))
    rows, cols = np.triu_indices(3)
    d_inertia[np.arange(6), rows, cols] = 1.0
    d_inertia[np.arange(6), cols, rows] = 1.0
    e1, e2 = plane_basis(model.drive_axis)
    r = drive_rotation(model.drive_axis, angle)
    p0, p1 = model.drive_anisotropy
    size = np.hypot(p0, p1)
    plane = np.outer(e1, e1) + np.outer(e2, e2)
    for k, (p, shape) in enumerate(((p0, np.outer(e1, e1) - np.outer(e2, e2)),
                                    (p1, np.outer(e1, e2) + np.outer(e2, e1)))):
        d_t0 = (p / size if size > 0 else 0.0) * plane + shape
        d_inertia[6 + k] = r.T @ d_t0 @ r
    f = model.coupling(angle)                                   # (3, N)
    for k in range(n):
        turn = r.T if model.turning[k] else np.eye(3)
        # d(f_k f_k^T) / dv_kj = t_j f_k^T + f_k t_j^T, t_j the j-th column of turn
        outer = turn.T[:, :, None] * f[None, :, k, None].transpose(0, 2, 1)
        d_inertia[8 + 3 * k:11 + 3 * k] = outer + outer.transpose(0, 2, 1)
    return -(gain @ d_inertia @ gain).reshape(d_inertia.shape[0], 9).T


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
