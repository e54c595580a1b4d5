"""Fitting a :class:`identifiers.physical.scheduled_model.ScheduledPhysicalModel`
to a record of torques, outputs and drive angles by output error.

Two stages. Equation-error starts (:mod:`identifiers.physical.scheduled_start`): each
appendage's mode and coupling from a linear regression of its deflection's second
derivative, then the inertia and couplings from the hub's torque balance, on signals passed
through a state-variable filter ``1 / (tau s + 1)^3`` at several ``tau``. Then, from each
start, every parameter, the initial state and a constant disturbance torque included, by
bounded nonlinear least squares on the weighted simulation error (the model re-discretized
per :data:`identifiers.physical.scheduled_simulation.RESOLUTION` of drive travel; the tip
gains solved linearly inside every evaluation, variable projection), the best kept; a torque
whose Wald statistic is below the Bayesian information criterion's penalty is dropped and
the model refined without it. Output error needs nothing but the torques that acted, so
closed-loop data do not bias it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from identifiers.physical.physical_model import DAMPING_BOUNDS, FREQUENCY_BOUNDS_HZ
from identifiers.physical.scheduled_model import ScheduledPhysicalModel
from identifiers.physical.scheduled_simulation import (
    _block_angles,
    _block_bounds,
    _block_models,
    _run_blocks,
)
from identifiers.physical.scheduled_start import equation_error_start
from identifiers.physical.scheduled_uncertainty import (
    _gain_derivative,
    _inertia_covariance,
    _parameter_covariance,
    noise_floor,
)
from spacecraft_conventions import OutputLayout, single_threaded_blas

__all__ = ["ScheduledFit", "fit_scheduled_model", "noise_floor"]

#: Scales of the fitted parameters (they only condition the problem): inertia
#: kg m^2, coupling kg^1/2 m, anisotropy kg m^2, initial state, disturbance N m.
_INERTIA, _COUPLING, _ANISOTROPY, _STATE, _TORQUE = 2e4, 30.0, 1e3, 1e-3, 1e-2


@dataclass(frozen=True)
class ScheduledFit:
    """What :func:`fit_scheduled_model` returns.

    Attributes
    ----------
    model : ScheduledPhysicalModel
    initial_state : (6 + 2 N,) ndarray
        The fitted state at the record's first sample.
    inertia_covariance : (8 + 3 N, 8 + 3 N) ndarray
        Covariance of the parameters ``J(a)`` depends on, ``[S's upper
        triangle (row-major, 6); the anisotropy (2); the couplings (3 N,
        row-major)]`` (kg m^2, kg^1/2 m), from the least-squares Jacobian
        and the residual variance (white residuals assumed).
    cost : float
        Weighted mean square error per output sample (1 at the noise level
        the weights assume).
    noise_floor : float
        The record's white-noise floor in the same units (:func:`noise_floor`):
        ``cost / noise_floor`` near 1 is a fit down to the noise, well above 1
        an unmodelled part (noise-free records: the plant's further modes).
    disturbance_torque : (3,) ndarray
        The constant body-frame torque, N m, that acted besides ``u`` over the
        record (gravity gradient, solar pressure, a biased wheel); zeros when
        the fit did not estimate one.
    disturbance_covariance : (3, 3) ndarray
        Its covariance, (N m)^2, as :attr:`inertia_covariance` (zeros when not
        estimated).
    disturbance_statistic : float
        The fitted torque's Wald statistic ``d^T Cov(d)^-1 d`` (chi-square with
        3 degrees of freedom where none acts; NaN when none was fitted). Below
        the fit's ``disturbance_threshold`` the torque is set to zero and the
        model refitted without it.
    """

    model: ScheduledPhysicalModel
    initial_state: np.ndarray
    inertia_covariance: np.ndarray
    cost: float
    noise_floor: float = float("nan")
    disturbance_torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    disturbance_covariance: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    disturbance_statistic: float = float("nan")

    def gain_covariance(self, angle: float) -> np.ndarray:
        """:attr:`inertia_covariance` through the gain's derivative (central differences) at
        drive angle ``a`` (rad): the band widens where the fitted anisotropy is extrapolated.

        Returns
        -------
        (9, 9) ndarray
            Covariance of ``J(a)^-1``'s row-major entries, (rad/s^2 per N m)^2.
        """
        d = _gain_derivative(self.model, angle)
        return d @ self.inertia_covariance @ d.T


class _Problem:
    """The weighted simulation error as a function of ``[tril(log-diagonal Cholesky of
    S / _INERTIA)] (6); P / _ANISOTROPY (2); log w (N); log zeta (N); v / _COUPLING
    (3 N); x0 / _STATE (6 + 2 N); d / _TORQUE (3, with ``disturbance``)]``; the
    constant torque ``d`` adds to every ``u``."""

    def __init__(self, u, y, angle, dt, layout, weights, turning, sensors, axis,
                 disturbance: bool = False) -> None:
        # contiguous: the compiled simulation reads it every evaluation
        self.u = np.ascontiguousarray(u, dtype=float)
        self.angle, self.dt, self.layout = angle, dt, layout
        self.good = np.all(np.isfinite(y), axis=1)
        self.y = y[self.good]
        self.w = weights
        self.att, self.rate = layout.indices("attitude"), layout.indices("rate")
        self.defl = layout.indices("deflection") if "deflection" in layout.names \
            else np.zeros(0, dtype=int)
        self.turning, self.sensors, self.axis = turning, sensors, axis
        self.n = turning.size
        self.n_state = 6 + 2 * self.n + (3 if disturbance else 0)   # the trailing entries
        self.disturbance = disturbance
        self.block_bounds = _block_bounds(angle, None)
        self.block_angles = _block_angles(angle, self.block_bounds)
        self._last: tuple[bytes, np.ndarray, tuple | None] | None = None

    def unpack(self, p: np.ndarray, tips: np.ndarray | None = None
               ) -> tuple[ScheduledPhysicalModel, np.ndarray, np.ndarray]:
        """(model, x0, d) of ``p`` (``d`` zeros without ``disturbance``)."""
        n = self.n
        lower = np.zeros((3, 3))
        lower[np.tril_indices(3)] = p[:6]
        lower[np.diag_indices(3)] = np.exp(lower[np.diag_indices(3)])
        model = ScheduledPhysicalModel._trusted(
            _INERTIA * lower @ lower.T, _ANISOTROPY * p[6:8], np.exp(p[8:8 + n]) / (2 * np.pi),
            np.exp(p[8 + n:8 + 2 * n]), _COUPLING * p[8 + 2 * n:8 + 5 * n].reshape(n, 3),
            self.turning, np.zeros(self.sensors.size) if tips is None else tips, self.sensors,
            self.axis)
        x0, d = self._state_part(p[8 + 5 * n:])
        return model, x0, d

    def _state_part(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x0, d) of the trailing ``n_state`` entries."""
        k = 6 + 2 * self.n
        return _STATE * q[:k], (_TORQUE * q[k:] if self.disturbance else np.zeros(3))

    def pack(self, rest, anisotropy, w, zeta, couplings, x0, d=(0.0, 0.0, 0.0)) -> np.ndarray:
        lower = np.linalg.cholesky(rest / _INERTIA)
        lower[np.diag_indices(3)] = np.log(lower[np.diag_indices(3)])
        return np.concatenate([lower[np.tril_indices(3)], np.asarray(anisotropy) / _ANISOTROPY,
                               np.log(w), np.log(zeta), np.ravel(couplings) / _COUPLING,
                               np.asarray(x0) / _STATE]
                              + ([np.asarray(d, dtype=float) / _TORQUE] if self.disturbance
                                 else []))

    def _matrices(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(x0, d, A_d, B_d)`` of every block for parameters ``p``; None where the
        model breaks."""
        try:
            model, x0, d = self.unpack(p)
            ad, bd = _block_models(model, self.block_angles, self.dt)
        except (np.linalg.LinAlgError, ValueError):
            return None
        return x0, d, ad, bd

    def _residuals(self, mats: tuple | None) -> tuple[np.ndarray, np.ndarray]:
        """(weighted residuals, tip gains) of the simulation on ``mats``; residuals of
        1e6 where the model breaks."""
        x = None
        if mats is not None:
            x0, d, ad, bd = mats
            states = np.empty((self.u.shape[0], ad.shape[1]))
            u = self.u + d if self.disturbance else self.u
            _run_blocks(ad, bd, u, self.block_bounds, x0, states)
            x = states[self.good]
        if x is None or not np.all(np.isfinite(x)):
            return np.full(int(self.good.sum()) * self.layout.size, 1e6), np.zeros(
                self.sensors.size)
        y, w = self.y, self.w
        parts = [((y[:, self.att] - x[:, 0:3]) * w[self.att]).ravel(),
                 ((y[:, self.rate] - x[:, 3:6]) * w[self.rate]).ravel()]
        tips = np.zeros(self.sensors.size)
        for i, (row, k) in enumerate(zip(self.defl, self.sensors, strict=True)):
            eta = x[:, 6 + k]
            tips[i] = (eta @ y[:, row]) / max(eta @ eta, 1e-30)
            parts.append((y[:, row] - tips[i] * eta) * w[row])
        return np.concatenate(parts), tips

    def evaluate(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(weighted residuals, tip gains); residuals of 1e6 where the model breaks."""
        mats = self._matrices(p)
        residuals, tips = self._residuals(mats)
        self._last = (p.tobytes(), residuals, mats)
        return residuals, tips

    def jacobian(self, p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Forward differences of :meth:`evaluate` (steps ``sqrt(eps) max(1, |p_i|)``,
        taken backward where forward would leave the bounds). The initial state's and
        the disturbance's columns reuse the blocks' matrices at ``p``: they do not
        depend on them."""
        if self._last is None or self._last[0] != p.tobytes():
            self.evaluate(p)
        _, f0, mats = self._last
        sign = np.where(p >= 0, 1.0, -1.0)
        h = np.sqrt(np.finfo(float).eps) * sign * np.maximum(1.0, np.abs(p))
        h = np.where((p + h > hi) | (p + h < lo), -h, h)
        h = (p + h) - p
        jac = np.empty((f0.size, p.size))
        first_state = p.size - self.n_state
        for i in range(p.size):
            q = p.copy()
            q[i] += h[i]
            if i < first_state or mats is None:
                f = self._residuals(self._matrices(q))[0]
            else:
                f = self._residuals((*self._state_part(q[first_state:]), *mats[2:]))[0]
            jac[:, i] = (f - f0) / h[i]
        return jac

    def bounds(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        lo, hi = np.full(size, -np.inf), np.full(size, np.inf)
        lo[:6], hi[:6] = -6.0, 6.0
        lo[8:8 + n], hi[8:8 + n] = np.log(2 * np.pi * np.array(FREQUENCY_BOUNDS_HZ))
        lo[8 + n:8 + 2 * n], hi[8 + n:8 + 2 * n] = np.log(DAMPING_BOUNDS)
        return lo, hi

    def solve(self, p0: np.ndarray, max_nfev: int):
        lo, hi = self.bounds(p0.size)
        p0 = np.clip(p0, lo + 1e-9, hi - 1e-9)
        return least_squares(lambda p: self.evaluate(p)[0], p0,
                             jac=lambda p: self.jacobian(p, lo, hi), method="trf",
                             x_scale="jac", bounds=(lo, hi), max_nfev=max_nfev)


@single_threaded_blas
def fit_scheduled_model(u: ArrayLike, y: ArrayLike, angle: ArrayLike, dt: float,
                        layout: OutputLayout, turning: Sequence[bool], *,
                        sensor_appendage: Sequence[int] | None = None,
                        drive_axis: ArrayLike = (0.0, 1.0, 0.0),
                        weights: ArrayLike | None = None,
                        filter_constants: Sequence[float] = (1.0, 0.5, 2.0, 3.0),
                        good_enough: float | None = None, start_nfev: int = 60,
                        max_nfev: int = 150, disturbance: bool = True,
                        disturbance_threshold: float | None = None,
                        initial: tuple[ScheduledPhysicalModel, ArrayLike]
                        | tuple[ScheduledPhysicalModel, ArrayLike, ArrayLike] | None = None
                        ) -> ScheduledFit:
    """Fit a :class:`ScheduledPhysicalModel` to a record by output error.

    Parameters
    ----------
    u : (T, 3) array_like
        Applied torques, N m (the actuators' output).
    y : (T, m) array_like
        Outputs in the order of ``layout`` (rad, rad/s, m); rows with a
        non-finite entry are left out of the error.
    angle : (T,) array_like
        The drive angle at each sample, rad (the drive's encoder).
    dt : float
        Sample time, s.
    layout : OutputLayout
        Attitude, rate and deflection groups, all required.
    turning : sequence of bool
        One flag per appendage (one mode each): whether the drive carries it.
    sensor_appendage : sequence of int, optional
        The appendage of each deflection sensor (default: sensor i on appendage
        i); every appendage needs a sensor.
    drive_axis : (3,) array_like
        The drive's axis in the body frame (normalized here).
    weights : (m,) array_like, optional
        Weight of each output's error (default one over the layout's nominal
        levels, i.e. one over the noise when every channel has the same SNR).
    filter_constants : sequence of float
        The equation-error starts' filter constants, s, refined in this order
        (a start whose regression fails is passed over).
    good_enough : float, optional
        Stop at the first refined start whose weighted mean square error is
        below this multiple of the record's noise floor (:func:`noise_floor`).
        Default: refine every start and keep the best. Stopping early saves
        time but, at low SNR, basins whose costs differ by a few percent of
        the noise floor look alike (paddle rotation at 30 dB: a start with
        the rigid gain 61 % off stopped at 1.06x the floor, where the best
        start, 15 % off, reached 1.05x).
    start_nfev : int
        Function evaluations of each start's refinement.
    max_nfev : int
        Function evaluations in all for the kept start (it continues if its
        first refinement stopped at ``start_nfev``).
    disturbance : bool
        Fit a constant body-frame torque ``d`` (N m) acting besides ``u``
        (default True). Without it a steady torque (gravity gradient, solar
        pressure) is read as inertia: under 0.05 N m per axis the closed-loop
        paddle rotation's rigid-body gain was 40 % off (median of 10 seeds),
        1 % with it.
    disturbance_threshold : float, optional
        The fitted torque is kept only if its Wald statistic
        (:attr:`ScheduledFit.disturbance_statistic`) reaches this value; below
        it the model is refined without it. Default ``3 ln N`` (``N`` the
        number of residuals), the Bayesian information criterion's penalty
        for three parameters (24 for 30 s, 28 for 120 s of ten outputs): a
        fixed chi-square quantile kept torques that a misfit made look
        significant. 0 keeps it always.
    initial : (ScheduledPhysicalModel, (6 + 2 N,) array_like[, (3,) array_like])
        A model, its state at the record's first sample and optionally the
        disturbance torque (default zero) to refine first, before the
        equation-error starts (a refit after a change starts from the model it
        replaces); it must have this call's appendages.

    Returns
    -------
    ScheduledFit

    Raises
    ------
    ValueError
        Shapes that do not match, a layout without the three groups, an
        appendage without a sensor, non-finite torques or angles.
    """
    if disturbance_threshold is not None and not disturbance_threshold >= 0.0:
        raise ValueError(f"disturbance_threshold must be >= 0 or None, got "
                         f"{disturbance_threshold}")
    u, y, angle = (np.asarray(v, dtype=float) for v in (u, y, angle))
    if u.ndim != 2 or u.shape[1] != 3 or y.shape != (u.shape[0], layout.size) \
            or angle.shape != (u.shape[0],):
        raise ValueError(f"u, y and angle must have shapes (T, 3), (T, {layout.size}) and "
                         f"(T,), got {u.shape}, {y.shape} and {angle.shape}")
    if set(layout.names) != {"attitude", "rate", "deflection"}:
        raise ValueError(f"the layout must hold attitude, rate and deflection, "
                         f"got {layout.names}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(angle))):
        raise ValueError("u and angle must be finite (the torques that acted, the encoder)")
    turning = np.asarray(turning, dtype=bool).reshape(-1)
    n_tip = layout.indices("deflection").size
    sensors = np.arange(n_tip) if sensor_appendage is None else \
        np.asarray(sensor_appendage, dtype=int).reshape(-1)
    if sensors.shape != (n_tip,) or set(sensors.tolist()) != set(range(turning.size)):
        raise ValueError(f"sensor_appendage must give each of the {n_tip} deflection sensors "
                         f"an appendage in [0, {turning.size}), each appendage at least one "
                         f"sensor; got {sensors.tolist()}")
    axis = np.asarray(drive_axis, dtype=float).reshape(3)
    if not np.isfinite(axis).all() or np.linalg.norm(axis) == 0:
        raise ValueError(f"drive_axis must be a finite non-zero 3-vector, got {axis}")
    axis = axis / np.linalg.norm(axis)
    w = 1.0 / layout.scales() if weights is None else np.asarray(weights, dtype=float)
    problem = _Problem(u, y, angle, float(dt), layout, w, turning, sensors, axis,
                       bool(disturbance))
    floor = noise_floor(y, w)
    starts: list = list(filter_constants)
    if initial is not None:
        model0, x0, *d0 = initial
        x0 = np.asarray(x0, dtype=float).reshape(-1)
        d0 = np.asarray(d0[0] if d0 else np.zeros(3), dtype=float).reshape(-1)
        if model0.n_modes != turning.size or x0.shape != (6 + 2 * turning.size,) \
                or d0.shape != (3,) or not np.all(np.isfinite(d0)) or len(initial) > 3:
            raise ValueError(f"initial must be a model of {turning.size} appendages, its "
                             f"({6 + 2 * turning.size},) state and optionally a finite (3,) "
                             f"torque, got {model0.n_modes}, {x0.shape} and {d0.shape} "
                             f"({len(initial)} items)")
        starts.insert(0, problem.pack(model0.rest_inertia, model0.drive_anisotropy,
                                      2 * np.pi * np.asarray(model0.frequencies_hz),
                                      model0.damping, model0.couplings, x0, d0))
    best = None
    for start in starts:
        try:
            p0 = start if isinstance(start, np.ndarray) else \
                equation_error_start(problem, y, float(start))
        except (np.linalg.LinAlgError, ValueError):
            continue
        solution = problem.solve(p0, start_nfev)
        if best is None or solution.cost < best.cost:
            best = solution
        if good_enough is not None and 2.0 * best.cost / best.fun.size < good_enough * floor:
            break
    if best is None:
        raise np.linalg.LinAlgError("no equation-error start was usable on this record")
    if best.status == 0 and max_nfev > start_nfev:      # stopped by the budget
        best = problem.solve(best.x, max_nfev - start_nfev)
    residuals, tips = problem.evaluate(best.x)
    cov = _parameter_covariance(best.x, best.jac, residuals)
    model, x0, d = problem.unpack(best.x, tips)
    d_cov = _TORQUE**2 * cov[-3:, -3:] if disturbance else np.zeros((3, 3))
    statistic = float(d @ np.linalg.pinv(d_cov) @ d) if disturbance else float("nan")
    threshold = 3.0 * np.log(residuals.size) if disturbance_threshold is None \
        else disturbance_threshold
    if disturbance and statistic < threshold:
        # not told from zero: the model without it, refined from this fit
        problem = _Problem(u, y, angle, float(dt), layout, w, turning, sensors, axis)
        best = problem.solve(best.x[:-3], start_nfev)
        residuals, tips = problem.evaluate(best.x)
        cov = _parameter_covariance(best.x, best.jac, residuals)
        model, x0, d = problem.unpack(best.x, tips)
        d_cov = np.zeros((3, 3))
    return ScheduledFit(model, x0, _inertia_covariance(problem, best.x, cov),
                        float(np.mean(residuals**2)), floor, d, d_cov, statistic)
