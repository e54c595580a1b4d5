"""Rigid-flexible coupling truth model of the spacecraft (docs/design/model.md).

Equations of motion (paper Eq. 1-12), generalized coordinates
``delta = [psi (3); eta_1 (k_1); ...; eta_N (k_N)]``::

    M(t) delta'' + E delta' + K delta = L u

    M(t) = [[J(t), F(t)], [F(t)^T, I]],   F = [F_1, ..., F_N]
    E = blkdiag(0_3, 2 zeta_i Omega_i),   K = blkdiag(0_3, Omega_i^2),   L = [I_3; 0]

    J(t) = J_r - m_r S(r_r)^2 + sum_i T_i^T J_i T_i - sum_i m_i S(r_i)^2
           + sum over docked modules (own inertia + parallel-axis term)

State ``x = [delta; delta']`` (order n = 2 (3 + sum k_i)), continuous
matrices ``A_c = [[0, I], [-M^-1 K, -M^-1 E]]``, ``B_c = [0; M^-1 L]``;
outputs ``y = C x`` select attitude angles psi (rad), body rates
omega = psi' (rad/s) and appendage deflections ``w_i = Phi_i eta_i`` (m).

The sampled model is the zero-order-hold discretization, from the matrix
exponential of ``[[A_c, B_c], [0, 0]] dt`` (:mod:`spacecraft_env.discretization`):
exact and cached per configuration for piecewise-constant scenarios (docking
costs one exponential per segment), and for a turning paddle a Chebyshev
interpolant in the paddle angle of exact exponentials that agrees with them to
rounding, shared by every episode of the model (so the first and a randomized
rotation episode cost about what a repeated one does).
"""

from __future__ import annotations

import dataclasses
import math
from bisect import bisect_right
from collections import OrderedDict
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from spacecraft_conventions import (
    AXES,
    LABEL_PREFIX,
    OUTPUT_GROUPS,
    OutputLayout,
)
from spacecraft_env.discretization import AnglePanels, zoh_exponential
from spacecraft_env.modes import cantilever_moments, coupling_matrix, sensor_mode_shapes
from spacecraft_env.parameters import SpacecraftParameters, ets8_parameters
from spacecraft_env.scenarios import (
    Configuration,
    ConstantScenario,
    DockingScenario,
    Scenario,
    make_scenario,
)

__all__ = [
    "DRIVE_AXIS",
    "FlexibleSpacecraftModel",
    "StateSpaceMatrices",
    "rotation_pitch",
    "skew",
]

class StateSpaceMatrices(NamedTuple):
    """State-space matrices ``(A, B, C, D)`` of the true plant at one instant.

    ``dt`` is ``None`` for the continuous-time model and the sample time (s)
    for the zero-order-hold model.

    Attributes
    ----------
    A : (n, n) ndarray
        State matrix (continuous time) or the zero-order-hold transition
        matrix over one step (discrete time).
    B : (n, 3) ndarray
        Input matrix of the three body torques (N m).
    C : (m, n) ndarray
        Output matrix of the plant outputs (attitude, rad; rate, rad/s; tip
        deflections, m; in the model's output order).
    D : (m, 3) ndarray
        Feedthrough (zero).
    dt : float or None
        Sample time, s, or None for the continuous-time model.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float | None


# The generated constructor holds the fields' annotations as strings, to be resolved in
# a namespace without numpy (``from __future__ import annotations``); resolved here, so
# introspection (help(), the API reference) sees the types.
StateSpaceMatrices.__new__.__annotations__.update(
    {name: np.ndarray for name in "ABCD"} | {"dt": float | None})


def skew(r: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``S(r)`` with ``S(r) v = r x v``.

    Returns
    -------
    (3, 3) ndarray
        ``S(r)``, antisymmetric.
    """
    x, y, z = r
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


#: The paddle drive's axis in the body frame: the pitch (y) axis.
DRIVE_AXIS = (0.0, 1.0, 0.0)


def rotation_pitch(theta: float) -> np.ndarray:
    """Paddle rotation ``T_s(theta)`` of Appendix A: body frame -> paddle frame, by
    ``theta`` about :data:`DRIVE_AXIS`.

    The paddle's inertia in the body frame is ``T^T J_s T`` and a paddle-fixed
    direction ``d0`` appears in the body frame as ``T^T d0``. With this
    convention 50 deg of rotation moves J_xz from +1708 to about -2213 kg m^2,
    as docs/design/model.md records.

    Returns
    -------
    (3, 3) ndarray
        The rotation matrix ``T_s(theta)``.
    """
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


