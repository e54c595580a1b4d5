"""Euler-Bernoulli cantilever modes in closed form, and the coupling they imply.

A uniform clamped-free beam of length L has mode shapes (xi = s / L)

    psi_j(xi) = cosh(b xi) - cos(b xi) - sigma_j (sinh(b xi) - sin(b xi)),
    sigma_j   = (sinh b - sin b) / (cosh b + cos b),   b = beta_j L,

with ``1 + cos b cosh b = 0``. They satisfy ``int_0^1 psi_j^2 dxi = 1``, so
``phi_j(s) = psi_j(s / L) / sqrt(m)`` is mass-normalized
(``int phi_j^2 dm = 1``). Two moment integrals have closed forms:

    int_0^1 psi_j dxi    = 2 sigma_j / b
    int_0^1 xi psi_j dxi = 2 / b^2

which give the rigid-flexible coupling column (docs/design/model.md)

    F_ij = int (rho(s) x d) phi_j(s) dm
         = sqrt(m) [ (h x d) 2 sigma_j / b + L (e x d) 2 / b^2 ]

for a beam rooted at ``h`` along unit ``e`` bending along unit ``d``.
The mode shapes are evaluated in a numerically stable exponential form so
that modes 1..8 keep full precision.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

__all__ = [
    "cantilever_eigenvalues",
    "cantilever_mode_shape",
    "cantilever_moments",
    "coupling_matrix",
    "sensor_mode_shapes",
]


def cantilever_eigenvalues(n_modes: int) -> np.ndarray:
    """Roots ``b_j = beta_j L`` of ``1 + cos b cosh b = 0``.

    Parameters
    ----------
    n_modes : int
        Number of roots, >= 1.

    Returns
    -------
    (n_modes,) ndarray
        1.8751, 4.6941, 7.8548, 10.9955, ... (dimensionless).
    """
    if n_modes < 1:
        raise ValueError(f"n_modes must be >= 1, got {n_modes}")
    # 1 + cos b cosh b = 0  <=>  cos b + 1/cosh b = 0 (well scaled for large b)
    def f(b: float) -> float:
        return np.cos(b) + 1.0 / np.cosh(b)

    roots = []
    for j in range(1, n_modes + 1):
        guess = (2 * j - 1) * np.pi / 2
        roots.append(brentq(f, guess - 0.4, guess + 0.4, xtol=1e-15))
    return np.array(roots)


def _sigma(b: np.ndarray) -> np.ndarray:
    return (np.sinh(b) - np.sin(b)) / (np.cosh(b) + np.cos(b))


def cantilever_mode_shape(xi: np.ndarray, n_modes: int) -> np.ndarray:
    """Unit-norm cantilever mode shapes psi_j at span fractions ``xi``.

    Parameters
    ----------
    xi : (s,) array_like
        Span fractions s / L in [0, 1].
    n_modes : int
        Number of modes.

    Returns
    -------
    (s, n_modes) ndarray
        ``psi_j(xi)``; ``int_0^1 psi_j^2 = 1`` and ``psi_j(1) = +-2``.
    """
    xi = np.atleast_1d(np.asarray(xi, dtype=float))[:, None]
    b = cantilever_eigenvalues(n_modes)[None, :]
    sigma = _sigma(b)
    # (1 - sigma) computed without cancellation: sigma -> 1 as b grows.
    one_minus_sigma = (np.exp(-b) + np.cos(b) + np.sin(b)) / (np.cosh(b) + np.cos(b))
    bx = b * xi
    # cosh - sigma sinh = ((1 - sigma) e^{bx} + (1 + sigma) e^{-bx}) / 2
    hyper = 0.5 * (one_minus_sigma * np.exp(bx) + (1.0 + sigma) * np.exp(-bx))
    return hyper - np.cos(bx) + sigma * np.sin(bx)


def cantilever_moments(n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form zeroth and first moments of the unit-norm mode shapes.

    Returns
    -------
    I0, I1 : (n_modes,) ndarray
        ``int_0^1 psi_j dxi = 2 sigma_j / b_j`` and
        ``int_0^1 xi psi_j dxi = 2 / b_j^2``.
    """
    b = cantilever_eigenvalues(n_modes)
    return 2.0 * _sigma(b) / b, 2.0 / b**2


def coupling_matrix(mass: float, length: float, hinge: np.ndarray, span_axis: np.ndarray,
                    bending_axis: np.ndarray, n_modes: int) -> np.ndarray:
    """Rigid-flexible coupling matrix F_i of one appendage.

    Parameters
    ----------
    mass : float
        Appendage mass, kg.
    length : float
        Span length, m.
    hinge, span_axis, bending_axis : (3,) ndarray
        Root point from the system mass centre (m), unit span and unit
        bending directions, body frame.
    n_modes : int
        Retained modes.

    Returns
    -------
    (3, n_modes) ndarray
        Column j is ``int (rho x d) phi_j dm``, kg^(1/2) m.
    """
    i0, i1 = cantilever_moments(n_modes)
    root = np.cross(hinge, bending_axis)[:, None]
    lever = np.cross(span_axis, bending_axis)[:, None]
    return np.sqrt(mass) * (root * i0[None, :] + length * lever * i1[None, :])


def sensor_mode_shapes(mass: float, sensor_positions: np.ndarray, n_modes: int) -> np.ndarray:
    """Mass-normalized mode shapes at the sensor points, Phi_i.

    Parameters
    ----------
    mass : float
        Appendage mass, kg.
    sensor_positions : (s,) array_like
        Span fractions of the sensors.
    n_modes : int
        Retained modes.

    Returns
    -------
    (s, n_modes) ndarray
        Deflection (m) per unit modal coordinate (kg^(1/2) m): ``w = Phi eta``.
    """
    return cantilever_mode_shape(sensor_positions, n_modes) / np.sqrt(mass)
