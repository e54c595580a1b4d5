"""What a record says about a held drive-scheduled fit, before (or beside) fitting it.

:func:`predicted_gain_covariance`: what a refit of the record would know about the
rigid-body gain, judged at the held parameters. :func:`held_misfit`: how well the
held model explains the record, its initial state refitted (what a refit after a
detected change must beat to replace it).

An accumulating refit (:class:`identifiers.ScheduledPhysicalIdentifier`) is a
nonlinear fit of seconds; on a record without the warm-up's excitation its gain
comes out less certain than the held fit's, and it is kept out. One Jacobian of
the output error at the held parameters on the new record (the Gauss-Newton
covariance ``sigma^2 (J^T J)^-1`` with the record's noise floor for
``sigma^2``, mapped to ``J(a)^-1`` as the fit maps its own) predicts that in
0.05-0.25 s, where the refits it finds not worth running took 1-31 s each in
the closed loop.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from identifiers.physical.scheduled_fit import ScheduledFit, _Problem
from identifiers.physical.scheduled_uncertainty import (
    _gain_derivative,
    _inertia_covariance,
    noise_floor,
)
from spacecraft_conventions import OutputLayout, single_threaded_blas

__all__ = ["held_misfit", "predicted_gain_covariance"]


def _held_problem(fit: ScheduledFit, u: ArrayLike, y: ArrayLike, angle: ArrayLike,
                  dt: float, layout: OutputLayout, initial_state: ArrayLike,
                  disturbance: bool) -> tuple[_Problem, np.ndarray]:
    """The fit's output-error problem on the record and the held fit's parameters in it
    (validated as :func:`predicted_gain_covariance` documents)."""
    u, y, angle = (np.asarray(v, dtype=float) for v in (u, y, angle))
    model = fit.model
    x0 = np.asarray(initial_state, dtype=float).reshape(-1)
    if u.ndim != 2 or u.shape[1] != 3 or y.shape != (u.shape[0], layout.size) \
            or angle.shape != (u.shape[0],) or x0.shape != (model.order,):
        raise ValueError(f"u, y, angle and initial_state must have shapes (T, 3), "
                         f"(T, {layout.size}), (T,) and ({model.order},), got {u.shape}, "
                         f"{y.shape}, {angle.shape} and {x0.shape}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(angle))
            and np.all(np.isfinite(x0))):
        raise ValueError("u, angle and initial_state must be finite")
    problem = _Problem(u, y, angle, float(dt), layout, 1.0 / layout.scales(), model.turning,
                       model.sensor_appendage, model.drive_axis, disturbance)
    p = problem.pack(model.rest_inertia, model.drive_anisotropy,
                     2 * np.pi * np.asarray(model.frequencies_hz), model.damping,
                     model.couplings, x0, fit.disturbance_torque)
    return problem, p


@single_threaded_blas
def predicted_gain_covariance(fit: ScheduledFit, u: ArrayLike, y: ArrayLike,
                              angle: ArrayLike, dt: float, layout: OutputLayout,
                              initial_state: ArrayLike) -> np.ndarray:
    """The covariance of ``J(a)^-1`` a fit of the record would have at ``fit``'s
    parameters, at the record's last drive angle.

    Parameters
    ----------
    fit : ScheduledFit
        The held fit; its model carries the appendages (which turn, which
        sensor sits on which, the drive's axis), and its constant disturbance
        torque is among the parameters where it kept one.
    u, y, angle, dt, layout
        The record, as for
        :func:`identifiers.physical.scheduled_fit.fit_scheduled_model`
        (default output weights).
    initial_state : (6 + 2 N,) array_like
        The held model's state at the record's first sample (physical units).

    Returns
    -------
    (9, 9) ndarray
        Covariance of ``J(a)^-1``'s row-major entries, (rad/s^2 per N m)^2: the
        record's white-noise floor (:func:`identifiers.physical.scheduled_fit.noise_floor`,
        what a refit's residuals reach: 1.04-1.14x it in the closed loop)
        times ``(J^T J)^-1`` of the output error's Jacobian at the held
        parameters, mapped as
        :meth:`identifiers.physical.scheduled_fit.ScheduledFit.gain_covariance`.
        Against the refit's own covariance, on the closed-loop refits measured
        (docs/design/control.md): its standard deviation 0.4-2.1x the refit's.

    Raises
    ------
    ValueError
        Shapes that do not match the held model, or non-finite torques,
        angles or initial state.
    """
    problem, p = _held_problem(fit, u, y, angle, dt, layout, initial_state,
                               bool(np.any(fit.disturbance_torque != 0)))
    model = fit.model
    lo, hi = problem.bounds(p.size)
    p = np.clip(p, lo + 1e-9, hi - 1e-9)
    jac = problem.jacobian(p, lo, hi)
    # the noise a refit would leave, not the held model's misfit of the new record:
    # that inflated the prediction 4-6x where the held fit had drifted from the plant
    cov = noise_floor(y, problem.w) * np.linalg.pinv(jac.T @ jac)
    d = _gain_derivative(model, float(angle[-1]))
    return d @ _inertia_covariance(problem, p, cov) @ d.T


@single_threaded_blas
def held_misfit(fit: ScheduledFit, u: ArrayLike, y: ArrayLike, angle: ArrayLike,
                dt: float, layout: OutputLayout, initial_state: ArrayLike) -> float:
    """The held model's mean squared output error on a record, its model held and its
    initial state and constant torque refitted.

    The same weighted residuals as the fit's
    :attr:`identifiers.physical.scheduled_fit.ScheduledFit.cost` (default output
    weights), so the two compare on one record: a refit of the
    record from the held fit reaches at most this (it starts there with more
    freedom). The state and the torque enter the simulation linearly; a
    Levenberg-Marquardt solve from ``initial_state`` and the fit's torque finds
    them (about 20 simulations of the record).

    Parameters
    ----------
    fit, u, y, angle, dt, layout, initial_state
        As for :func:`predicted_gain_covariance`.

    Returns
    -------
    float
        In the fit's cost units; inf where the held model cannot simulate the
        record.

    Raises
    ------
    ValueError
        As :func:`predicted_gain_covariance`.
    """
    problem, p = _held_problem(fit, u, y, angle, dt, layout, initial_state, True)
    first = p.size - problem.n_state
    mats = problem._matrices(p)
    if mats is None:
        return float("inf")
    blocks = mats[2:]

    def residuals(q: np.ndarray) -> np.ndarray:
        return problem._residuals((*problem._state_part(q), *blocks))[0]

    solution = least_squares(residuals, p[first:], method="lm")
    misfit = float(np.mean(solution.fun ** 2))
    return misfit if np.isfinite(misfit) else float("inf")
