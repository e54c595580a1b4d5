"""A flexible spacecraft with a turning drive: hub-plus-appendage model scheduled on
the drive's angle.

The state is ``x = [theta (3); omega (3); eta (N); eta' (N)]``: the hub's attitude
and body rate and one cantilever mode per appendage. The mass matrix is that of
the hybrid (hub + constrained modes) coordinates,

    M(a) = [[J(a), F(a)], [F(a)^T, I]],
    J(a) omega' + F(a) eta'' = u,
    F(a)^T omega' + eta'' + 2 Z W eta' + W^2 eta = 0,

where ``a`` is the drive angle (rad), ``F(a)``'s column k is appendage k's
coupling, turned with the drive for an appendage the drive carries
(``f_k(a) = R(a)^T v_k``, ``R(a)`` the rotation by ``a`` about the drive axis)
and constant otherwise, and

    J(a) = S + R(a)^T (|P| Pi + P) R(a) + F(a) F(a)^T,

with ``S`` symmetric positive definite, ``P`` the turning appendages'
inertia anisotropy in the plane of the drive (traceless there: two numbers),
``Pi`` the projector onto that plane and ``|P|`` its eigenvalue: the
turning part ``|P| Pi + P`` is positive semidefinite (in-plane eigenvalues
``2 |P|`` and 0; an isotropic in-plane part does not change with the angle
and belongs to ``S``). ``M(a)`` is then positive definite and the model
passive at every angle, as a collocated spacecraft is, also at angles the
fit never saw. The outputs are ``attitude = theta``,
``rate = omega`` and each deflection sensor's ``d_i eta_{k(i)}`` (sensor i on
appendage k(i)).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.expm import expm_stack
from identifiers.core.model import StateSpaceModel
from spacecraft_conventions import OutputLayout

__all__ = ["ScheduledPhysicalModel", "drive_rotation", "plane_basis"]


def drive_rotation(axis: ArrayLike, angle: ArrayLike) -> np.ndarray:
    """``R(a)``: rotation by ``angle`` (rad) about the unit vector ``axis`` (Rodrigues);
    about the body y axis ``[[c, 0, s], [0, 1, 0], [-s, 0, c]]``. ``angle`` of shape
    (K,) gives the K rotations, (K, 3, 3).

    Returns
    -------
    (3, 3) or (K, 3, 3) ndarray
        The rotation matrices.
    """
    x, y, z = np.asarray(axis, dtype=float)
    cross = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    a = np.asarray(angle, dtype=float)[..., None, None]
    return np.eye(3) + np.sin(a) * cross + (1.0 - np.cos(a)) * (cross @ cross)


def plane_basis(axis: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``(e1, e2)`` spanning the plane perpendicular to ``axis`` with
    ``e1 x e2 = axis`` (for the y axis: z and x).

    Returns
    -------
    (e1, e2) : (3,) ndarrays
        Orthonormal, with e1 x e2 = axis.
    """
    k = np.asarray(axis, dtype=float)
    seed = np.eye(3)[int(np.argmin(np.abs(k)))]
    e1 = _cross(k, seed)
    e1 /= np.linalg.norm(e1)
    return e1, _cross(k, e1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of two 3-vectors: ``np.cross``'s arithmetic (each product rounded, then
    the difference) without its generic-shape overhead (a fit calls this 8000 times)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _check_values(values: dict[str, np.ndarray], structure: bool) -> None:
    """What a parameter vector can break in a model of the right shapes: every value
    finite, ``rest_inertia`` positive definite, frequencies > 0, damping >= 0; with
    ``structure`` also what a fit's parametrization fixes: ``rest_inertia``
    symmetric, ``drive_axis`` a unit vector (:class:`ValueError` otherwise)."""
    if not all(np.all(np.isfinite(x)) for x in values.values()):
        raise ValueError("every parameter of a ScheduledPhysicalModel must be finite")
    s = values["rest_inertia"]
    if (structure and not np.allclose(s, s.T, rtol=1e-9, atol=0.0)) \
            or np.linalg.eigvalsh(s).min() <= 0:
        raise ValueError("rest_inertia must be symmetric positive definite")
    if structure and abs(np.linalg.norm(values["drive_axis"]) - 1.0) > 1e-9:
        raise ValueError(f"drive_axis must be a unit vector, got {values['drive_axis']}")
    if np.any(values["frequencies_hz"] <= 0) or np.any(values["damping"] < 0):
        raise ValueError("frequencies_hz must be > 0 and damping >= 0")


