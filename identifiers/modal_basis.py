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

__all__ = ["HighPass", "ModalFilterBank", "Resonator", "mode_zoh"]


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
        v = x - self._last[0] + self.rho * self._out[0]
        self._last[0] = x
        self._out[0] = v
        w = v - self._last[1] + self.rho * self._out[1]
        self._last[1] = v
        self._out[1] = w
        return w


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
    """

    def __init__(self, resonators: tuple[Resonator, ...] | list[Resonator], dt: float,
                 rate_to_attitude: float = 1.0) -> None:
        self.resonators = tuple(resonators)
        self.dt = float(dt)
        self.ratio = float(rate_to_attitude)
        mats = [mode_zoh(r.frequency_hz, r.damping, self.dt) for r in self.resonators]
        m = len(mats)
        self._a = np.array([a for a, _ in mats]).reshape(m, 2, 2)
        self._b = np.array([b for _, b in mats]).reshape(m, 2)
        self.n_flexible = 6 * m
        self.size = 6 + self.n_flexible + 2 * m + 2
        self.slices = {"attitude": slice(0, 3), "rate": slice(3, 6),
                       "flexible": slice(6, 6 + self.n_flexible),
                       "free": slice(6 + self.n_flexible, 6 + self.n_flexible + 2 * m),
                       "step": slice(self.size - 2, self.size - 1),
                       "ramp": slice(self.size - 1, self.size)}
        self.reset()

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
        self.restart()

    def restart(self) -> None:
        """Restart the initial-condition regressors (at the start, after a change)."""
        m = len(self.resonators)
        self._free = np.zeros((m, 2, 2))
        self._free[:, 0, 0] = self._free[:, 1, 1] = 1.0
        self._since = 0

    def restart_free(self) -> None:
        """Restart only the resonators' free responses."""
        self._free = np.zeros_like(self._free)
        self._free[:, 0, 0] = self._free[:, 1, 1] = 1.0

    def regressor(self) -> np.ndarray:
        """The regressor of the current sample (states before its torque acts)."""
        return np.concatenate((self._p, self._v, self._q.ravel(),
                               self._free[:, 0, :].ravel(),
                               (1.0, self._since * self.dt)))

    def step(self, u: np.ndarray) -> None:
        """Advance every filter by one sample under torque ``u`` (normalized, (3,))."""
        dt = self.dt
        self._p = self._p + dt * self.ratio * self._v + 0.5 * dt * dt * self.ratio * u
        self._v = self._v + dt * u
        self._q = np.einsum("mij,maj->mai", self._a, self._q) + self._b[:, None, :] * u[None, :,
                                                                                           None]
        self._free = np.einsum("mij,mjk->mik", self._a, self._free)
        self._since += 1
