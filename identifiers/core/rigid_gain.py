"""The rigid-body gain and how well it is known.

The rigid body of a spacecraft is three double integrators driven by the
torques through the inverse inertia ``G = J(t)^-1``. The rigid-flexible
identifier regresses the body rates on the integrated torques (and the
modal terms), so ``G`` is a block of a linear regression's estimate, and
its uncertainty the matching block of the regression's covariance.
:class:`RigidGainEstimate` carries both, in physical units, and answers
the questions a controller asks: how large is the uncertainty, does an
interval contain a given gain, how far may the true gain be from the
estimate.

Calibration: the regression is a Kalman filter over parameters that drift
as random walks, and its covariance is in units of the output noise
variance, so ``covariance = sigma^2 P`` with ``sigma^2`` the variance of
the regression's a-priori errors (measured, so model error and coloured
noise count too).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import gammaincinv

__all__ = ["RigidGainEstimate"]


@dataclass(frozen=True)
class RigidGainEstimate:
    """An estimate of the rigid-body gain ``G = J^-1`` and its covariance.

    Attributes
    ----------
    gain : (3, 3) ndarray
        ``G``, rad/s^2 per N m.
    covariance : (9, 9) ndarray
        Covariance of ``gain.ravel()`` (row-major), (rad/s^2 per N m)^2.
    """

    gain: np.ndarray
    covariance: np.ndarray

    def __post_init__(self) -> None:
        gain = np.asarray(self.gain, dtype=float)
        cov = np.asarray(self.covariance, dtype=float)
        if gain.shape != (3, 3) or cov.shape != (9, 9):
            raise ValueError(f"gain must be (3, 3) and covariance (9, 9), got {gain.shape} "
                             f"and {cov.shape}")
        object.__setattr__(self, "gain", gain)
        object.__setattr__(self, "covariance", 0.5 * (cov + cov.T))

    @classmethod
    def from_regression(cls, theta: ArrayLike, p: ArrayLike, noise_variance: ArrayLike,
                        row_scale: ArrayLike, column_scale: ArrayLike) -> RigidGainEstimate:
        """From the rate rows of a regression with a covariance shared by its rows.

        Parameters
        ----------
        theta : (3, 3) array_like
            Estimate of the rate outputs' coefficients on the three
            integrated-torque regressors, in the regression's units.
        p : (3, 3) array_like
            The block of the regression's covariance for those regressors, in
            units of the noise variance.
        noise_variance : (3,) array_like
            Noise variance of each rate output, in the regression's units.
        row_scale : (3,) array_like
            Physical units of one regression unit of each output, times any
            factor converting the coefficient to ``G`` (rad/s^2 per N m).
        column_scale : (3,) array_like
            Physical units of one regression unit of each regressor.

        Returns
        -------
        RigidGainEstimate
            The gain J^-1 (3, 3), rad/s^2 per N m, and its (9, 9) covariance.
        """
        theta = np.asarray(theta, dtype=float)
        p = np.asarray(p, dtype=float)
        rows = np.asarray(row_scale, dtype=float)
        cols = np.asarray(column_scale, dtype=float)
        var = np.asarray(noise_variance, dtype=float)
        gain = rows[:, None] * theta / cols[None, :]
        block = p / np.outer(cols, cols)
        cov = np.zeros((9, 9))
        for r in range(3):
            cov[3 * r:3 * r + 3, 3 * r:3 * r + 3] = rows[r] ** 2 * var[r] * block
        return cls(gain, cov)

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of each entry of ``gain``, (3, 3)."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0)).reshape(3, 3)

    def relative_std(self) -> float:
        """``sqrt(trace(covariance)) / ||gain||_F``: the gain's relative uncertainty.

        Returns
        -------
        float
            The relative standard deviation (inf for a zero gain).
        """
        norm = float(np.linalg.norm(self.gain))
        return float(np.sqrt(max(np.trace(self.covariance), 0.0)) / norm) if norm > 0 \
            else float("inf")

    def mahalanobis(self, gain: ArrayLike) -> float:
        """The distance of ``gain`` from the estimate in standard deviations: the
        square root of ``d^T C^+ d`` over the entries with a positive variance
        (``C^+`` the pseudo-inverse: a constrained estimate, e.g. a symmetric one,
        has a singular covariance).

        Returns
        -------
        float
            The distance, in standard deviations.
        """
        d, keep = self._difference(gain)
        if not keep.any():
            return float("inf") if np.any(d) else 0.0
        return float(np.sqrt(_whitened(d[keep], self.covariance[np.ix_(keep, keep)])[0]))

    def covers(self, gain: ArrayLike, sigmas: float = 2.0) -> bool:
        """Whether ``gain`` lies in the estimate's confidence region of the probability
        a scalar's ``+-sigmas`` band holds (95.45 % for 2).

        The region is the ellipsoid ``d^T C^+ d <= chi2_k^-1(p)``, ``d`` the
        difference, ``k`` the covariance's rank and ``p = erf(sigmas / sqrt(2))``:
        an estimate whose errors are Gaussian with covariance ``C`` covers the
        truth with probability ``p``, whatever the shape of ``C`` (so the share of
        covered samples is a calibration check). For ``k = 1`` it is the scalar
        band ``|d| <= sigmas * std``. An entry the estimate claims exactly (zero
        variance) must agree to rounding.

        Until 2026-11-27 the test was ``||d||_F <= sigmas sqrt(trace(C))``, which a
        calibrated estimate passes with probability 0.95-1.0 depending on the
        shape of ``C`` (about 1.0 for nine equal variances): it overstated
        coverage.

        Returns
        -------
        bool
            True when ``gain`` lies in the region.
        """
        if not sigmas > 0:
            raise ValueError(f"sigmas must be > 0, got {sigmas}")
        d, keep = self._difference(gain)
        if np.any(np.abs(d[~keep]) > 1e-12 * np.linalg.norm(self.gain)):
            return False
        if not keep.any():
            return True
        distance2, rank = _whitened(d[keep], self.covariance[np.ix_(keep, keep)])
        probability = math.erf(sigmas / math.sqrt(2.0))
        threshold = 2.0 * float(gammaincinv(0.5 * rank, probability))   # chi2_k quantile
        return bool(distance2 <= threshold)

    def _difference(self, gain: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(gain - G).ravel()`` and the mask of the entries with a positive variance."""
        gain = np.asarray(gain, dtype=float)
        if gain.shape != (3, 3):
            raise ValueError(f"gain must be (3, 3), got {gain.shape}")
        return (gain - self.gain).ravel(), np.diag(self.covariance) > 0


#: Eigenvalues of a covariance below this fraction of its largest are its null space
#: (a constrained estimate's: a symmetric gain's antisymmetric directions, which
#: rounding fills with noise of about 1e-16 of the largest).
_RANK_TOLERANCE = 1e-10


def _whitened(d: np.ndarray, cov: np.ndarray) -> tuple[float, int]:
    """``d^T C^+ d`` over ``cov``'s range and that range's dimension (its rank)."""
    values, vectors = np.linalg.eigh(cov)
    keep = values > _RANK_TOLERANCE * values[-1]
    z = vectors[:, keep].T @ d
    return float(np.sum(z * z / values[keep])), int(keep.sum())