@dataclass(frozen=True)
class ScheduledPhysicalModel:
    """Hub plus one cantilever mode per appendage, scheduled on the drive angle.

    See the module docstring for the equations.

    Parameters
    ----------
    rest_inertia : (3, 3) array_like
        ``S``, kg m^2: the inertia that does not turn with the drive and is
        not the modes'; symmetric positive definite.
    drive_anisotropy : (2,) array_like
        ``P = p0 (e1 e1^T - e2 e2^T) + p1 (e1 e2^T + e2 e1^T)`` (kg m^2) in the
        drive plane's basis ``(e1, e2)`` of :func:`plane_basis`, at drive
        angle 0.
    frequencies_hz, damping : (N,) array_like
        The cantilever modes' frequencies (Hz) and damping ratios.
    couplings : (N, 3) array_like
        ``v_k``, kg^1/2 m: appendage k's coupling, body frame at drive angle 0.
    turning : (N,) array_like of bool
        Whether the drive carries appendage k.
    tips : (n_tip,) array_like
        ``d_i``: deflection sensor i's reading per unit of its appendage's mode.
    sensor_appendage : (n_tip,) array_like of int
        ``k(i)``, the appendage of sensor i.
    drive_axis : (3,) array_like
        The drive's unit axis in the body frame.
    """

    rest_inertia: np.ndarray
    drive_anisotropy: np.ndarray
    frequencies_hz: np.ndarray
    damping: np.ndarray
    couplings: np.ndarray
    turning: np.ndarray
    tips: np.ndarray
    sensor_appendage: np.ndarray
    drive_axis: np.ndarray

    def __post_init__(self) -> None:
        v = {name: np.array(getattr(self, name), dtype=float) for name in
             ("rest_inertia", "drive_anisotropy", "frequencies_hz", "damping", "couplings",
              "tips", "drive_axis")}
        n = v["frequencies_hz"].reshape(-1).size
        v["frequencies_hz"] = v["frequencies_hz"].reshape(n)
        v["tips"] = v["tips"].reshape(-1)
        turning = np.array(self.turning, dtype=bool).reshape(-1)
        sensors = np.array(self.sensor_appendage, dtype=int).reshape(-1)
        for name, shape in (("rest_inertia", (3, 3)), ("drive_anisotropy", (2,)),
                            ("damping", (n,)), ("couplings", (n, 3)), ("drive_axis", (3,)),
                            ("tips", sensors.shape)):
            if v[name].shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {v[name].shape}")
        if turning.shape != (n,):
            raise ValueError(f"turning must have one flag per mode ({n}), got {turning.shape}")
        if sensors.size and (sensors.min() < 0 or sensors.max() >= n):
            raise ValueError(f"sensor_appendage must be indices in [0, {n}), got {sensors}")
        _check_values(v, structure=True)
        v["turning"], v["sensor_appendage"] = turning, sensors
        for name, value in v.items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def _trusted(cls, rest_inertia: np.ndarray, drive_anisotropy: np.ndarray,
                 frequencies_hz: np.ndarray, damping: np.ndarray, couplings: np.ndarray,
                 turning: np.ndarray, tips: np.ndarray, sensor_appendage: np.ndarray,
                 drive_axis: np.ndarray) -> ScheduledPhysicalModel:
        """A model from a fit's parametrization, which fixes the shapes, the symmetry of
        ``rest_inertia`` (``L L^T``), ``turning``, ``sensor_appendage`` and
        ``drive_axis`` (taken from a checked model): only what a parameter vector can
        still break is checked (finiteness, ``S`` positive definite, frequencies > 0,
        damping >= 0; :class:`ValueError` as the constructor's). The fit builds one
        model per residual and Jacobian column; the constructor's full checks were a
        seventh of its time."""
        values = {"rest_inertia": rest_inertia, "drive_anisotropy": drive_anisotropy,
                  "frequencies_hz": frequencies_hz, "damping": damping,
                  "couplings": couplings, "tips": tips}
        _check_values(values, structure=False)
        model = object.__new__(cls)
        values.update(turning=turning, sensor_appendage=sensor_appendage, drive_axis=drive_axis)
        for name, value in values.items():
            value = np.array(value)                 # a read-only copy, as the constructor's
            value.setflags(write=False)
            object.__setattr__(model, name, value)
        return model

    @property
    def n_modes(self) -> int:
        """N, the number of appendage modes."""
        return int(self.frequencies_hz.size)

    @property
    def order(self) -> int:
        """The state dimension, ``6 + 2 N``."""
        return 6 + 2 * self.n_modes

    @cached_property
    def turning_inertia_at_zero(self) -> np.ndarray:
        """``|P| Pi + P`` (3, 3), kg m^2: the turning part of the inertia at angle 0,
        positive semidefinite."""
        e1, e2 = plane_basis(self.drive_axis)
        p0, p1 = self.drive_anisotropy
        anisotropy = p0 * (np.outer(e1, e1) - np.outer(e2, e2)) + p1 * (np.outer(e1, e2)
                                                                       + np.outer(e2, e1))
        plane = np.outer(e1, e1) + np.outer(e2, e2)
        return np.hypot(p0, p1) * plane + anisotropy

    def coupling(self, angle: ArrayLike) -> np.ndarray:
        """``F(a)`` (3, N), kg^1/2 m; (K, 3, N) for K angles.

        Returns
        -------
        (3, N) or (K, 3, N) ndarray
            The couplings at the angle(s), kg^1/2 m.
        """
        a = np.asarray(angle, dtype=float)
        f = np.broadcast_to(self.couplings.T, (*a.shape, 3, self.n_modes)).copy()
        if self.turning.any():
            f[..., self.turning] = np.swapaxes(drive_rotation(self.drive_axis, a), -1, -2) \
                @ self.couplings.T[:, self.turning]
        return f

    def inertia(self, angle: float) -> np.ndarray:
        """``J(a)`` (3, 3), kg m^2: the whole spacecraft's inertia at drive angle ``a``.

        Returns
        -------
        (3, 3) ndarray
            J(a), kg m^2, symmetric positive definite.
        """
        f = self.coupling(angle)
        return self.rest_inertia + f @ f.T + self._turned(angle)

    def gain(self, angle: float) -> np.ndarray:
        """``J(a)^-1``, rad/s^2 per N m: the rigid-body gain at drive angle ``a``.

        Returns
        -------
        (3, 3) ndarray
            J(a)^-1, rad/s^2 per N m.
        """
        return np.linalg.inv(self.inertia(angle))

    def _turned(self, angle: ArrayLike) -> np.ndarray:
        r = drive_rotation(self.drive_axis, angle)
        return np.swapaxes(r, -1, -2) @ self.turning_inertia_at_zero @ r

    def continuous(self, angle: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(A, B)`` of ``x' = A x + B u`` at drive angle ``a`` (rad): (6 + 2 N, 6 + 2 N)
        and (6 + 2 N, 3); for K angles, (K, ...) stacks, built in one pass.

        ``J(a) - F F^T = S + R^T (|P| Pi + P) R`` is positive definite at every
        angle by construction.

        Returns
        -------
        (A, B) : ndarrays
            (6 + 2 N, 6 + 2 N) and (6 + 2 N, 3), or (K, ...) stacks; SI units.
        """
        n, size = self.n_modes, self.order
        lead = np.shape(angle)
        f = self.coupling(angle)                                    # (..., 3, N)
        schur_inv = np.linalg.inv(self.rest_inertia + self._turned(angle))
        g = schur_inv @ f
        w = 2 * np.pi * self.frequencies_hz
        stiff, damp = -(w**2), -2.0 * self.damping * w
        h = np.eye(n) + np.swapaxes(f, -1, -2) @ g
        a = np.zeros((*lead, size, size))
        b = np.zeros((*lead, size, 3))
        a[..., 0:3, 3:6] = np.eye(3)
        a[..., 6:6 + n, 6 + n:] = np.eye(n)
        # omega' = S^-1 (u - F r), eta'' = -G^T u + (I + F^T G) r, r = -W^2 eta - 2ZW eta'
        a[..., 3:6, 6:6 + n] = -g * stiff
        a[..., 3:6, 6 + n:] = -g * damp
        a[..., 6 + n:, 6:6 + n] = h * stiff
        a[..., 6 + n:, 6 + n:] = h * damp
        b[..., 3:6, :] = schur_inv
        b[..., 6 + n:, :] = -np.swapaxes(g, -1, -2)
        return a, b

    def zoh(self, angle: ArrayLike, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Zero-order-hold ``(A_d, B_d)`` at sample time ``dt`` (s) and angle ``a``; for
        K angles, (K, ...) stacks (one exponential call for the stack).

        Returns
        -------
        (A_d, B_d) : ndarrays
            (6 + 2 N, 6 + 2 N) and (6 + 2 N, 3), or (K, ...) stacks.
        """
        a, b = self.continuous(angle)
        size = a.shape[-1]
        block = np.zeros((*a.shape[:-2], size + 3, size + 3))
        block[..., :size, :size] = a * dt
        block[..., :size, size:] = b * dt
        e = expm_stack(block)                   # compiled: the fit calls this ~4000 times
        return e[..., :size, :size], e[..., :size, size:]

    def output_matrix(self, layout: OutputLayout) -> np.ndarray:
        """``C`` (m, 6 + 2 N) for the groups of ``layout`` (attitude, rate, deflection).

        Returns
        -------
        (m, 6 + 2 N) ndarray
            The output matrix C.
        """
        c = np.zeros((layout.size, self.order))
        for name, rows in layout:
            if name == "attitude":
                c[rows, 0:3] = np.eye(3)
            elif name == "rate":
                c[rows, 3:6] = np.eye(3)
            elif name == "deflection":
                if rows.stop - rows.start != self.tips.size:
                    raise ValueError(f"the layout has {rows.stop - rows.start} deflections, "
                                     f"the model {self.tips.size}")
                c[np.arange(rows.start, rows.stop), 6 + self.sensor_appendage] = self.tips
            else:
                raise ValueError(f"a ScheduledPhysicalModel has no output group {name!r}")
        return c

    def discrete(self, angle: float, dt: float, layout: OutputLayout) -> StateSpaceModel:
        """The zero-order-hold model at drive angle ``a`` (rad), sample time ``dt`` (s),
        outputs of ``layout``; ``D = 0`` and ``K = 0``.

        Returns
        -------
        StateSpaceModel
            The discrete model (A, B, C, 0, 0) at ``dt`` and the angle.
        """
        a, b = self.zoh(angle, dt)
        c = self.output_matrix(layout)
        return StateSpaceModel(a, b, c, np.zeros((layout.size, 3)),
                               np.zeros((a.shape[0], layout.size)), dt=dt)
