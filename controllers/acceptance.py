"""Whether a gain designed on an identified model may fly: a test with physical meaning.

"The identified closed loop is stable" holds for every LQR gain by
construction and says nothing when the model is wrong: a model that believes
torque barely moves the spacecraft yields a gain that barely pushes. An
attitude controller must above all be a spring and a damper on every axis,
so :class:`GainAcceptance` checks, for a candidate gain on a model:

1. **Effective stiffness and damping.** The torque the gain commands for a
   unit attitude error at rest (``K_p``, N m/rad) and for a unit rate at
   zero attitude (``K_d``, N m s/rad), read through the model's own state
   coordinates (:func:`effective_gains`). The smallest eigenvalue of each
   (symmetric part) must exceed ``floor`` times that of a trusted reference
   design (the robust fixed design): positive, and not much softer.
2. **Stability on the model** (with the integral): spectral radius below 1.
3. **Prediction agreement.** The model's recent 1 s-ahead rate prediction
   error, relative to that of persistence, must be below
   ``max_prediction_error``: a model that does not predict the data clearly
   better than no model is not designed on.

A rejected gain is not flown; the caller falls back to the reference design.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.lqg import augment_integral, equilibrium_state
from controllers.riccati import spectral_radius

__all__ = ["GainAcceptance", "effective_gains"]


def effective_gains(a: np.ndarray, c: np.ndarray, gain_x: np.ndarray, att_rows: np.ndarray,
                    rate_rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Effective attitude stiffness and damping of ``u = -G_x x`` on a model.

    Parameters
    ----------
    a : (n, n) ndarray
        Model transition matrix.
    c : (m, n) ndarray
        Output matrix (physical units).
    gain_x : (3, n) ndarray
        State-feedback part of the gain.
    att_rows, rate_rows : ndarray of int
        Rows of ``c`` that measure attitude (rad) and body rate (rad/s).

    Returns
    -------
    K_p, K_d : (3, 3) ndarray
        Torque per unit attitude (N m/rad) at the zero-input equilibrium with
        that attitude, and per unit rate (N m s/rad) for the least-norm state
        with that rate, zero attitude and zero other outputs.
    """
    n = a.shape[0]
    k_p = np.column_stack([gain_x @ equilibrium_state(a, c[att_rows], e) for e in np.eye(3)])
    rows = np.concatenate([att_rows, rate_rows])
    others = np.setdiff1d(np.arange(c.shape[0]), rows)
    lhs = np.vstack([c[rows], c[others]]) if others.size else c[rows]
    states = []
    for e in np.eye(3):
        rhs = np.concatenate([np.zeros(3), e, np.zeros(others.size)])
        states.append(np.linalg.lstsq(lhs, rhs, rcond=None)[0] if n else np.zeros(0))
    k_d = np.column_stack([gain_x @ x for x in states])
    return k_p, k_d


def _softest(matrix: np.ndarray) -> float:
    return float(np.linalg.eigvalsh(0.5 * (matrix + matrix.T)).min())


@dataclass
class GainAcceptance:
    """Acceptance test of a candidate gain (see the module docstring).

    Attributes
    ----------
    floor : float
        Smallest stiffness and damping, as a fraction of the reference's.
    max_prediction_error : float
        Largest 1 s rate prediction error (mean square) of the model relative
        to persistence's.
    """

    floor: float = 0.3
    max_prediction_error: float = 0.5

    def __post_init__(self) -> None:
        if not 0 <= self.floor:
            raise ValueError(f"floor must be >= 0, got {self.floor}")
        if not self.max_prediction_error > 0:
            raise ValueError(f"max_prediction_error must be > 0, got {self.max_prediction_error}")

    def check(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, gain: np.ndarray,
              att_rows: np.ndarray, rate_rows: np.ndarray, reference: tuple[float, float],
              prediction_error: float, dt: float) -> str | None:
        """None if the gain passes, else the reason it does not.

        Parameters
        ----------
        a, b, c : ndarray
            The model the gain was designed on (physical units).
        gain : (3, n) or (3, n + 3) ndarray
            ``[G_x]`` or ``[G_x, G_z]`` (with the integral).
        att_rows, rate_rows : ndarray of int
        reference : (float, float)
            Softest stiffness and damping of the reference design.
        prediction_error : float
            The model's recent relative one-step rate prediction error.
        dt : float
        """
        n = a.shape[0]
        if not np.all(np.isfinite(gain)):
            return "non-finite gain"
        if not np.isfinite(prediction_error) or prediction_error > self.max_prediction_error:
            return "prediction"
        k_p, k_d = effective_gains(a, c, gain[:, :n], att_rows, rate_rows)
        if _softest(k_p) < self.floor * reference[0]:
            return "stiffness"
        if _softest(k_d) < self.floor * reference[1]:
            return "damping"
        if gain.shape[1] > n:
            a_cl, b_cl = augment_integral(a, b, c[att_rows], dt)
        else:
            a_cl, b_cl = a, b
        if spectral_radius(a_cl - b_cl @ gain) >= 1.0:
            return "unstable"
        return None

    @staticmethod
    def softest(a: np.ndarray, c: np.ndarray, gain_x: np.ndarray, att_rows: np.ndarray,
                rate_rows: np.ndarray) -> tuple[float, float]:
        """Softest effective stiffness and damping of a design (the reference)."""
        k_p, k_d = effective_gains(a, c, gain_x, att_rows, rate_rows)
        return _softest(k_p), _softest(k_d)
