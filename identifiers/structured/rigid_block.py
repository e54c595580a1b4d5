"""The rigid body of a spacecraft as an exact block: regressors and ZOH model.

The rigid body is three double integrators driven by the torques through
the inverse inertia ``G = J^-1``. Given ``G`` its ZOH model is exact, and
with the outputs and the torques through the same high-pass
``((1 - z^-1) / (1 - rho z^-1))^2`` (the constants and ramps of the unknown
initial attitude and rate removed exactly) every output is linear in the
rigid coefficients: ``y_f = Theta_r rho_k + (the rest)``, with ``rho_k``
the high-passed torques integrated once and twice and the initial
conditions' high-passed constant and ramp (:class:`RigidBlock`).
:class:`identifiers.structured.structured_rpbsid.StructuredRPBSID` regresses
on them beside a subspace method's past window.
"""

from __future__ import annotations

import numpy as np

from identifiers.core.modal_basis import HighPass, ModalFilterBank
from identifiers.core.rigid_gain import RigidGainEstimate
from spacecraft_conventions import OutputLayout

__all__ = ["N_RIGID_REGRESSORS", "RIGID_ORDER", "RigidBlock", "highpass_offset"]

#: States of the rigid block: attitude (3) and rate (3).
RIGID_ORDER = 6

#: Rigid regressors: double and single integrals of the three torques, and the
#: high-passed constant and ramp of the unknown initial attitude and rate.
N_RIGID_REGRESSORS = 8

def highpass_offset(hp: HighPass) -> np.ndarray:
    """What :class:`HighPass` adds to its next input: ``F(x_k) = x_k + offset``
    (the filter's leading coefficient is 1), from its past alone.

    Returns
    -------
    (size,) ndarray
        The offset the high-pass adds to its next input.
    """
    last, out, rho = hp._last, hp._out, hp.rho
    return rho * (out[0] + out[1]) - last[0] - last[1]


class RigidBlock:
    """The rigid body's regressors and its exact ZOH model, given ``G``.

    Parameters
    ----------
    layout : OutputLayout
        Sensor groups of ``y``; attitude and rate are required.
    dt : float
        Sample time, s.
    highpass : float
        Pole ``rho`` of the high-pass on outputs, torques and regressors.
    output_scale : (m,) ndarray
        Physical units of one normalized output unit.

    Notes
    -----
    :meth:`regressor` returns, for the sample about to be processed (before
    its torque acts), the high-passed ``[double integral (3); integral (3);
    1; t]`` of the normalized torques, each divided by a fixed scale (its
    filter's RMS gain for white input) so the regression's columns are of
    unit order.
    """

    def __init__(self, layout: OutputLayout, dt: float, highpass: float,
                 output_scale: np.ndarray) -> None:
        self.layout = layout
        self.dt = float(dt)
        self.highpass = float(highpass)
        self._att = layout.indices("attitude")
        self._rate = layout.indices("rate")
        s = np.asarray(output_scale, dtype=float)
        self.ratio = float(np.mean(s[self._rate]) / np.mean(s[self._att]))
        # per axis: normalized attitude increment per normalized rate and sample
        self._kinematic = self.dt * s[self._rate] / s[self._att]
        self.scale = self._regressor_scales()
        self.restart()

    def _regressor_scales(self) -> np.ndarray:
        """RMS gain of each regressor's filter for a white unit torque (integrals),
        the peak of the high-passed step and ramp (initial-condition terms)."""
        n = int(20 / (1.0 - self.highpass)) + 50
        bank = ModalFilterBank((), self.dt, self.ratio)
        hp = HighPass(N_RIGID_REGRESSORS, self.highpass)
        rows = np.empty((n, N_RIGID_REGRESSORS))
        for k in range(n):
            rows[k] = bank.highpassed(hp)[0]
            bank.step(np.ones(3) if k == 0 else np.zeros(3))
        scale = np.sqrt(np.sum(rows[:, :6] ** 2, axis=0))
        return np.concatenate((scale, np.abs(rows[:, 6:]).max(axis=0)))

    def restart(self) -> None:
        """A new record: integrals, initial-condition terms and high-passes from zero."""
        self._bank = ModalFilterBank((), self.dt, self.ratio)
        self._hp = HighPass(N_RIGID_REGRESSORS, self.highpass)

    def regressor(self) -> np.ndarray:
        """The scaled high-passed regressor of the current sample (the high-pass advances).

        Returns
        -------
        (8,) ndarray
            The scaled high-passed rigid regressor.
        """
        return self._bank.highpassed(self._hp)[0] / self.scale

    def peek(self) -> np.ndarray:
        """:meth:`regressor` without advancing anything.

        Returns
        -------
        (8,) ndarray
            The regressor the next call of :meth:`regressor` would return.
        """
        raw = self._bank.regressor()
        return (raw + highpass_offset(self._hp)) / self.scale

    def restart_initial_conditions(self) -> None:
        """Restart the initial-condition terms (after a change: the rates jump)."""
        self._bank.restart()

    def step(self, u: np.ndarray) -> None:
        """Advance the integrals by one sample of normalized torque ``u`` (3,)."""
        self._bank.step(u)

    def gain(self, theta: np.ndarray) -> np.ndarray:
        """``G`` in normalized units (rate output per integrated torque) from the
        regression's rigid coefficients ``theta`` (m x 8): the rate rows' block.

        Returns
        -------
        (3, 3) ndarray
            The gain G in normalized units.
        """
        return theta[np.ix_(self._rate, np.arange(3, 6))] / self.scale[3:6]

    def estimate(self, theta: np.ndarray, p: np.ndarray, error_variance: np.ndarray,
                 output_scale: np.ndarray, input_scale: np.ndarray) -> RigidGainEstimate:
        """``G`` in physical units with its calibrated covariance, from a regression whose
        first 8 columns are :meth:`regressor`'s.

        Parameters
        ----------
        theta : (m, d) ndarray
            The regression's estimate (normalized units).
        p : (d, d) ndarray
            Its covariance in units of the error variance.
        error_variance : (m,) ndarray
            Variance of each output's regression errors (normalized units).
        output_scale, input_scale : (m,), (3,) ndarray
            Physical units of one normalized output and torque unit.

        Returns
        -------
        RigidGainEstimate
            The gain J^-1 (rad/s^2 per N m) and its (9, 9) covariance.
        """
        rate, cols = self._rate, np.arange(3, 6)
        return RigidGainEstimate.from_regression(
            theta[np.ix_(rate, cols)], p[np.ix_(cols, cols)], error_variance[rate],
            output_scale[rate], self.scale[3:6] * input_scale)

    def matrices(self, g: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The exact ZOH rigid block in normalized units, state ``[psi_n; omega_n]``.

        Parameters
        ----------
        g : (3, 3) ndarray
            ``G`` in normalized units (see :meth:`gain`).
        m : int
            Number of outputs.

        Returns
        -------
        a : (6, 6), b : (6, 3), c : (m, 6) ndarray
        """
        dt = self.dt
        kin = self._kinematic
        a = np.eye(RIGID_ORDER)
        a[np.arange(3), np.arange(3, 6)] = kin
        b = np.vstack((0.5 * dt * kin[:, None] * g, dt * g))
        c = np.zeros((m, RIGID_ORDER))
        c[self._att, np.arange(3)] = 1.0
        c[self._rate, np.arange(3, 6)] = 1.0
        return a, b, c
