"""Physical parameters of the ETS-VIII rigid-flexible spacecraft.

All parameters are frozen dataclasses validated on creation. Vectors and
matrices are stored as tuples (hashable, picklable, immutable) and exposed as
read-only numpy arrays through properties.

Sources: Ni et al. (2019), Appendix A and Table 2 (docs/design/model.md
has the equations and numbers). Where the paper is silent (appendage
geometry, bending directions, sensor points) the choice is documented on
the field.

Frames and units
----------------
Body frame: x = roll, y = pitch (solar-paddle span axis), z = yaw. Positions
are measured from the system mass centre, in metres; masses in kg; inertias
in kg m^2 about the body's own mass centre; frequencies in Hz.

Inertia reading
-------------------------------------------------
The PDF extraction interleaves the paddle and antenna inertia matrices. We
read the paddle inertia as ``[[1683.4, 0, 853.8], [0, 18.2, 0],
[853.8, 0, 3629.9]]`` (small inertia about the paddle's own span axis, y)
and the antenna inertia as ``diag(3611.7, 3226.8, 3291.3)``. With it
``J(0)`` is about ``[[28898, 0, 1708], [0, 19398, 0], [1708, 0, 22363]]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from spacecraft_env.limits import check_parameter

__all__ = [
    "ANTENNA_FREQUENCIES_HZ",
    "MAX_MODES",
    "PADDLE_FREQUENCIES_HZ",
    "AppendageParameters",
    "DockingModule",
    "SpacecraftParameters",
    "ets8_parameters",
]

#: Cantilever frequencies of the solar paddles s1/s2, modes 1..8 (Table 2), Hz.
PADDLE_FREQUENCIES_HZ: tuple[float, ...] = (
    0.0767, 0.5063, 0.9958, 1.4848, 3.0459, 3.0609, 5.2750, 5.3488,
)
#: Cantilever frequencies of the antenna reflectors a1/a2, modes 1..8 (Table 2), Hz.
ANTENNA_FREQUENCIES_HZ: tuple[float, ...] = (
    0.0887, 0.2364, 0.3698, 0.4935, 0.9236, 0.9936, 1.3815, 1.7823,
)
#: Largest number of modes per appendage the tables provide.
MAX_MODES = 8


def _vector(name: str, value: Sequence[float], size: int = 3) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return tuple(float(v) for v in arr)


def _matrix3(name: str, value: Sequence[Sequence[float]]) -> tuple[tuple[float, ...], ...]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must have shape (3, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    if not np.allclose(arr, arr.T, rtol=0, atol=1e-9 * max(1.0, np.abs(arr).max())):
        raise ValueError(f"{name} must be symmetric")
    if np.linalg.eigvalsh(arr).min() <= 0:
        raise ValueError(f"{name} must be positive definite")
    return tuple(tuple(float(v) for v in row) for row in arr)


def _unit(name: str, value: Sequence[float]) -> tuple[float, ...]:
    vec = np.asarray(_vector(name, value))
    norm = np.linalg.norm(vec)
    if norm < 1e-12:
        raise ValueError(f"{name} must be a non-zero direction")
    return tuple(float(v) for v in vec / norm)


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value}")
    return value


def _readonly(value) -> np.ndarray:
    arr = np.array(value, dtype=float)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class AppendageParameters:
    """One flexible appendage modelled as a uniform Euler-Bernoulli cantilever.

    Parameters
    ----------
    name : str
        Identifier (``"s1"``, ``"s2"``, ``"a1"``, ``"a2"`` for ETS-VIII).
    mass : float
        Appendage mass m_i, kg.
    inertia : (3, 3) array_like
        Own inertia J_i about its mass centre, appendage frame, kg m^2.
    position : (3,) array_like
        Mass-centre position r_i from the system mass centre, m.
    hinge : (3,) array_like
        Root (clamp) point of the cantilever from the system mass centre, m.
    span_axis : (3,) array_like
        Unit direction from the root along the span (body frame).
    bending_axis : (3,) array_like
        Unit out-of-plane bending direction d_i at zero rotation (body frame);
        must be orthogonal to ``span_axis``.
    length : float
        Span length L_i, m.
    frequencies_hz : sequence of float
        Cantilever (clamped-hub) natural frequencies, Hz, increasing.
    damping : float
        Modal damping ratio zeta, shared by every mode (paper: 0.01).
    rotates : bool
        True for the solar paddles, which turn about the pitch axis in the
        ``solar_rotation`` scenario (``T_s(t)`` in Appendix A).
    sensor_positions : sequence of float
        Sensor points as fractions of the span in (0, 1]; each gives one
        out-of-plane deflection output ``w = Phi eta``.
    """

    name: str
    mass: float
    inertia: tuple
    position: tuple
    hinge: tuple
    span_axis: tuple
    bending_axis: tuple
    length: float
    frequencies_hz: tuple
    damping: float = 0.01
    rotates: bool = False
    sensor_positions: tuple = (1.0,)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if not isinstance(self.name, str) or not self.name:
            raise TypeError("name must be a non-empty string")
        set_(self, "mass", _positive("mass", self.mass))
        set_(self, "inertia", _matrix3("inertia", self.inertia))
        set_(self, "position", _vector("position", self.position))
        set_(self, "hinge", _vector("hinge", self.hinge))
        set_(self, "span_axis", _unit("span_axis", self.span_axis))
        set_(self, "bending_axis", _unit("bending_axis", self.bending_axis))
        if abs(np.dot(self.span_axis, self.bending_axis)) > 1e-9:
            raise ValueError("bending_axis must be orthogonal to span_axis")
        set_(self, "length", _positive("length", self.length))
        freqs = np.asarray(self.frequencies_hz, dtype=float)
        if freqs.ndim != 1 or freqs.size < 1:
            raise ValueError("frequencies_hz must be a non-empty 1-D sequence")
        if not np.all(np.isfinite(freqs)) or np.any(freqs <= 0) or np.any(np.diff(freqs) < 0):
            raise ValueError("frequencies_hz must be positive, finite and non-decreasing")
        set_(self, "frequencies_hz", tuple(float(f) for f in freqs))
        damping = float(self.damping)
        if not np.isfinite(damping) or not 0.0 <= damping < 1.0:
            raise ValueError(f"damping must be in [0, 1), got {damping}")
        set_(self, "damping", damping)
        sensors = np.atleast_1d(np.asarray(self.sensor_positions, dtype=float))
        if sensors.ndim != 1 or np.any(sensors <= 0) or np.any(sensors > 1):
            raise ValueError("sensor_positions must be span fractions in (0, 1]")
        set_(self, "sensor_positions", tuple(float(s) for s in sensors))
        set_(self, "rotates", bool(self.rotates))

    @property
    def n_modes(self) -> int:
        """Number of retained modes k_i."""
        return len(self.frequencies_hz)

    @cached_property
    def inertia_matrix(self) -> np.ndarray:
        """Own inertia J_i as a read-only (3, 3) array, kg m^2."""
        return _readonly(self.inertia)

    @cached_property
    def position_vector(self) -> np.ndarray:
        """Mass-centre position r_i as a read-only (3,) array, m."""
        return _readonly(self.position)

    def with_modes(self, n_modes: int) -> AppendageParameters:
        """Return a copy keeping the first ``n_modes`` frequencies.

        Returns
        -------
        AppendageParameters
            The copy.
        """
        if not 1 <= n_modes <= len(self.frequencies_hz):
            raise ValueError(
                f"n_modes must be in [1, {len(self.frequencies_hz)}] for {self.name}, "
                f"got {n_modes}"
            )
        return replace(self, frequencies_hz=self.frequencies_hz[:n_modes])


@dataclass(frozen=True)
class DockingModule:
    """A rigid cuboid that docks with the hub (paper Case 1, Fig. 4).

    Parameters
    ----------
    mass : float
        Module mass, kg (paper: 600).
    dimensions : (3,) array_like
        Edge lengths along body x, y, z, m (paper: 2.35 x 2.45 x 3).
    position : (3,) array_like
        Module mass centre from the system mass centre, m. The paper assumes
        docking leaves the system mass centre where it was; we follow it.
        Default: on the yaw axis 3 m from the mass centre (hub half-height
        1.5 m plus the module's half-length 1.5 m).
    time : float
        Docking instant, s.
    angular_momentum : (3,) array_like or None
        The module's angular momentum at capture (N m s, body frame, about
        the system mass centre). ``None`` (default, the paper's assumption):
        it arrives co-rotating with the spacecraft, and the body rates carry
        on. A vector (0 for a module at rest, or a tumbling target's
        momentum): the capture conserves the total angular momentum, and the
        rates jump (``FlexibleSpacecraftModel.capture``).
    """

    mass: float = 600.0
    dimensions: tuple = (2.35, 2.45, 3.0)
    position: tuple = (0.0, 0.0, 3.0)
    time: float = 100.0
    angular_momentum: tuple | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", check_parameter(
            "module_mass", _positive("mass", self.mass), "mass"))
        dims = _vector("dimensions", self.dimensions)
        if min(dims) <= 0:
            raise ValueError("dimensions must be positive")
        object.__setattr__(self, "dimensions", dims)
        object.__setattr__(self, "position", _vector("position", self.position))
        object.__setattr__(self, "time", check_parameter("docking_time", self.time, "time"))
        if self.angular_momentum is not None:
            momentum = _vector("angular_momentum", self.angular_momentum)
            for value in momentum:
                check_parameter("capture_momentum", value, "angular_momentum")
            object.__setattr__(self, "angular_momentum", momentum)

    def inertia_about_system_centre(self) -> np.ndarray:
        """Own cuboid inertia plus the parallel-axis term, (3, 3), kg m^2 (read-only).

        Computed once per module: the truth model adds it at every
        interpolation node of a docked configuration.

        Returns
        -------
        (3, 3) ndarray
            The inertia, kg m^2 (read-only).
        """
        cached = self.__dict__.get("_inertia_cache")
        if cached is None:
            a, b, c = self.dimensions
            own = self.mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
            r = np.asarray(self.position)
            cached = own + self.mass * (r @ r * np.eye(3) - np.outer(r, r))
            cached.flags.writeable = False
            object.__setattr__(self, "_inertia_cache", cached)
        return cached


@dataclass(frozen=True)
class SpacecraftParameters:
    """The whole spacecraft: rigid hub plus flexible appendages.

    Parameters
    ----------
    hub_mass : float
        Central rigid body mass m_r, kg (paper: 2400).
    hub_inertia : (3, 3) array_like
        Hub own inertia J_r, kg m^2 (paper: diag(11858.5, 11762.5, 2305)).
    hub_position : (3,) array_like
        Hub mass centre r_r from the system mass centre, m.
    appendages : tuple of AppendageParameters
        The flexible appendages, in output order.
    coupling : bool
        If False the rigid-flexible coupling matrices F_i are zeroed: the
        modes then vibrate at exactly their cantilever frequencies (for
        checks against closed forms).
    """

    hub_mass: float
    hub_inertia: tuple
    hub_position: tuple
    appendages: tuple = field(default_factory=tuple)
    coupling: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "hub_mass", _positive("hub_mass", self.hub_mass))
        object.__setattr__(self, "hub_inertia", _matrix3("hub_inertia", self.hub_inertia))
        object.__setattr__(self, "hub_position", _vector("hub_position", self.hub_position))
        apps = tuple(self.appendages)
        if not all(isinstance(a, AppendageParameters) for a in apps):
            raise TypeError("appendages must be AppendageParameters instances")
        names = [a.name for a in apps]
        if len(set(names)) != len(names):
            raise ValueError(f"appendage names must be unique, got {names}")
        object.__setattr__(self, "appendages", apps)
        object.__setattr__(self, "coupling", bool(self.coupling))

    @property
    def n_modes(self) -> tuple[int, ...]:
        """Modes per appendage (k_1, ..., k_N)."""
        return tuple(a.n_modes for a in self.appendages)

    @property
    def n_dof(self) -> int:
        """Generalized coordinates: 3 attitude angles plus all modal coordinates."""
        return 3 + sum(self.n_modes)

    @property
    def order(self) -> int:
        """State dimension n = 2 (3 + sum k_i)."""
        return 2 * self.n_dof

    def with_modes(self, n_modes: int) -> SpacecraftParameters:
        """Copy keeping ``n_modes`` modes on every appendage (1..8).

        Returns
        -------
        SpacecraftParameters
            The copy.
        """
        if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)):
            raise TypeError(f"n_modes must be an int, got {type(n_modes).__name__}")
        return replace(self, appendages=tuple(a.with_modes(int(n_modes)) for a in self.appendages))

    def without_coupling(self) -> SpacecraftParameters:
        """Copy with the coupling matrices F_i switched off.

        Returns
        -------
        SpacecraftParameters
            The copy.
        """
        return replace(self, coupling=False)

    def with_damping(self, damping: float) -> SpacecraftParameters:
        """Copy with every modal damping ratio set to ``damping``.

        Returns
        -------
        SpacecraftParameters
            The copy.
        """
        return replace(self, appendages=tuple(replace(a, damping=damping) for a in self.appendages))


# ---------------------------------------------------------------------------
# ETS-VIII defaults
# ---------------------------------------------------------------------------
_Z0 = 0.4827  # height of every mass centre above the system mass centre (Appendix A), m
_HUB_HALF_WIDTH_Y = 1.225  # hub half-width along pitch (2.45 m module face), m
_SIN_CANT, _COS_CANT = 0.5, float(np.sqrt(3.0) / 2.0)  # antenna cant of 30 deg about roll


def _paddle_normal() -> tuple[float, float, float]:
    """Plate normal of the paddle: principal axis of largest inertia in x-z.

    The paddle lies in the plane spanned by its span axis (y) and the
    principal direction of smallest in-plane inertia; it bends along the
    principal axis of largest inertia, about (0.352, 0, 0.936).
    """
    jxz = np.array([[1683.4, 853.8], [853.8, 3629.9]])
    w, v = np.linalg.eigh(jxz)
    nx, nz = v[:, np.argmax(w)]
    if nz < 0:
        nx, nz = -nx, -nz
    return (float(nx), 0.0, float(nz))


def ets8_parameters(n_modes: int = 2, *, coupling: bool = True, damping: float = 0.01,
                    sensor_positions: Sequence[float] = (1.0,)) -> SpacecraftParameters:
    """ETS-VIII parameters (Appendix A, Table 2) with our documented geometry.

    Geometry (not printed in the paper; chosen so each appendage's mass
    centre sits at its Appendix A position ``r_i``):

    * Solar paddles s1/s2: cantilevers along +-y, root at |y| = 1.225 m (hub
      face), length 7.55 m, so the uniform-beam mass centre is at |y| = 5 m;
      height z = 0.4827 m. They bend along the plate normal (principal axis
      of largest paddle inertia, about (0.352, 0, 0.936)), which turns with
      the paddle about pitch.
    * Antenna reflectors a1/a2: cantilevers along +-x from the hub's y-z
      mid-plane (the reflector tower root), length 2.35 m, mass centre at
      |x| = 1.175 m, height 0.4827 m. The two reflectors serve different
      areas and are canted by +-30 deg about roll, so their out-of-plane
      bending directions are (0, +-sin 30, cos 30).

    With this geometry the paddles couple with roll and yaw (their symmetric
    mode weakly with pitch) and the antennas with pitch and yaw. Without the
    cant the antennas' symmetric modes would be exactly uncontrollable from
    the hub torque (mirror symmetry), and an n = 2 (3 + 4 k) model would
    over-parameterize the input-output behaviour.

    Parameters
    ----------
    n_modes : int
        Modes per appendage, 1..8; the state order is n = 2 (3 + 4 n_modes).
    coupling : bool
        Keep the coupling matrices (False for closed-form checks).
    damping : float
        Modal damping ratio for every mode.
    sensor_positions : sequence of float
        Span fractions of the deflection sensors on every appendage (Fig. 3);
        default: one sensor at each tip.

    Returns
    -------
    SpacecraftParameters
        Hub of 2400 kg and inertia diag(11858.5, 11762.5, 2305) kg m^2 and the
        four appendages s1, s2, a1, a2, in that (output) order.

    Raises
    ------
    TypeError
        ``n_modes`` is not an int (a bool is refused).
    ValueError
        ``n_modes`` is outside 1..8.
    """
    if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)):
        raise TypeError(f"n_modes must be an int in [1, {MAX_MODES}], got {n_modes!r}")
    if not 1 <= n_modes <= MAX_MODES:
        raise ValueError(f"n_modes must be in [1, {MAX_MODES}], got {n_modes}")
    k = int(n_modes)
    paddle_inertia = ((1683.4, 0.0, 853.8), (0.0, 18.2, 0.0), (853.8, 0.0, 3629.9))
    antenna_inertia = ((3611.7, 0.0, 0.0), (0.0, 3226.8, 0.0), (0.0, 0.0, 3291.3))
    paddle_length = 2.0 * (5.0 - _HUB_HALF_WIDTH_Y)
    antenna_length = 2.0 * 1.175
    normal = _paddle_normal()
    common = {"damping": damping, "sensor_positions": tuple(sensor_positions)}
    appendages = (
        AppendageParameters(
            "s1", 115.2, paddle_inertia, (0.0, 5.0, _Z0), (0.0, _HUB_HALF_WIDTH_Y, _Z0),
            (0.0, 1.0, 0.0), normal, paddle_length, PADDLE_FREQUENCIES_HZ[:k],
            rotates=True, **common,
        ),
        AppendageParameters(
            "s2", 115.2, paddle_inertia, (0.0, -5.0, _Z0), (0.0, -_HUB_HALF_WIDTH_Y, _Z0),
            (0.0, -1.0, 0.0), normal, paddle_length, PADDLE_FREQUENCIES_HZ[:k],
            rotates=True, **common,
        ),
        AppendageParameters(
            "a1", 165.0, antenna_inertia, (1.175, 0.0, _Z0), (0.0, 0.0, _Z0),
            (1.0, 0.0, 0.0), (0.0, _SIN_CANT, _COS_CANT), antenna_length,
            ANTENNA_FREQUENCIES_HZ[:k], **common,
        ),
        AppendageParameters(
            "a2", 165.0, antenna_inertia, (-1.175, 0.0, _Z0), (0.0, 0.0, _Z0),
            (-1.0, 0.0, 0.0), (0.0, -_SIN_CANT, _COS_CANT), antenna_length,
            ANTENNA_FREQUENCIES_HZ[:k],
            **common,
        ),
    )
    return SpacecraftParameters(
        hub_mass=2400.0,
        hub_inertia=((11858.5, 0.0, 0.0), (0.0, 11762.5, 0.0), (0.0, 0.0, 2305.0)),
        hub_position=(0.0, 0.0, _Z0),
        appendages=appendages,
        coupling=coupling,
    )
