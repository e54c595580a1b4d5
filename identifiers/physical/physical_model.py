"""A flexible spacecraft's physical model, and its fit to a record by output error.

The model is physical by construction (docs/design/control.md, "What the
remaining gap is made of"): a rigid body whose inverse inertia
``G = J^-1 = L L^T`` is symmetric positive definite, and ``N`` modes driven
through the same vectors that the hub sensors see them through,

    psi'' = G u,    q_k'' + 2 zeta_k w_k q_k' + w_k^2 q_k = phi_k^T u,
    attitude = psi + sum_k phi_k q_k,   rate = psi' + sum_k phi_k q_k',
    deflection = D q,

so the torque-to-rate response ``G / s + sum_k phi_k phi_k^T s / (s^2 +
2 zeta_k w_k s + w_k^2)`` is passive (its Hermitian part is >= 0 at every
frequency), as the collocated plant's is. :func:`fit_physical_model` fits it
to a record of applied torques and measured outputs by nonlinear least
squares on the simulation error (output error: the torques are known
exactly, so the regressors carry no noise, in open or closed loop), the
initial state included and ``D`` solved linearly inside every evaluation
(variable projection), the modes added one at a time from a frequency grid
(:mod:`identifiers.physical.physical_fit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal
from numpy.typing import ArrayLike

from identifiers.core.fit_jobs import cancellation_point
from identifiers.core.modal_kernels import oscillator_zoh as mode_zoh
from identifiers.core.model import StateSpaceModel
from spacecraft_conventions import OutputLayout

__all__ = ["DAMPING_BOUNDS", "FREQUENCY_BOUNDS_HZ", "PhysicalModel", "mode_response", "simulate"]

#: Range of a fitted mode's frequency (Hz) and damping ratio.
FREQUENCY_BOUNDS_HZ = (0.03, 0.4)
DAMPING_BOUNDS = (1e-3, 0.3)


@dataclass(frozen=True)
class PhysicalModel:
    """Rigid body plus collocated modes; see the module docstring for the equations.

    Parameters
    ----------
    gain : (3, 3) array_like
        ``G = J^-1``, rad/s^2 per N m; symmetric positive definite.
    frequencies_hz, damping : (N,) array_like
        The modes' undamped frequencies (Hz) and damping ratios.
    couplings : (N, 3) array_like
        ``phi_k``: row k is mode k's torque input (its forcing is
        ``phi_k^T u``) and its share of the hub attitude and rate.
    tips : (n_tip, N) array_like
        ``D``: the tip deflections' response to each modal coordinate.
    """

    gain: np.ndarray
    frequencies_hz: np.ndarray
    damping: np.ndarray
    couplings: np.ndarray
    tips: np.ndarray

    def __post_init__(self) -> None:
        fields = {name: np.array(getattr(self, name), dtype=float) for name in
                  ("gain", "frequencies_hz", "damping", "couplings", "tips")}
        n = fields["frequencies_hz"].reshape(-1).size
        fields["frequencies_hz"] = fields["frequencies_hz"].reshape(n)
        fields["damping"] = fields["damping"].reshape(-1)
        fields["couplings"] = fields["couplings"].reshape(-1, 3) if n else np.zeros((0, 3))
        if fields["tips"].size == 0:
            fields["tips"] = fields["tips"].reshape(fields["tips"].shape[0] if
                                                    fields["tips"].ndim == 2 else 0, n)
        for name, shape in (("gain", (3, 3)), ("damping", (n,)), ("couplings", (n, 3))):
            if fields[name].shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {fields[name].shape}")
        if fields["tips"].ndim != 2 or fields["tips"].shape[1] != n:
            raise ValueError(f"tips must have shape (n_tip, {n}), got {fields['tips'].shape}")
        if not all(np.all(np.isfinite(v)) for v in fields.values()):
            raise ValueError("every parameter of a PhysicalModel must be finite")
        gain = fields["gain"]
        if not np.allclose(gain, gain.T, rtol=1e-9, atol=0.0) or \
                np.linalg.eigvalsh(0.5 * (gain + gain.T)).min() <= 0:
            raise ValueError("gain must be symmetric positive definite (it is J^-1)")
        if np.any(fields["frequencies_hz"] <= 0) or np.any(fields["damping"] < 0):
            raise ValueError("frequencies_hz must be > 0 and damping >= 0")
        for name, value in fields.items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_modes(self) -> int:
        """N, the number of modes."""
        return int(self.frequencies_hz.size)

    def continuous(self) -> tuple[np.ndarray, np.ndarray]:
        """``(A, B)`` of ``x' = A x + B u``, state ``[psi (3); psi' (3); q_1; q_1'; ...]``.

        Returns
        -------
        (A, B) : ((6 + 2 N, 6 + 2 N), (6 + 2 N, 3)) ndarrays
            The continuous-time model, SI units (rad, rad/s per N m).
        """
        n = 6 + 2 * self.n_modes
        a = np.zeros((n, n))
        b = np.zeros((n, 3))
        a[0:3, 3:6] = np.eye(3)
        b[3:6] = self.gain
        w = 2 * np.pi * self.frequencies_hz
        q = np.arange(6, n, 2)
        a[q, q + 1] = 1.0
        a[q + 1, q] = -w**2
        a[q + 1, q + 1] = -2.0 * self.damping * w
        b[q + 1] = self.couplings
        return a, b

    def output_matrix(self, layout: OutputLayout) -> np.ndarray:
        """``C`` (m, 6 + 2 N) for the groups of ``layout`` (attitude, rate, deflection).

        Returns
        -------
        (m, 6 + 2 N) ndarray
            The output matrix C.
        """
        n = 6 + 2 * self.n_modes
        c = np.zeros((layout.size, n))
        q = np.arange(6, n, 2)
        for name, rows in layout:
            if name == "attitude":
                c[rows, 0:3] = np.eye(3)
                c[rows, q] = self.couplings.T
            elif name == "rate":
                c[rows, 3:6] = np.eye(3)
                c[rows, q + 1] = self.couplings.T
            elif name == "deflection":
                if rows.stop - rows.start != self.tips.shape[0]:
                    raise ValueError(f"the layout has {rows.stop - rows.start} deflections, "
                                     f"the model {self.tips.shape[0]}")
                c[rows, q] = self.tips
            else:
                raise ValueError(f"a PhysicalModel has no output group {name!r}")
        return c

    def discrete(self, dt: float, layout: OutputLayout) -> StateSpaceModel:
        """The zero-order-hold model at sample time ``dt`` (s) with the outputs of
        ``layout``; ``D = 0`` and ``K = 0`` (no predictor gain: a filter on it is the
        user's).

        Returns
        -------
        StateSpaceModel
            The discrete model (A, B, C, 0, 0) at ``dt``.
        """
        a, b = self.continuous()
        n = a.shape[0]
        block = np.zeros((n + 3, n + 3))
        block[:n, :n] = a * dt
        block[:n, n:] = b * dt
        e = scipy.linalg.expm(block)
        c = self.output_matrix(layout)
        return StateSpaceModel(e[:n, :n], e[:n, n:], c, np.zeros((layout.size, 3)),
                               np.zeros((n, layout.size)), dt=dt)

    def rate_response(self, frequencies_hz: ArrayLike) -> np.ndarray:
        """The torque-to-rate frequency response ``G / s + sum phi phi^T s / (...)``,
        (F, 3, 3) complex, rad/s per N m, at ``s = 2 pi j f`` (continuous time).

        Returns
        -------
        (F, 3, 3) complex ndarray
            The response at each frequency, rad/s per N m.
        """
        s = 2j * np.pi * np.asarray(frequencies_hz, dtype=float).reshape(-1)
        w = 2 * np.pi * self.frequencies_hz
        modal = s[:, None] / (s[:, None] ** 2 + 2 * self.damping * w * s[:, None] + w**2)
        outer = np.einsum("ka,kb->kab", self.couplings, self.couplings)
        return self.gain[None] / s[:, None, None] + np.einsum("fk,kab->fab", modal, outer)


def mode_response(ad: np.ndarray, bd: np.ndarray, force: np.ndarray,
                   s0: np.ndarray) -> np.ndarray:
    """States ``[q, q']`` (T, 2) of ``s_{t+1} = ad s_t + bd f_t`` from ``s_0``: ``s_t``
    sees the forces before t. By the recursion, vectorized over nothing but cheap:
    two multiply-adds per sample in a compiled filter.

    Returns
    -------
    (T, 2) ndarray
        The mode's displacement and velocity at each sample.
    """
    # transfer functions from f to q and q' (one-sample delay), and the free response
    den = np.array([1.0, -np.trace(ad), np.linalg.det(ad)])
    adj = np.array([[ad[1, 1], -ad[0, 1]], [-ad[1, 0], ad[0, 0]]])   # det(zI - ad) (zI - ad)^-1
    out = np.empty((force.size, 2))
    for i in range(2):
        # e_i^T (z I - ad)^-1 bd = (z e_i^T bd - e_i^T adj bd) / den(z)
        num = np.array([0.0, bd[i], -(adj @ bd)[i]])
        # free response e_i^T ad^t s0 = (z e_i^T s0 - e_i^T adj s0) z / den(z) on an impulse
        free_num = np.array([s0[i], -(adj @ s0)[i], 0.0])
        impulse = np.zeros(force.size)
        impulse[0] = 1.0
        out[:, i] = (scipy.signal.lfilter(num, den, force)
                     + scipy.signal.lfilter(free_num, den, impulse))
    return out


def simulate(model: PhysicalModel, u: ArrayLike, dt: float,
             x0: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zero-order-hold response to the torques ``u`` from the state ``x0``.

    Parameters
    ----------
    model : PhysicalModel
    u : (T, 3) array_like
        Torques, N m, held over each sample.
    dt : float
        Sample time, s.
    x0 : (6 + 2 N,) array_like, optional
        Initial state (default 0).

    Returns
    -------
    attitude, rate : (T, 3) ndarray
        rad and rad/s at ``t = k dt``, before ``u_k`` acts.
    q : (T, N) ndarray
        The modal coordinates.
    """
    cancellation_point()                  # a background fit nobody wants stops here
    u = np.asarray(u, dtype=float)
    n = model.n_modes
    x0 = np.zeros(6 + 2 * n) if x0 is None else np.asarray(x0, dtype=float)
    gu = u @ model.gain.T
    before = np.vstack([np.zeros((1, 3)), np.cumsum(gu[:-1], axis=0)])    # sum_{j<k} G u_j
    rate = x0[3:6] + dt * before
    step = dt * rate[:-1] + 0.5 * dt * dt * gu[:-1]
    attitude = x0[0:3] + np.vstack([np.zeros((1, 3)), np.cumsum(step, axis=0)])
    q = np.zeros((u.shape[0], n))
    qd = np.zeros((u.shape[0], n))
    forces = u @ model.couplings.T
    for k in range(n):
        ad, bd = mode_zoh(model.frequencies_hz[k], model.damping[k], dt)
        states = mode_response(ad, bd, forces[:, k], x0[6 + 2 * k:8 + 2 * k])
        q[:, k], qd[:, k] = states[:, 0], states[:, 1]
    return attitude + q @ model.couplings, rate + qd @ model.couplings, q
