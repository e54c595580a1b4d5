"""The LQG control law every model-based controller here shares, with integral action.

For a model ``x_{k+1} = A x_k + B u_k``, ``y = C x`` with attitude rows
``C_att``, the state is augmented with the integral of the attitude error
``z_{k+1} = z_k + dt (psi_k - ref)`` (LQI), and the gain of ::

    A_a = [[A, 0], [dt C_att, I]],   B_a = [[B], [0]],
    Q_a = blkdiag(C^T Q_y C + eps I, Q_z),   R = r I

acts as ``u = -G_x (xhat - x_ref) - G_z z``, with ``x_ref`` the model's
zero-torque equilibrium at the reference attitude. The integral removes
the steady-state error a constant disturbance torque (or a wrong model
gain) would leave. It integrates only near the reference (every axis
within ``band``, 0.2 deg by default) and not while the torque saturates:
conditional integration, so a slew or an initial error of degrees does not
wind it up (an integral charged by a 2 deg initial error took minutes to
discharge: 25x the attitude error after 100 s).

:class:`LQGLaw` holds the weights, the Riccati solution
(:class:`controllers.riccati.RiccatiTracker`) and the integral state, so
the fixed, scheduled, oracle and adaptive designs differ only in the model
and the state estimate they feed it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.riccati import RiccatiTracker, check_iterations, check_weights
from spacecraft_conventions import NOMINAL_SCALE, CostWeights, output_cost_weights
from spacecraft_conventions.kept import KeptWhileEqual

__all__ = ["INTEGRAL_BAND", "INTEGRAL_SETTLE_S", "LQGLaw", "LQRWeights", "augment_integral",
           "check_settle_time", "equilibrium_map", "equilibrium_state", "output_weight",
           "set_integral_settle"]

#: Attitude error (rad) within which the integral runs: 0.2 deg.
INTEGRAL_BAND = np.deg2rad(0.2)

#: Time (s) every attitude error must have stayed within the band before the integral
#: runs, so the tail of a slew or of the warm-up's excitation does not charge it. 50 s
#: puts the oracle LQG at 0.60-0.65x its cost from 100 s with the integral at once on the
#: slews, 0.82-0.87x on regulation, and level under a constant disturbance on regulation
#: (``python benchmarks/bench_integral_rule.py``); 0 runs the integral at once.
INTEGRAL_SETTLE_S = 50.0


@dataclass(frozen=True)
class LQRWeights(CostWeights):
    """Output, integral and torque weights of the LQG designs.

    The common stage cost's weights (:class:`spacecraft_conventions.CostWeights`,
    whose defaults every design here shares, so each LQG minimizes the cost the
    env rewards and the harness reports) and the design-only integral weight:
    ``Q_y = diag(attitude / (1 deg)^2 [x3], rate / (0.1 deg/s)^2 [x3],
    deflection / (1 cm)^2 [per sensor])``, ``Q = C^T Q_y C + eps I``,
    ``Q_z = integral / (1 deg s)^2 I`` on the attitude-error integral and
    ``R = torque * I`` per (N m)^2. The defaults give a closed-loop attitude
    bandwidth of roughly 0.1 rad/s, below the first flexible mode
    (0.48 rad/s), and an integral time constant of about 50 s.

    Attributes
    ----------
    attitude, rate, deflection, torque : float
        The cost's weights (:class:`spacecraft_conventions.CostWeights`;
        defaults 1, 1, 0.1 and 0.3 per (N m)^2); ``torque`` must be > 0.
    integral : float
        Weight of the squared attitude-error integral in units of 1 deg s
        (default 4e-4).
    eps : float
        Added to the diagonal of ``Q`` so it is positive definite (default 1e-6).

    All must be finite and >= 0 (``torque`` > 0); ``ValueError`` otherwise.
    """

    integral: float = 4e-4
    eps: float = 1e-6

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.torque <= 0:
            raise ValueError("LQR torque weight must be positive (R positive definite)")


def output_weight(layout, weights: LQRWeights) -> np.ndarray:
    """Diagonal output weight ``Q_y`` for the sensor groups of ``layout``.

    Each channel's weight is its group's weight divided by the square of the
    group's nominal level (:meth:`OutputLayout.scales`).

    Parameters
    ----------
    layout : OutputLayout
        The output groups, in order; only its sensor groups (``"attitude"``,
        ``"rate"``, ``"deflection"``, via ``layout.sensors()``) are weighted.
    weights : LQRWeights
        The per-group weights (``attitude``, ``rate``, ``deflection``).

    Returns
    -------
    (m, m) ndarray
        Diagonal ``Q_y`` for the m sensor channels: per rad^2, per (rad/s)^2
        and per m^2 for the three groups.
    """
    return np.diag(output_cost_weights(layout, weights))


def equilibrium_state(a: np.ndarray, c_att: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Zero-input equilibrium with attitude ``reference``: ``(A - I) x = 0``, ``C_att x = ref``.

    Least-squares solution (exact for the rigid-body equilibria of the true
    model; the closest one for an identified model).

    Parameters
    ----------
    a : (n, n) ndarray
        Discrete-time state matrix.
    c_att : (3, n) ndarray
        Rows of the output matrix giving the attitude (rad).
    reference : (3,) ndarray
        Reference attitude, rad.

    Returns
    -------
    (n,) ndarray
        The state ``x`` (in the model's coordinates).
    """
    n = a.shape[0]
    lhs = np.vstack([a - np.eye(n), c_att])
    rhs = np.concatenate([np.zeros(n), reference])
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0]