#: Steps of a rotating scenario whose ZOH matrices are interpolated together.
_BLOCK_STEPS = 64


def _not_positive_definite(cfg: Configuration, t: float) -> ValueError:
    where = (f"at t = {t} s" if math.isfinite(t)
             else f"at paddle angle {math.degrees(cfg.paddle_angle):.6g} deg")
    return ValueError(f"mass matrix M is not positive definite {where}: "
                      "J - sum F_i F_i^T must be positive definite")


def _inv3_spd(s: np.ndarray) -> np.ndarray | None:
    """Inverse of a symmetric 3x3 matrix, or ``None`` if it is not positive definite.

    Sylvester's criterion (positive leading minors) and the adjugate, in
    scalar arithmetic: several times faster than LAPACK calls at this size.
    """
    (a, b, c), (_, e, f), (_, _, i) = s.tolist()
    c11, c12, c13 = e * i - f * f, c * f - b * i, b * f - c * e
    det = a * c11 + b * c12 + c * c13
    if not (a > 0 and a * e - b * b > 0 and det > 0):
        return None
    c22, c23, c33 = a * i - c * c, b * c - a * f, a * e - b * b
    return np.array([[c11, c12, c13], [c12, c22, c23], [c13, c23, c33]]) / det


def _scenario_key(scenario: Scenario):
    """A cheap hashable key of the plant at time ``t`` (s) for the matrix cache.

    Docking: the number of events passed (one entry per docked configuration).
    A continuously varying plant (a turning paddle): ``t`` itself, since its
    matrices change every step. Any other piecewise-constant scenario: its
    configuration.
    """
    if isinstance(scenario, DockingScenario):
        times = scenario.event_times()
        return lambda t: bisect_right(times, t)
    if not scenario.piecewise_constant:
        return float
    return scenario.configuration


