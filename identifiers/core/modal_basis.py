"""The filter bank of the rigid-flexible identifier: known dynamics, unknown gains.

A spacecraft's response to torque is, exactly (ZOH-sampled),

    y = sum_a G_ra * DI(u_a)  +  sum_i sum_a W_ia * R_i(u_a)  +  initial-condition terms

with ``DI`` the double integrator of one torque axis (attitude rows; its
integrator for rate rows), ``R_i`` the resonator of flexible mode ``i``
(two states: modal displacement and velocity under a unit force) and the
gains ``G`` (the inverse inertia) and ``W`` linear unknowns. Given the mode
frequencies, the regression is linear. :class:`ModalFilterBank` runs those
filters on the torques and returns the regressor of each sample;
:class:`HighPass` removes from outputs and regressors alike the constant
and ramp left by the unknown initial attitude and rate.

Initial-condition regressors, restarted by :meth:`ModalFilterBank.restart`
at the start and after every detected change, absorb what the forced
responses cannot: a step and a ramp (the rigid body's state at the restart,
whose high-passed transient decays as ``rho^k``) and each resonator's free
response (the flexible state at the restart, ringing at the mode's
frequency).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from identifiers.core.modal_kernels import (
    bank_highpassed,
    bank_regressor,
    bank_run,
    bank_step,
    highpass_run,
    highpass_step,
    oscillator_zoh_derivatives,
)

__all__ = ["MAX_DAMPING", "MIN_DAMPING", "HighPass", "ModalFilterBank", "Resonator",
           "highpass_noise_gain", "mode_zoh"]

#: Range a tracked resonator's damping ratio is kept in.
MIN_DAMPING, MAX_DAMPING = 1e-4, 0.3


@dataclass(frozen=True)
class Resonator:
    """One flexible mode (or a cluster of near-coincident modes).

    Attributes
    ----------
    frequency_hz : float
        Natural frequency, Hz.
    damping : float
        Damping ratio.
    rank : int
        Modes it stands for (1-3): near-coincident modes, unresolvable in the
        data at hand, share a resonator and are exported as ``rank`` modes.
    """

    frequency_hz: float
    damping: float
    rank: int = 1

    def __post_init__(self) -> None:
        if not (np.isfinite(self.frequency_hz) and self.frequency_hz > 0):
            raise ValueError(f"frequency_hz must be positive, got {self.frequency_hz}")
        if not (np.isfinite(self.damping) and 0 <= self.damping < 1):
            raise ValueError(f"damping must be in [0, 1), got {self.damping}")
        if self.rank not in (1, 2, 3):
            raise ValueError(f"rank must be 1, 2 or 3, got {self.rank}")


def mode_zoh(frequency_hz: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """ZOH sample of ``q'' + 2 zeta w q' + w^2 q = f``: state ``[q, q']``.

    Returns
    -------
    a : (2, 2) ndarray
    b : (2,) ndarray
        Response to a unit force held over one sample.
    """
    w = 2 * np.pi * frequency_hz
    aug = np.zeros((3, 3))
    aug[:2, :2] = [[0.0, 1.0], [-w * w, -2.0 * damping * w]]
    aug[1, 2] = 1.0
    phi = expm(aug * dt)
    return phi[:2, :2], phi[:2, 2]


class HighPass:
    """``F(z) = ((1 - z^-1) / (1 - rho z^-1))^2`` on many signals at once.

    The double zero at ``z = 1`` removes constants and ramps exactly; ``rho``
    sets the corner, about ``(1 - rho) / dt`` rad/s (0.99 at dt = 0.1 s:
    0.1 rad/s, below the rigid body's useful band).
    """

    def __init__(self, size: int, rho: float) -> None:
        if not 0 <= rho < 1:
            raise ValueError(f"rho must be in [0, 1), got {rho}")
        self.rho = float(rho)
        self._last = np.zeros((2, size))
        self._out = np.zeros((2, size))

    def reset_columns(self, columns: np.ndarray) -> None:
        """Forget the past of some signals: they start anew from 0 (a new regressor)."""
        self._last[:, columns] = 0.0
        self._out[:, columns] = 0.0

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample of every signal (the filter advances)."""
        return highpass_step(self._last, self._out, np.asarray(x, dtype=float), self.rho)

    def run(self, xs: np.ndarray) -> np.ndarray:
        """Filter a record, one sample per row of ``xs`` (N, size), as N calls would.

        Returns
        -------
        (N, size) ndarray
            The filtered record, one row per sample.
        """
        return highpass_run(self._last, self._out, np.ascontiguousarray(xs, dtype=float),
                            self.rho)


class ModalFilterBank:
    """Rigid integrators and resonators driven by the torques, plus IC regressors.

    Parameters
    ----------
    resonators : sequence of Resonator
    dt : float
        Sample time, s.
    rate_to_attitude : float
        ``(rate level) / (attitude level)``: converts the normalized rate into
        normalized attitude increments (``psi_n += dt * ratio * omega_n``).
    sensitivities : bool
        Also run the derivative filters: every resonator state's derivative
        with respect to the resonator's log-frequency and damping ratio
        (:meth:`sensitivity`), which the modal tracker regresses on, and
        which let :meth:`recenter` move a resonator without restarting it.

    Notes
    -----
    Regressor layout (``regressor()``), for ``M`` resonators:

    ====================  =======  =====================================
    block                 size     meaning
    ====================  =======  =====================================
    ``attitude``          3        double integral of each torque axis
    ``rate``              3        integral of each torque axis
    ``flexible``          6 M      per (resonator, axis): ``[q, q']``
    ``free``              2 M      each resonator's free response since
                                   the last restart
    ``step``, ``ramp``    2        1 and ``t - t_restart`` (s)
    ====================  =======  =====================================

    One sample is one compiled pass (:func:`identifiers.core.modal_kernels.bank_step`).
    """

    def __init__(self, resonators: tuple[Resonator, ...] | list[Resonator], dt: float,
                 rate_to_attitude: float = 1.0, sensitivities: bool = False) -> None:
        self.resonators = tuple(resonators)
        self.dt = float(dt)
        self.ratio = float(rate_to_attitude)
        self.sensitivities = bool(sensitivities)
        m = len(self.resonators)
        self._a = np.zeros((m, 2, 2))
        self._b = np.zeros((m, 2))
        self._da = np.zeros((m, 2, 2, 2))
        self._db = np.zeros((m, 2, 2))
        self._set_matrices()
        self.n_flexible = 6 * m
        self.size = 6 + self.n_flexible + 2 * m + 2
        self.slices = {"attitude": slice(0, 3), "rate": slice(3, 6),
                       "flexible": slice(6, 6 + self.n_flexible),
                       "free": slice(6 + self.n_flexible, 6 + self.n_flexible + 2 * m),
                       "step": slice(self.size - 2, self.size - 1),
                       "ramp": slice(self.size - 1, self.size)}
        self.reset()

    def _set_matrices(self) -> None:
        for i, r in enumerate(self.resonators):
            a, b, da, db = oscillator_zoh_derivatives(r.frequency_hz, r.damping, self.dt)
            self._a[i], self._b[i], self._da[i], self._db[i] = a, b, da, db

    @property
    def mode_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """``(a, b)`` of every resonator, shapes ``(M, 2, 2)`` and ``(M, 2)``."""
        return self._a, self._b

    def reset(self) -> None:
        """All filter states to zero (torques before now unknown: none applied)."""
        m = len(self.resonators)
        self._p = np.zeros(3)
        self._v = np.zeros(3)
        self._q = np.zeros((m, 3, 2))          # per resonator, per axis: [q, q']
        self._dq = np.zeros((m, 2, 3, 2))      # per resonator, parameter, axis: d[q, q']
        self.restart()

    def restart(self) -> None:
        """Restart the initial-condition regressors (at the start, after a change)."""
        self.restart_free()
        self._since = 0

    def restart_free(self) -> None:
        """Restart only the resonators' free responses."""
        m = len(self.resonators)
        self._free = np.zeros((m, 2, 2))
        self._free[:, 0, 0] = self._free[:, 1, 1] = 1.0
        self._dfree = np.zeros((m, 2, 2, 2))

    def regressor(self) -> np.ndarray:
        """The regressor of the current sample (states before its torque acts).

        Returns
        -------
        (size,) ndarray
            The bank's regressor at the current sample.
        """
        out = np.empty(self.size)
        bank_regressor(out, self._p, self._v, self._q, self._free, self._since, self.dt)
        return out

    def sensitivity(self) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives of the flexible regressors by each resonator's parameters.

        Returns
        -------
        dq : (M, 2, 3, 2) ndarray
            ``dq[i, p, a]``: derivative of resonator i's ``[q, q']`` on torque axis a
            by its parameter p (0: log-frequency, 1: damping ratio).
        dfree : (M, 2, 2) ndarray
            ``dfree[i, p]``: derivative of its two free-response regressors.
        """
        return self._dq, self._dfree[:, :, 0, :]

    def highpassed(self, highpass: HighPass, dq_highpass: HighPass | None = None,
                   dfree_highpass: HighPass | None = None
                   ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """:meth:`regressor` and :meth:`sensitivity` through high-passes, in one
        compiled pass.

        The same as ``highpass(regressor())`` and, if both derivative
        high-passes are given, ``dq_highpass(dq.ravel())`` and
        ``dfree_highpass(dfree.ravel())`` with ``dq, dfree = sensitivity()``
        (the high-passes advance); the derivatives are None otherwise.

        Returns
        -------
        (regressor, dq, dfree)
            The high-passed regressor (size,) and the two high-passed sensitivities
            (None unless both derivative high-passes are given).
        """
        derivatives = dq_highpass is not None and dfree_highpass is not None
        if derivatives and not self.sensitivities:
            raise RuntimeError("derivatives need a bank built with sensitivities=True")
        dq_hp = dq_highpass if derivatives else highpass
        dfree_hp = dfree_highpass if derivatives else highpass
        x, dq, dfree = bank_highpassed(
            self._p, self._v, self._q, self._free, self._since, self.dt, self._dq, self._dfree,
            highpass._last, highpass._out, highpass.rho, dq_hp._last, dq_hp._out, dq_hp.rho,
            dfree_hp._last, dfree_hp._out, dfree_hp.rho, derivatives)
        return (x, dq, dfree) if derivatives else (x, None, None)

    def step(self, u: np.ndarray) -> None:
        """Advance every filter by one sample under torque ``u`` (normalized, (3,))."""
        bank_step(np.asarray(u, dtype=float), self.dt, self.ratio, self._p, self._v, self._q,
                  self._free, self._a, self._b, self._dq, self._dfree, self._da, self._db,
                  self.sensitivities)
        self._since += 1

    def run(self, inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance the bank over a record of torques, as one :meth:`step` per row would.

        Parameters
        ----------
        inputs : (N, 3) ndarray
            Normalized torques.

        Returns
        -------
        regressors : (N, size) ndarray
            Row k: :meth:`regressor` before torque k acts.
        dq, dfree : (N, 12 M), (N, 4 M) ndarray
            Row k: :meth:`sensitivity` at the same time, flattened (zeros
            without sensitivities).
        """
        inputs = np.ascontiguousarray(inputs, dtype=float).reshape(-1, 3)
        n, m = inputs.shape[0], len(self.resonators)
        regressors = np.empty((n, self.size))
        dq = np.zeros((n, 12 * m))
        dfree = np.zeros((n, 4 * m))
        bank_run(inputs, self.dt, self.ratio, self._p, self._v, self._q, self._free, self._a,
                 self._b, self._dq, self._dfree, self._da, self._db, self.sensitivities,
                 self._since, regressors, dq, dfree)
        self._since += n
        return regressors, dq, dfree

    def recenter(self, dlogf: np.ndarray, dzeta: np.ndarray) -> None:
        """Move every resonator by ``(dlogf, dzeta)`` (log-frequency, damping ratio).

        The filter states are corrected to first order with the derivative
        filters (``s <- s + dlogf ds/dlogf + dzeta ds/dzeta``), so the bank's
        regressors stay those of the new resonators driven by the past
        torques, without a restart.

        Raises
        ------
        RuntimeError
            If the bank runs without sensitivities.
        """
        if not self.sensitivities:
            raise RuntimeError("recenter needs a bank built with sensitivities=True")
        d = np.stack([np.asarray(dlogf, float), np.asarray(dzeta, float)], axis=1)   # (M, 2)
        self._q += np.einsum("mp,mpai->mai", d, self._dq)
        self._free += np.einsum("mp,mpik->mik", d, self._dfree)
        self.resonators = tuple(
            Resonator(r.frequency_hz * float(np.exp(d[i, 0])),
                      float(np.clip(r.damping + d[i, 1], MIN_DAMPING, MAX_DAMPING)), r.rank)
            for i, r in enumerate(self.resonators))
        self._set_matrices()


def highpass_noise_gain(rho: float) -> float:
    """Sum of the squared impulse response of ``((1 - z^-1) / (1 - rho z^-1))^2``:
    the factor by which :class:`HighPass` scales the variance of white noise.

    Returns
    -------
    float
        The variance gain, at least 1.
    """
    hp = HighPass(1, rho)
    impulse = np.zeros(4000)
    impulse[0] = 1.0
    return float(sum(hp(np.array([x]))[0] ** 2 for x in impulse))