def equilibrium_map(a: np.ndarray, c_att: np.ndarray) -> np.ndarray:
    """The linear map from reference attitude to :func:`equilibrium_state`.

    The least-squares solution is linear in the reference, so
    ``equilibrium_state(a, c_att, ref) == equilibrium_map(a, c_att) @ ref`` (to
    rounding): a controller whose model is kept over several steps pays for
    the solve once.

    Parameters
    ----------
    a : (n, n) ndarray
        Discrete-time state matrix.
    c_att : (k, n) ndarray
        Rows of the output matrix giving the attitude (rad).

    Returns
    -------
    (n, k) ndarray
        The equilibrium state per rad of reference attitude.
    """
    n, k = a.shape[0], c_att.shape[0]
    lhs = np.vstack([a - np.eye(n), c_att])
    rhs = np.vstack([np.zeros((n, k)), np.eye(k)])
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0]


def augment_integral(a: np.ndarray, b: np.ndarray, c_att: np.ndarray,
                     dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(A_a, B_a)`` of the model augmented with the attitude-error integral.

    Returns
    -------
    (A_a, B_a) : ((n + k, n + k), (n + k, m)) ndarrays
        The augmented state matrix and input matrix (k attitude outputs integrated).
    """
    n, k = a.shape[0], c_att.shape[0]
    a_aug = np.zeros((n + k, n + k))
    a_aug[:n, :n] = a
    a_aug[n:, :n] = dt * c_att
    a_aug[n:, n:] = np.eye(k)
    b_aug = np.vstack([b, np.zeros((k, b.shape[1]))])
    return a_aug, b_aug


class LQGLaw:
    """LQI state feedback re-designed on whatever model it is given.

    Parameters
    ----------
    qy : (m, m) ndarray
        Output weight (:func:`output_weight`) for the rows of ``C`` passed to
        :meth:`design`.
    weights : LQRWeights
    dt : float
        Sample time, s.
    integral : bool
        Augment with the attitude-error integral (default True).
    iterations : int or None
        None (default): each new model's Riccati equation solved exactly; an
        integer: that many warm-started iterations per re-design
        (:class:`controllers.riccati.RiccatiTracker`).
    band : float
        The integral runs only while every attitude error is within this, rad.
    settle_s : float
        ... and only once every attitude error has stayed within ``band`` for
        this long, s (0: at once), so the tail of a transient (a slew's
        settling, a warm-up's excitation) does not charge an integral meant
        for a constant disturbance.
    """

    def __init__(self, qy: np.ndarray, weights: LQRWeights, dt: float, *,
                 integral: bool = True, iterations: int | None = None,
                 band: float = INTEGRAL_BAND, settle_s: float = INTEGRAL_SETTLE_S) -> None:
        self.qy = np.asarray(qy, dtype=float)
        self.weights = weights
        self.r = weights.torque * np.eye(3)
        check_weights(self.qy, self.r)
        self.dt = float(dt)
        self.integral = bool(integral)
        self.iterations = check_iterations(iterations)
        if not (np.isfinite(band) and band > 0):
            raise ValueError(f"band must be a positive angle in rad, got {band}")
        self.band = float(band)
        self.settle_s = settle_s
        # (1 deg s)^-2 in rad: the integral state is in rad s
        self._qz = weights.integral / (NOMINAL_SCALE["attitude"] ** 2)
        self.tracker: RiccatiTracker | None = None
        self.gain: np.ndarray | None = None
        #: the equilibrium map of the model (A, C_att) last flown
        self._equilibrium: KeptWhileEqual[np.ndarray] = KeptWhileEqual()
        #: (Q_a, A_a, B_a) of the model (A, B, C, C_att) last designed on
        self._design_model: KeptWhileEqual[tuple[np.ndarray, ...]] = KeptWhileEqual()
        self.reset()

    @property
    def settle_s(self) -> float:
        """Seconds in the band before the integral runs (checked when set; >= 0)."""
        return self._settle_s

    @settle_s.setter
    def settle_s(self, value: float) -> None:
        self._settle_s = check_settle_time(value)
        # counted in steps (the current one included), so 500 steps of 0.1 s are 50 s
        # exactly, which a float sum is not
        self._settle_steps = math.ceil(self._settle_s / self.dt - 1e-9)

    def reset(self) -> None:
        """Zero the integral (start of an episode); keep the Riccati design."""
        self.z = np.zeros(3)
        self._in_band_steps = 0

    def restart_settle(self) -> None:
        """Start the settling clock again, the integral kept: it integrates again only
        once every attitude error has stayed ``settle_s`` in the band from now (after a
        sensor fault is compensated, the attitude's walk back is a transient, not a
        constant disturbance)."""
        self._in_band_steps = 0

    def weight_matrix(self, c: np.ndarray) -> np.ndarray:
        """``Q_a`` for a model with output matrix ``c``.

        Returns
        -------
        (n + 3, n + 3) or (n, n) ndarray
            The state weight of the augmented model (without the integral when it is
            off).
        """
        n = c.shape[1]
        q = c.T @ self.qy @ c + self.weights.eps * np.eye(n)
        if not self.integral:
            return q
        out = np.zeros((n + 3, n + 3))
        out[:n, :n] = q
        out[n:, n:] = self._qz * np.eye(3)
        return out

    def design(self, a: np.ndarray, b: np.ndarray, c: np.ndarray,
               c_att: np.ndarray) -> np.ndarray:
        """Gain ``[G_x, G_z]`` for the model (:class:`controllers.riccati.RiccatiTracker`).

        Returns
        -------
        (3, n + 3) or (3, n) ndarray
            The gain [G_x, G_z], N m per state unit (G_x alone without the integral).

        Raises
        ------
        ValueError
            If the Riccati equation has no stabilizing solution.
        """
        q, a, b = self._design_model.get((a, b, c, c_att), lambda: (
            self.weight_matrix(c),
            *(augment_integral(a, b, c_att, self.dt) if self.integral else (a, b))))
        if self.tracker is None or self.tracker.q.shape != q.shape:
            self.tracker = RiccatiTracker(q, self.r, self.iterations)
        else:
            self.tracker.q = q
        return self.tracker.design(a, b)

    def equilibrium(self, a: np.ndarray, c_att: np.ndarray, reference: np.ndarray
                    ) -> np.ndarray:
        """:func:`equilibrium_state` of the model, its map kept while the model is
        unchanged (:func:`equilibrium_map`).

        Returns
        -------
        (n,) ndarray
            The model's equilibrium state at the reference attitude.
        """
        return self._equilibrium.get((a, c_att), lambda: equilibrium_map(a, c_att)) @ reference

    def torque(self, gain: np.ndarray, x_hat: np.ndarray, x_ref: np.ndarray) -> np.ndarray:
        """``-G_x (xhat - x_ref) - G_z z``, N m.

        Returns
        -------
        (3,) ndarray
            The torque, N m, before saturation.
        """
        n = x_hat.shape[0]
        u = -gain[:, :n] @ (x_hat - x_ref)
        if self.integral:
            u = u - gain[:, n:] @ self.z
        return u

    def integrate(self, attitude_error: np.ndarray, saturated: bool) -> None:
        """Advance the integral by ``dt * error`` if near the reference (for
        ``settle_s`` already, this step included) and not saturated; a held call
        (``saturated``) still counts the time in the band."""
        near = bool(np.isfinite(attitude_error).all()
                    and np.abs(attitude_error).max() < self.band)
        self._in_band_steps = self._in_band_steps + 1 if near else 0
        if (self.integral and not saturated and near
                and self._in_band_steps >= self._settle_steps):
            self.z = self.z + self.dt * attitude_error


def set_integral_settle(controller: Any, settle_s: float) -> Any:
    """Make every :class:`LQGLaw` of ``controller`` wait ``settle_s`` before integrating.

    The laws reached are the controller's own (``controller.law``) and its
    fallback's (``controller.fallback.law``, the adaptive LQG's robust design),
    so the two never disagree. Used to fly a design as it was flown before the
    default changed: a residual agent keeps the base it was trained on.

    Parameters
    ----------
    controller : Controller
        Any controller; one without an ``LQGLaw`` is returned unchanged.
    settle_s : float
        Seconds in the band before the integral runs (0: at once), >= 0.

    Returns
    -------
    Controller
        ``controller`` itself.

    Raises
    ------
    ValueError
        If ``settle_s`` is negative or not finite.
    """
    settle_s = check_settle_time(settle_s)
    for part in (controller, getattr(controller, "fallback", None)):
        law = getattr(part, "law", None)
        if isinstance(law, LQGLaw):
            law.settle_s = settle_s
    return controller


def check_settle_time(settle_s: float) -> float:
    """``settle_s`` as a float, s.

    Returns
    -------
    float
        The settle time, s.

    Raises
    ------
    ValueError
        If it is negative or not finite (the message names ``settle_s``).
    """
    if not (np.isfinite(settle_s) and settle_s >= 0):
        raise ValueError(f"settle_s must be a finite time >= 0 s, got {settle_s}")
    return float(settle_s)