class FlexibleSpacecraftModel:
    """Time-varying truth model of the flexible spacecraft.

    Parameters
    ----------
    params : SpacecraftParameters, optional
        Physical parameters; default :func:`ets8_parameters` with 2 modes per
        appendage (n = 22).
    scenario : str or Scenario
        ``"constant"``, ``"docking"``, ``"solar_rotation"``,
        ``"docking_solar_rotation"`` or a :class:`Scenario` instance.
    outputs : sequence of str
        Output groups to measure, a subset of ``("attitude", "rate",
        "deflection")``; stacked in the canonical order.
    dt : float
        Sample time of the discrete model, s (paper: 0.1).
    cache_size : int, optional
        Most per-step discrete models kept in the scenario's LRU cache (at
        least 128, two interpolation blocks); default holds a full 2500-step
        rotation episode within about 64 MB.
        The configuration-level caches behind it (exact exponentials per
        docked configuration, angle interpolants) are bounded separately and
        shared by every model of the same parameters and ``dt`` in the
        process (new envs, vector envs, :meth:`with_scenario` copies), so
        they survive episodes and envs.

    Attributes
    ----------
    n : int
        State order, 2 (3 + sum k_i).
    n_inputs : int
        3 torques (N m).
    n_outputs : int
        Number of measured outputs m.
    output_labels : tuple of str
        Name of every output channel (``"psi_x"``, ..., ``"w_s1_1.00"``).
    output_layout : spacecraft_conventions.OutputLayout
        Rows of each output group in ``C`` (``C[model.output_layout.slice("rate")]``).
    n_sensors : int
        Deflection sensors over all appendages.
    """

    def __init__(self, params: SpacecraftParameters | None = None,
                 scenario: str | Scenario = "constant",
                 outputs: Sequence[str] = OUTPUT_GROUPS, dt: float = 0.1,
                 cache_size: int | None = None) -> None:
        if params is None:
            params = ets8_parameters()
        if not isinstance(params, SpacecraftParameters):
            raise TypeError(f"params must be SpacecraftParameters, got {type(params).__name__}")
        dt = float(dt)
        if not np.isfinite(dt) or dt <= 0:
            raise ValueError(f"dt must be a positive finite number of seconds, got {dt}")
        if isinstance(outputs, str):
            outputs = (outputs,)
        unknown = [o for o in outputs if o not in OUTPUT_GROUPS]
        if unknown or not outputs:
            raise ValueError(f"outputs must be a non-empty subset of {OUTPUT_GROUPS}, "
                             f"got {tuple(outputs)}")
        self.params = params
        self.scenario = make_scenario(scenario)
        self.outputs = tuple(o for o in OUTPUT_GROUPS if o in outputs)
        self.dt = dt
        self._key = _scenario_key(self.scenario)
        self._build_constant_parts()
        if cache_size is None:
            per_entry = 8 * self.n * (self.n + 3)
            cache_size = int(np.clip(64e6 // per_entry, 16, 4096))
        cache_size = max(int(cache_size), 2 * _BLOCK_STEPS)
        self._cache_size = int(cache_size)
        self._cache: OrderedDict = OrderedDict()
        self._shared = _shared_discretization(self)

    # ------------------------------------------------------------------ setup
    def _build_constant_parts(self) -> None:
        p = self.params
        self.n_dof = p.n_dof
        self.n = p.order
        self.n_inputs = 3
        kk = sum(p.n_modes)
        omega = np.concatenate([2 * np.pi * np.asarray(a.frequencies_hz) for a in p.appendages])
        zeta = np.concatenate([np.full(a.n_modes, a.damping) for a in p.appendages])
        self.modal_frequencies_rad = omega
        self._K = np.diag(np.concatenate([np.zeros(3), omega**2]))
        self._E = np.diag(np.concatenate([np.zeros(3), 2 * zeta * omega]))
        self._L = np.zeros((self.n_dof, 3))
        self._L[:3] = np.eye(3)
        self._neg_k_modal = -(omega**2)
        self._neg_e_modal = -2 * zeta * omega
        self._eye_modal = np.eye(kk)
        self._eye_dof = np.eye(self.n_dof)

        # Time-invariant part of J: hub, non-rotating appendages, all
        # parallel-axis terms (the paddles rotate about their own mass centre).
        r_r = np.asarray(p.hub_position)
        j_fixed = np.asarray(p.hub_inertia) - p.hub_mass * skew(r_r) @ skew(r_r)
        for a in p.appendages:
            s_r = skew(a.position_vector)
            j_fixed = j_fixed - a.mass * s_r @ s_r
            if not a.rotates:
                j_fixed = j_fixed + a.inertia_matrix
        self._j_fixed = j_fixed
        self._rotating = [a for a in p.appendages if a.rotates]

        # Coupling. Non-rotating appendages have fixed columns. A rotating one
        # is linear in its bending direction d = T^T d0 (modes.coupling_matrix):
        # F = (sqrt(m) S(h) d) I0^T + (sqrt(m) L S(e) d) I1^T, so we keep the two
        # 3x3 operators and the closed-form moments and never redo root finding.
        self._mode_slices = []
        start = 3
        for a in p.appendages:
            self._mode_slices.append(slice(start, start + a.n_modes))
            start += a.n_modes
        self._F_fixed = np.zeros((3, kk))
        self._F_rotating = []  # (columns, sqrt(m) S(h), sqrt(m) L S(e), d0, I0, I1)
        self._root_terms = []  # (columns, sqrt(m), d0, I0, rotates): for a moved mass centre
        self._undocked_mass = p.hub_mass + sum(a.mass for a in p.appendages)
        for a, sl in zip(p.appendages, self._mode_slices, strict=True):
            cols = slice(sl.start - 3, sl.stop - 3)
            if not p.coupling:
                continue
            hinge, span, d0 = (np.asarray(v) for v in (a.hinge, a.span_axis, a.bending_axis))
            self._root_terms.append((cols, np.sqrt(a.mass), d0, cantilever_moments(a.n_modes)[0],
                                     a.rotates))
            if a.rotates:
                i0, i1 = cantilever_moments(a.n_modes)
                root_op = np.sqrt(a.mass) * skew(hinge)
                lever_op = np.sqrt(a.mass) * a.length * skew(span)
                self._F_rotating.append((cols, root_op, lever_op, d0, i0, i1))
            else:
                self._F_fixed[:, cols] = coupling_matrix(a.mass, a.length, hinge, span, d0,
                                                         a.n_modes)

        self._build_rotation_harmonics()

        # Output matrix (time-invariant: sensors ride on the appendages).
        nd = self.n_dof
        self.n_sensors = sum(len(a.sensor_positions) for a in p.appendages)
        self.output_layout = OutputLayout.of(self.outputs, self.n_sensors)
        blocks = {"attitude": np.eye(3, self.n), "rate": np.eye(3, self.n, nd)}
        labels = {g: [f"{LABEL_PREFIX[g]}_{axis}" for axis in AXES] for g in ("attitude", "rate")}
        phis, labels["deflection"] = [], []
        for a, sl in zip(p.appendages, self._mode_slices, strict=True):
            phi = sensor_mode_shapes(a.mass, np.asarray(a.sensor_positions), a.n_modes)
            block = np.zeros((phi.shape[0], self.n))
            block[:, sl] = phi
            phis.append(block)
            labels["deflection"] += [f"{LABEL_PREFIX['deflection']}_{a.name}_{s:.2f}"
                                     for s in a.sensor_positions]
        blocks["deflection"] = np.vstack(phis)
        self.C = np.vstack([blocks[g] for g in self.outputs])
        self.C.flags.writeable = False
        self.D = np.zeros((self.C.shape[0], 3))
        self.D.flags.writeable = False
        self.n_outputs = self.C.shape[0]
        self.output_labels = tuple(lab for g in self.outputs for lab in labels[g])
        #: The appendage of each deflection channel, and whether the paddle drive
        #: (about :data:`DRIVE_AXIS`) turns each appendage.
        self.sensor_appendage = tuple(i for i, a in enumerate(p.appendages)
                                      for _ in a.sensor_positions)
        self.appendage_turns = tuple(bool(a.rotates) for a in p.appendages)
        #: The drive's axis in the body frame (:data:`DRIVE_AXIS`), for a
        #: consumer that may not import this package (a controller's identifier).
        self.drive_axis = DRIVE_AXIS

    # --------------------------------------------------------- configuration
    def configuration(self, t: float) -> Configuration:
        """The scenario's configuration at time ``t`` (s).

        Returns
        -------
        Configuration
            The paddle angle and the modules docked at ``t``.
        """
        return self.scenario.configuration(float(t))

    def _paddle_inertia(self, theta: float) -> np.ndarray:
        """Sum of the rotating paddles' ``T^T J_s T`` at angle ``theta`` (rad)."""
        t_s = rotation_pitch(theta)
        return sum((t_s.T @ a.inertia_matrix @ t_s for a in self._rotating), np.zeros((3, 3)))

    def _rotating_coupling(self, theta: float) -> np.ndarray:
        """Coupling columns of the rotating paddles at angle ``theta`` (rad)."""
        f = np.zeros_like(self._F_fixed)
        t_s = rotation_pitch(theta)
        for cols, root_op, lever_op, d0, i0, i1 in self._F_rotating:
            d = t_s.T @ d0
            f[:, cols] = np.outer(root_op @ d, i0) + np.outer(lever_op @ d, i1)
        return f

    def _build_rotation_harmonics(self) -> None:
        """Exact harmonic form of the paddle terms, so no rotation per query.

        ``T^T J_s T`` is quadratic in (cos, sin) of theta, hence
        ``J_p(theta) = J0 + Jc cos 2 theta + Js sin 2 theta``; the coupling is
        linear in the rotated direction, ``F_p = F0 + Fc cos theta + Fs sin theta``.
        """
        j0, j90, j45 = (self._paddle_inertia(th) for th in (0.0, np.pi / 2, np.pi / 4))
        mean = 0.5 * (j0 + j90)
        self._j_harmonics = (mean, 0.5 * (j0 - j90), j45 - mean)
        f0, f90, f180 = (self._rotating_coupling(th) for th in (0.0, np.pi / 2, np.pi))
        fmean = 0.5 * (f0 + f180)
        self._f_harmonics = (fmean, 0.5 * (f0 - f180), f90 - fmean)

    def _mass_centre(self, cfg: Configuration) -> tuple[float, np.ndarray] | None:
        """Total mass (kg) and mass centre (m) with the docked modules, or None
        when the configuration keeps the paper's fixed mass centre."""
        if not (cfg.mass_centre_shift and cfg.modules):
            return None
        masses = np.array([m.mass for m in cfg.modules])
        total = self._undocked_mass + masses.sum()
        return total, masses @ np.array([m.position for m in cfg.modules]) / total

    def _inertia(self, cfg: Configuration) -> np.ndarray:
        j = self._j_fixed.copy()
        if self._rotating:
            mean, jc, js = self._j_harmonics
            two = 2.0 * cfg.paddle_angle
            j += mean + math.cos(two) * jc + math.sin(two) * js
        for module in cfg.modules:
            j += module.inertia_about_system_centre()
        centre = self._mass_centre(cfg)
        if centre is not None:      # parallel axes: J_c = J_o - M (|c|^2 I - c c^T)
            total, c = centre
            j -= total * (c @ c * np.eye(3) - np.outer(c, c))
        return j

    def _coupling(self, cfg: Configuration) -> np.ndarray:
        if not self._F_rotating:
            f = self._F_fixed.copy()
        else:
            mean, fc, fs = self._f_harmonics
            th = cfg.paddle_angle
            f = self._F_fixed + mean + math.cos(th) * fc + math.sin(th) * fs
        centre = self._mass_centre(cfg)
        if centre is not None and self.params.coupling:
            # every root moves by -c: F_i -= sqrt(m_i) (c x d_i) I0_i^T
            c = skew(centre[1])
            t_s = rotation_pitch(cfg.paddle_angle)
            for cols, root_mass, d0, i0, rotates in self._root_terms:
                d = t_s.T @ d0 if rotates else d0
                f[:, cols] -= np.outer(root_mass * (c @ d), i0)
        return f

    def inertia(self, t: float) -> np.ndarray:
        """Total inertia J(t) about the system mass centre, (3, 3), kg m^2.

        Returns
        -------
        (3, 3) ndarray
            J(t), kg m^2, symmetric positive definite.
        """
        return self._inertia(self.configuration(t))

    def coupling(self, t: float) -> np.ndarray:
        """Coupling matrix F(t) = [F_1, ..., F_N], (3, sum k_i), kg^(1/2) m.

        Returns
        -------
        (3, sum k_i) ndarray
            F(t), kg^(1/2) m.
        """
        return self._coupling(self.configuration(t))

    def _mass_matrix(self, cfg: Configuration) -> np.ndarray:
        nd = self.n_dof
        m = np.eye(nd)
        m[:3, :3] = self._inertia(cfg)
        f = self._coupling(cfg)
        m[:3, 3:] = f
        m[3:, :3] = f.T
        return m

    def mass_matrix(self, t: float) -> np.ndarray:
        """Generalized mass matrix M(t), (n_dof, n_dof); checked positive definite.

        Returns
        -------
        (n_dof, n_dof) ndarray
            M(t), symmetric positive definite.

        Raises
        ------
        ValueError
            If ``M(t)`` is not positive definite (``J - sum F_i F_i^T``
            must stay positive definite).
        """
        return self._checked_mass(self.configuration(t), t)

    def _checked_mass(self, cfg: Configuration, t: float) -> np.ndarray:
        m = self._mass_matrix(cfg)
        try:
            np.linalg.cholesky(m)
        except np.linalg.LinAlgError:
            raise _not_positive_definite(cfg, t) from None
        return m

    @property
    def stiffness(self) -> np.ndarray:
        """Stiffness matrix K, (n_dof, n_dof)."""
        return self._K.copy()

    @property
    def damping(self) -> np.ndarray:
        """Damping matrix E, (n_dof, n_dof)."""
        return self._E.copy()

    # --------------------------------------------------------------- matrices
    def _fill_continuous(self, out: np.ndarray, cfg: Configuration, t: float) -> None:
        """Write ``[A_c, B_c]`` into ``out[:n, :n + 3]`` (rest untouched).

        Uses the block inverse of M through the 3x3 Schur complement
        ``S = J - F F^T``, ``G = S^-1 F``:
        ``M^-1 = [[S^-1, -G], [-G^T, I + F^T G]]``. M is positive definite
        iff S is, which :func:`_inv3_spd` checks (Sylvester's criterion).
        ``t`` (s; NaN for a configuration off the scenario's path) only
        names the instant in the error.

        Raises
        ------
        ValueError
            If M is not positive definite.
        """
        nd = self.n_dof
        f = self._coupling(cfg)
        s_inv = _inv3_spd(self._inertia(cfg) - f @ f.T)
        if s_inv is None:
            raise _not_positive_definite(cfg, t)
        g = s_inv @ f
        # only the modal columns of K and E are non-zero: M^-1[:, 3:] = [-G; I + F^T G]
        minv_modal = np.vstack((-g, self._eye_modal + f.T @ g))
        out[:nd, nd:2 * nd] = self._eye_dof
        out[nd:self.n, 3:nd] = minv_modal * self._neg_k_modal
        out[nd:self.n, nd + 3:self.n] = minv_modal * self._neg_e_modal
        out[nd:nd + 3, self.n:] = s_inv
        out[nd + 3:self.n, self.n:] = -g.T

    def _continuous(self, cfg: Configuration, t: float) -> tuple[np.ndarray, np.ndarray]:
        aug = np.zeros((self.n, self.n + 3))
        self._fill_continuous(aug, cfg, t)
        return aug[:, :self.n].copy(), aug[:, self.n:].copy()

    def continuous(self, t: float) -> StateSpaceMatrices:
        """True continuous-time ``(A_c, B_c, C, D)`` at time ``t`` (s).

        Returns
        -------
        (A_c, B_c, C, D) : ndarrays
            (n, n), (n, 3), (m, n), (m, 3); SI units.
        """
        a, b = self._continuous(self.configuration(t), t)
        return StateSpaceMatrices(a, b, self.C.copy(), self.D.copy(), None)

    def modal(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Natural frequencies (Hz) and damping ratios of the true plant at ``t``.

        From the eigenvalues ``s`` of ``A_c(t)`` with positive imaginary part:
        ``|s| / 2 pi`` and ``-Re(s) / |s|``, sorted by frequency (the rigid-body
        poles at 0 are left out). The same definitions as
        ``identifiers.StateSpaceModel.modal`` uses for identified models.

        Returns
        -------
        (frequencies, damping) : ndarrays
            Frequencies (Hz) and damping ratios, sorted by frequency.
        """
        a, _ = self._continuous(self.configuration(t), t)
        s = np.linalg.eigvals(a)
        s = s[s.imag > 1e-9]
        wn = np.abs(s)
        order = np.argsort(wn)
        return wn[order] / (2 * np.pi), -s.real[order] / wn[order]

    def modal_residues(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frequencies (Hz), damping ratios and input-output weights of the modes at ``t``.

        The weight of a mode is the norm of its residue from the torques to
        the model's outputs, relative to the largest flexible one. Modes that
        hub torque hardly excites (the appendages' symmetric modes: their
        frequency stays at the cantilever value) have small weights and are
        barely identifiable from input-output data.

        Returns
        -------
        freq_hz, damping, weight : (k,) ndarray
            Sorted by frequency, as :meth:`modal`.
        """
        a, b = self._continuous(self.configuration(t), t)
        vals, vecs = np.linalg.eig(a)
        left = np.linalg.inv(vecs)
        keep = np.flatnonzero(vals.imag > 1e-9)
        wn = np.abs(vals[keep])
        order = np.argsort(wn)
        keep, wn = keep[order], wn[order]
        weight = np.array([np.linalg.norm(np.outer(self.C @ vecs[:, j], left[j] @ b))
                           for j in keep])
        return wn / (2 * np.pi), -vals[keep].real / wn, weight / weight.max()

    def _van_loan(self, cfg: Configuration, t: float) -> np.ndarray:
        """``[[A_c, B_c], [0, 0]] dt`` of configuration ``cfg`` ((n + 3, n + 3))."""
        aug = np.zeros((self.n + 3, self.n + 3))
        self._fill_continuous(aug, cfg, t)
        aug *= self.dt
        return aug

    def _discrete_ab(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Cached zero-order-hold ``(A_d, B_d)`` at time ``t`` (read-only arrays)."""
        key = self._key(t)
        cache = self._cache
        hit = cache.get(key)
        if hit is not None:
            return hit
        n = self.n
        if self.scenario.piecewise_constant:
            phi = self._shared.exact(self.configuration(t), t)
            entry = cache[key] = (phi[:n, :n], phi[:n, n:])
        else:
            entry = self._interpolate_block(t, key)
        while len(cache) > self._cache_size:
            cache.popitem(last=False)
        return entry

    def _interpolate_block(self, t: float, key) -> tuple[np.ndarray, np.ndarray]:
        """Interpolate (and cache) the ZOH of the whole block of steps holding ``t``.

        A time on the step grid (``t == k dt``) belongs to the fixed block of
        :data:`_BLOCK_STEPS` steps holding ``k``, evaluated in one product,
        so the per-step cost is a fraction of one evaluation; any other time
        is a block of its own. Block membership is a function of ``t`` alone,
        so the bits never depend on the query history.
        """
        n, dt = self.n, self.dt
        k = round(t / dt)
        if k >= 0 and k * dt == t:
            start = k - k % _BLOCK_STEPS
            ts = [(start + j) * dt for j in range(_BLOCK_STEPS)]
        else:
            ts = [t]
        phis = self._zoh_along(ts)
        phis.flags.writeable = False
        cache = self._cache
        for tj, phi in zip(ts, phis, strict=True):
            cache[tj] = (phi[:, :n], phi[:, n:])
        return cache[key]

    def _zoh_along(self, ts: list[float]) -> np.ndarray:
        """Interpolated ``[A_d, B_d]`` at the increasing times ``ts`` (s), ``(len(ts), n, n + 3)``.

        Where the block holds no event and its ends agree on everything but
        the paddle angle, only the angle changes inside it (the
        :meth:`spacecraft_env.scenarios.Scenario.event_times` contract):
        one configuration and a list of angles, without building a
        configuration per step. The interpolant's rows are the same either
        way (the same panel groups).
        """
        scenario = self.scenario
        base = dataclasses.replace(self.configuration(ts[0]), paddle_angle=0.0)
        if (len(ts) > 1
                and dataclasses.replace(self.configuration(ts[-1]), paddle_angle=0.0) == base
                and not any(ts[0] < e <= ts[-1] for e in scenario.event_times())):
            return self._shared.panels.evaluate_along(
                base, [scenario.paddle_angle(tj) for tj in ts])
        cfgs = [self.configuration(tj) for tj in ts]
        return self._shared.panels.evaluate([dataclasses.replace(c, paddle_angle=0.0)
                                             for c in cfgs], [c.paddle_angle for c in cfgs])

    def discrete(self, t: float) -> StateSpaceMatrices:
        """True zero-order-hold ``(A_d, B_d, C, D)`` for the step starting at ``t``.

        Returns
        -------
        StateSpaceModel
            ``(A_d, B_d, C, D)`` of the step (``K`` zero), sample time ``dt``.
        """
        ad, bd = self._discrete_ab(t)
        return StateSpaceMatrices(ad.copy(), bd.copy(), self.C.copy(), self.D.copy(), self.dt)

    def with_scenario(self, scenario: str | Scenario) -> FlexibleSpacecraftModel:
        """A copy sharing the constant matrices but following another scenario.

        Returns
        -------
        FlexibleSpacecraftModel
            The copy.
        """
        new = object.__new__(FlexibleSpacecraftModel)
        new.__dict__.update(self.__dict__)
        new.scenario = make_scenario(scenario)
        new._key = _scenario_key(new.scenario)
        new._cache = OrderedDict()
        return new

    def nominal(self, paddle_angle_deg: float = 0.0) -> FlexibleSpacecraftModel:
        """The design model of a fixed controller: this spacecraft with nothing docked
        and the paddles at ``paddle_angle_deg`` (0: the nominal configuration), constant.

        Returns
        -------
        FlexibleSpacecraftModel
            A constant model of the same spacecraft.
        """
        return self.with_scenario(ConstantScenario(paddle_angle_deg=float(paddle_angle_deg)))

    def clear_cache(self) -> None:
        """Forget every cached discrete model (this scenario's and the shared ones)."""
        self._cache.clear()
        self._shared.clear()

    # ------------------------------------------------------------ simulation
    def step(self, x: np.ndarray, u: np.ndarray, t: float) -> np.ndarray:
        """Exact ZOH step from time ``t``: ``x(t + dt)`` for constant torque ``u``.

        Returns
        -------
        (n,) ndarray
            ``x(t + dt)``.
        """
        ad, bd = self._discrete_ab(t)
        return ad @ x + bd @ u

    def simulate(self, inputs: np.ndarray, x0: np.ndarray | None = None,
                 t0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Noiseless response to a torque sequence.

        Parameters
        ----------
        inputs : (N, 3) array_like
            Torques u_k, N m, held over [t0 + k dt, t0 + (k + 1) dt).
        x0 : (n,) array_like, optional
            Initial state (default zero).
        t0 : float
            Start time, s.

        Returns
        -------
        states : (N + 1, n) ndarray
            x_0 ... x_N.
        outputs : (N, m) ndarray
            y_k = C x_k, k = 0 .. N - 1.
        """
        u = np.asarray(inputs, dtype=float)
        if u.ndim != 2 or u.shape[1] != 3:
            raise ValueError(f"inputs must have shape (N, 3), got {u.shape}")
        if not np.all(np.isfinite(u)):
            raise ValueError("inputs must be finite")
        x = np.zeros(self.n) if x0 is None else np.asarray(x0, dtype=float).copy()
        if x.shape != (self.n,):
            raise ValueError(f"x0 must have shape ({self.n},), got {x.shape}")
        states = np.empty((u.shape[0] + 1, self.n))
        states[0] = x
        for k in range(u.shape[0]):
            ad, bd = self._discrete_ab(t0 + k * self.dt)
            x = ad @ x + bd @ u[k]
            states[k + 1] = x
        return states, states[:-1] @ self.C.T

    def capture_steps(self) -> frozenset[int]:
        """Steps ``k`` (from t = 0) whose configuration first holds a module that
        brings its own angular momentum (:meth:`capture` applies there).

        Returns
        -------
        frozenset of int
            The steps.
        """
        steps = set()
        for module in self.configuration(math.inf).modules:
            if module.angular_momentum is None:
                continue
            k = math.ceil(module.time / self.dt)
            while k > 0 and (k - 1) * self.dt >= module.time:
                k -= 1
            while k * self.dt < module.time:
                k += 1
            steps.add(k)
        return frozenset(steps)

    def capture(self, x: np.ndarray, t: float) -> np.ndarray:
        """The state just after the modules docking at the step from ``t`` are captured.

        The capture is a plastic impact: positions carry on and the total
        angular momentum is conserved,
        ``M_+ delta'_+ = M_- delta'_- + [sum_i h_i; 0]``, with ``h_i`` the
        captured module's angular momentum (:class:`DockingModule`); a module
        without one arrives co-rotating and brings ``J_i omega``. With only
        co-rotating modules the rates carry on unchanged.

        Parameters
        ----------
        x : (n,) ndarray
            State before the capture.
        t : float
            Start of the first step whose configuration holds the new modules, s.

        Returns
        -------
        (n,) ndarray
        """
        before, after = self.configuration(t - self.dt), self.configuration(t)
        new = [m for m in after.modules if m not in before.modules]
        if all(m.angular_momentum is None for m in new):
            return np.array(x, dtype=float)
        nd = self.n_dof
        v = np.asarray(x, dtype=float)[nd:]
        momentum = self._mass_matrix(before) @ v
        for m in new:
            momentum[:3] += (m.inertia_about_system_centre() @ v[:3]
                             if m.angular_momentum is None else m.angular_momentum)
        out = np.array(x, dtype=float)
        out[nd:] = np.linalg.solve(self._checked_mass(after, t), momentum)
        return out

    def energy(self, x: np.ndarray, t: float) -> float:
        """Mechanical energy ``1/2 delta'^T M delta' + 1/2 delta^T K delta``, J.

        Returns
        -------
        float
            The energy, J.
        """
        nd = self.n_dof
        m = self._mass_matrix(self.configuration(t))
        q, v = x[:nd], x[nd:]
        return 0.5 * float(v @ m @ v + q @ self._K @ q)

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_cache"] = OrderedDict()  # rebuilt on demand; keeps pickles small
        del state["_key"], state["_shared"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._key = _scenario_key(self.scenario)
        self._shared = _shared_discretization(self)


#: Configuration-level caches per physics ``(params, dt)``, shared by every model
#: of the process (a new env, each env of a vector env); least recently used go first.
_SHARED: OrderedDict = OrderedDict()
_MAX_SHARED_PHYSICS = 4


def _shared_discretization(model: FlexibleSpacecraftModel) -> _SharedDiscretization:
    """The process-wide ZOH caches for ``model``'s physics (created on first use)."""
    key = (model.params, model.dt)
    shared = _SHARED.get(key)
    if shared is None:
        shared = _SHARED[key] = _SharedDiscretization(model)
        while len(_SHARED) > _MAX_SHARED_PHYSICS:
            _SHARED.popitem(last=False)
    else:
        _SHARED.move_to_end(key)
    return shared


class _SharedDiscretization:
    """The configuration-level ZOH caches of every model with the same physics.

    ``exact(cfg)`` holds the exponential of each piecewise-constant
    configuration (bounded LRU); ``panels`` the angle interpolants of the
    rotating scenarios (:class:`spacecraft_env.discretization.AnglePanels`).
    Both depend on the physics and ``dt`` only, never on the scenario's
    timing or the outputs, so every model of the same ``(params, dt)`` in the
    process shares them (:func:`_shared_discretization`), as do
    :meth:`FlexibleSpacecraftModel.with_scenario` copies. Their values do not
    depend on what is cached, so sharing never changes a result.
    """

    def __init__(self, model: FlexibleSpacecraftModel, max_configs: int = 64) -> None:
        self._model = model
        self._configs: OrderedDict = OrderedDict()
        self._max_configs = int(max_configs)
        self.panels = AnglePanels(self._build_panel, model.n)

    def _build_panel(self, cfg: Configuration, thetas: np.ndarray) -> np.ndarray:
        m = self._model
        return np.stack([m._van_loan(dataclasses.replace(cfg, paddle_angle=float(th)), math.nan)
                         for th in thetas])

    def exact(self, cfg: Configuration, t: float) -> np.ndarray:
        """Read-only ``[A_d, B_d]`` rows of the exponential of configuration ``cfg``."""
        hit = self._configs.get(cfg)
        if hit is not None:
            self._configs.move_to_end(cfg)
            return hit
        n = self._model.n
        phi = zoh_exponential(self._model._van_loan(cfg, t))[:n]
        phi.flags.writeable = False
        self._configs[cfg] = phi
        if len(self._configs) > self._max_configs:
            self._configs.popitem(last=False)
        return phi

    def clear(self) -> None:
        self._configs.clear()
        self.panels.clear()
