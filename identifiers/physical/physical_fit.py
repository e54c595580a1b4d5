"""Fitting a :class:`identifiers.physical.physical_model.PhysicalModel` to a record
by output error (nonlinear least squares on the simulation error)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from identifiers.core.modal_kernels import oscillator_zoh as mode_zoh
from identifiers.physical.physical_model import (
    DAMPING_BOUNDS,
    FREQUENCY_BOUNDS_HZ,
    PhysicalModel,
    mode_response,
    simulate,
)
from spacecraft_conventions import OutputLayout, single_threaded_blas

__all__ = ["GAIN_SCALE", "PhysicalFit", "fit_physical_model"]

#: Typical size of ``J^-1`` (rad/s^2 per N m): scales the fitted parameters only.
GAIN_SCALE = 4e-5
#: Scale of the fitted initial state (rad, rad/s, modal coordinates).
_STATE_SCALE = 1e-3


@dataclass(frozen=True)
class PhysicalFit:
    """What :func:`fit_physical_model` returns.

    Attributes
    ----------
    model : PhysicalModel
    initial_state : (6 + 2 N,) ndarray
        The fitted state at the record's first sample.
    gain_covariance : (9, 9) ndarray
        Covariance of ``model.gain`` (row-major entries), (rad/s^2 per N m)^2,
        from the least-squares Jacobian and the residual variance (white
        residuals assumed).
    cost : float
        Weighted mean square error per output sample (1 at the noise level
        the weights assume).
    """

    model: PhysicalModel
    initial_state: np.ndarray
    gain_covariance: np.ndarray
    cost: float


class _Problem:
    """The weighted simulation error of a record as a function of the parameters
    ``[tril(log-diagonal L / sqrt(GAIN_SCALE)) (6); per mode (log w, log zeta, phi /
    sqrt(GAIN_SCALE)) (5 N); x0 / _STATE_SCALE (6 + 2 N)]``."""

    def __init__(self, u: np.ndarray, y: np.ndarray, dt: float, layout: OutputLayout,
                 weights: np.ndarray) -> None:
        self.u, self.dt, self.layout = u, dt, layout
        self.good = np.all(np.isfinite(y), axis=1)
        self.y = y[self.good]
        self.w = weights
        self.att, self.rate = layout.indices("attitude"), layout.indices("rate")
        self.defl = layout.indices("deflection") if "deflection" in layout.names \
            else np.zeros(0, dtype=int)

    @staticmethod
    def gain(p: np.ndarray) -> np.ndarray:
        lower = np.zeros((3, 3))
        lower[np.tril_indices(3)] = p[:6]
        lower[np.diag_indices(3)] = np.exp(lower[np.diag_indices(3)])
        lower *= np.sqrt(GAIN_SCALE)
        return lower @ lower.T

    def unpack(self, p: np.ndarray, n: int) -> tuple[PhysicalModel, np.ndarray]:
        modes = p[6:6 + 5 * n].reshape(n, 5)
        tips = np.zeros((self.defl.size, n))
        model = PhysicalModel(self.gain(p), np.exp(modes[:, 0]) / (2 * np.pi),
                              np.exp(modes[:, 1]), np.sqrt(GAIN_SCALE) * modes[:, 2:5], tips)
        return model, _STATE_SCALE * p[6 + 5 * n:]

    @staticmethod
    def pack(model: PhysicalModel, x0: np.ndarray) -> np.ndarray:
        lower = np.linalg.cholesky(model.gain / GAIN_SCALE)
        lower[np.diag_indices(3)] = np.log(lower[np.diag_indices(3)])
        modes = np.column_stack([np.log(2 * np.pi * model.frequencies_hz),
                                 np.log(model.damping),
                                 model.couplings / np.sqrt(GAIN_SCALE)])
        return np.concatenate([lower[np.tril_indices(3)], modes.ravel(), x0 / _STATE_SCALE])

    def residuals(self, p: np.ndarray, n: int) -> np.ndarray:
        return self._evaluate(p, n)[0]

    def _evaluate(self, p: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
        model, x0 = self.unpack(p, n)
        attitude, rate, q = simulate(model, self.u, self.dt, x0)
        attitude, rate, q = attitude[self.good], rate[self.good], q[self.good]
        parts = [(self.y[:, self.att] - attitude) * self.w[self.att],
                 (self.y[:, self.rate] - rate) * self.w[self.rate]]
        tips = np.zeros((self.defl.size, n))
        if self.defl.size:
            yd = self.y[:, self.defl]
            if n:
                tips = np.linalg.lstsq(q, yd, rcond=None)[0].T
            parts.append((yd - q @ tips.T) * self.w[self.defl])
        r = np.concatenate([part.ravel() for part in parts])
        if not np.all(np.isfinite(r)):
            r = np.full(r.size, 1e6)
        return r, tips

    def bounds(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        size = 6 + 5 * n + 6 + 2 * n
        lo, hi = np.full(size, -np.inf), np.full(size, np.inf)
        lo[:6], hi[:6] = -8.0, 8.0
        f_lo, f_hi = (np.log(2 * np.pi * f) for f in FREQUENCY_BOUNDS_HZ)
        z_lo, z_hi = np.log(DAMPING_BOUNDS[0]), np.log(DAMPING_BOUNDS[1])
        lo[6:6 + 5 * n:5], hi[6:6 + 5 * n:5] = f_lo, f_hi
        lo[7:6 + 5 * n:5], hi[7:6 + 5 * n:5] = z_lo, z_hi
        return lo, hi

    def solve(self, p0: np.ndarray, n: int, max_nfev: int):
        lo, hi = self.bounds(n)
        p0 = np.clip(p0, lo + 1e-9, hi - 1e-9)
        return least_squares(self.residuals, p0, args=(n,), method="trf", x_scale="jac",
                             bounds=(lo, hi), max_nfev=max_nfev)

    def candidate(self, p: np.ndarray, n: int, frequency_hz: float,
                  damping: float) -> tuple[np.ndarray, float]:
        """A new mode's coupling at ``(frequency_hz, damping)``: the rank-1 ``phi phi^T``
        that best explains the rate error left by the current fit, and how much of
        its square it explains."""
        model, x0 = self.unpack(p, n)
        rate_error = (self.y[:, self.rate] - simulate(model, self.u, self.dt, x0)[1][self.good])
        ad, bd = mode_zoh(frequency_hz, damping, self.dt)
        responses = np.column_stack([mode_response(ad, bd, self.u[:, a], np.zeros(2))[:, 1]
                                     for a in range(3)])[self.good]
        fitted = np.linalg.lstsq(responses, rate_error, rcond=None)[0].T
        eigval, eigvec = np.linalg.eigh(0.5 * (fitted + fitted.T))
        phi = np.sqrt(max(eigval[-1], 1e-12)) * eigvec[:, -1]
        left = rate_error - responses @ np.outer(phi, phi)
        gain = float(np.sum(rate_error**2) - np.sum(left**2))
        return phi, gain


@single_threaded_blas
def fit_physical_model(u: ArrayLike, y: ArrayLike, dt: float, layout: OutputLayout, *,
                       n_modes: int = 4, weights: ArrayLike | None = None,
                       grid_hz: ArrayLike | None = None, start_damping: float = 0.02,
                       max_nfev: int = 200) -> PhysicalFit:
    """Fit a :class:`PhysicalModel` to a record by output error.

    The rigid body first, then one mode at a time: each new mode starts at
    the grid frequency whose rank-1 coupling explains most of the rate error
    left, and every parameter (the initial state included) is refitted after
    each addition by bounded least squares on the weighted simulation error.

    Parameters
    ----------
    u : (T, 3) array_like
        Applied torques, N m (after saturation: what acted).
    y : (T, m) array_like
        Outputs in the order of ``layout`` (rad, rad/s, m); rows with a
        non-finite entry are left out of the error.
    dt : float
        Sample time, s.
    layout : OutputLayout
        The output groups (attitude and rate required; deflection optional).
    n_modes : int
        N (default 4: the modes below 0.2 Hz of the ETS-VIII model).
    weights : (m,) array_like, optional
        Weight of each output's error, e.g. one over its noise standard
        deviation; default one over the layout's nominal levels.
    grid_hz : array_like, optional
        Candidate starting frequencies, Hz (default 15 log-spaced over
        0.06-0.2 Hz).
    start_damping : float
        Damping ratio a new mode starts from.
    max_nfev : int
        Function evaluations per least-squares refit.

    BLAS runs single-threaded during the fit (its products are small; see
    :mod:`spacecraft_conventions.blas`).

    Returns
    -------
    PhysicalFit

    Raises
    ------
    ValueError
        Shapes that do not match, or a layout without attitude and rate.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.ndim != 2 or u.shape[1] != 3 or y.shape != (u.shape[0], layout.size):
        raise ValueError(f"u and y must have shapes (T, 3) and (T, {layout.size}), "
                         f"got {u.shape} and {y.shape}")
    if not {"attitude", "rate"} <= set(layout.names):
        raise ValueError(f"the layout must hold attitude and rate, got {layout.names}")
    if not np.all(np.isfinite(u)):
        raise ValueError("u must be finite (the torques that acted)")
    w = 1.0 / layout.scales() if weights is None else np.asarray(weights, dtype=float)
    grid = np.geomspace(0.06, 0.2, 15) if grid_hz is None else np.asarray(grid_hz, float)
    problem = _Problem(u, y, float(dt), layout, w)
    rigid = PhysicalModel(GAIN_SCALE * np.eye(3), [], [], np.zeros((0, 3)),
                          np.zeros((problem.defl.size, 0)))
    solution = problem.solve(problem.pack(rigid, np.zeros(6)), 0, max_nfev)
    p = solution.x
    for n in range(n_modes):
        scored = [(problem.candidate(p, n, f, start_damping), f) for f in grid]
        (phi, _), frequency = max(scored, key=lambda item: item[0][1])
        model, x0 = problem.unpack(p, n)
        grown = PhysicalModel(model.gain, np.append(model.frequencies_hz, frequency),
                              np.append(model.damping, start_damping),
                              np.vstack([model.couplings, phi]), np.zeros((problem.defl.size,
                                                                           n + 1)))
        solution = problem.solve(problem.pack(grown, np.append(x0, np.zeros(2))), n + 1,
                                 max_nfev)
        p = solution.x
    residuals, tips = problem._evaluate(p, n_modes)
    model, x0 = problem.unpack(p, n_modes)
    model = PhysicalModel(model.gain, model.frequencies_hz, model.damping, model.couplings, tips)
    return PhysicalFit(model, x0, _gain_covariance(problem, p, solution.jac, residuals),
                       float(np.mean(residuals**2)))


def _gain_covariance(problem: _Problem, p: np.ndarray, jac: np.ndarray,
                     residuals: np.ndarray) -> np.ndarray:
    """Covariance of the gain's nine entries: ``sigma^2 (J^T J)^-1`` of the parameters
    (``jac``: the residuals' Jacobian at ``p``), mapped through ``dG / dp`` (the gain
    depends on the first six parameters only; central differences)."""
    dof = max(residuals.size - p.size, 1)
    sigma2 = float(np.sum(residuals**2)) / dof
    cov = sigma2 * np.linalg.pinv(jac.T @ jac)[:6, :6]
    step = 1e-6
    dgain = np.column_stack([(problem.gain(p + step * e) - problem.gain(p - step * e)).ravel()
                             / (2 * step) for e in np.eye(p.size)[:6]])
    return dgain @ cov @ dgain.T
