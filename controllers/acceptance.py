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
   ``max_prediction_error`` (default 2): a guard against a model that has
   lost track of the data (diverged, or modes rebuilt wrongly), not a
   demand that it predict better than persistence. In the quiet closed loop
   even the true model scores only 0.34-0.45 on this measure, the nominal
   rigid model about 0.55, and identified models whose gains fly better
   than the robust design's about 1.1-1.3 (docs/results/control.md): a
   threshold below 1 rejected every identified gain.
4. **Margins at the plant input, against the model's uncertainty**
   (:meth:`GainAcceptance.check_margin`): the disk margin
   :func:`input_disk_margin` of the output-feedback loop (the gain on the
   model's Kalman predictor, with the integral) must be at least
   ``min_disk_margin``, and the loop must tolerate the identifier's
   calibrated 2-sigma uncertainty of the rigid-body gain: covered by the
   disk margin, or the loop shown stable for real input gains across the
   band (:func:`stable_under_input_gains`). LQR's state-feedback margins do
   not survive a state estimator (Doyle 1978); this is the check that they
   did, for every plant the identified model does not rule out.

A rejected gain is not flown; the caller falls back to the reference design.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from controllers.lqg import augment_integral, equilibrium_map
from controllers.riccati import spectral_radius
from spacecraft_conventions.kept import KeptWhileEqual

__all__ = ["REJECTION_REASONS", "GainAcceptance", "effective_gains", "input_disk_margin",
           "margin_frequencies", "stable_under_input_gains", "unit_states"]

#: Every reason :meth:`GainAcceptance.check` and :meth:`GainAcceptance.check_margin`
#: return for a gain that may not fly, in the order the tests run.
REJECTION_REASONS = ("non-finite gain", "prediction", "stiffness", "damping", "unstable",
                     "margin", "uncertain")

#: Frequencies (rad/s) the margin is evaluated at, before the model's own.
MARGIN_GRID_POINTS = 48


def margin_frequencies(dt: float, n_points: int = MARGIN_GRID_POINTS,
                       low: float = 1e-3) -> np.ndarray:
    """Log-spaced frequencies (rad/s) from ``low`` to just below Nyquist ``pi / dt``.

    Returns
    -------
    (n_points,) ndarray
        The frequencies, rad/s, increasing.
    """
    return np.geomspace(low, 0.999 * np.pi / dt, n_points)


def input_disk_margin(a: np.ndarray, b: np.ndarray, c: np.ndarray, k: np.ndarray,
                      gain: np.ndarray, att_rows: np.ndarray, dt: float,
                      frequencies: np.ndarray | None = None) -> float:
    """Symmetric disk margin at the plant input of an observer-based LQG loop.

    The loop: plant ``x+ = A x + B u``, ``y = C x``, with the attitude
    integral ``z+ = z + dt C_att x`` when ``gain`` has the integral columns;
    compensator ``xhat+ = A xhat + B u + K (y - C xhat)`` (the model's
    Kalman predictor), ``u = -G_x xhat - G_z z``. Broken at the torque
    input, its loop transfer is ``L(z) = C_k(z) P(z)`` and the margin is ::

        alpha = min over w of sigma_min(I + L(e^{j w dt}))

    the distance of the return difference from singularity: the loop
    tolerates any simultaneous gain change within ``[1 / (1 + alpha),
    1 / (1 - alpha)]`` and phase change up to ``2 asin(alpha / 2)`` on all
    input channels at once. 1 is what continuous LQR guarantees; 0 means
    the loop is at the edge of instability.

    Parameters
    ----------
    a, b, c, k : ndarray
        Model ``(n, n)``, ``(n, 3)``, ``(m, n)`` and its predictor gain
        ``(n, m)``, physical units.
    gain : (3, n) or (3, n + 3) ndarray
        ``[G_x]`` or ``[G_x, G_z]``.
    att_rows : ndarray of int
        Rows of ``c`` that measure attitude.
    dt : float
        Sample time, s.
    frequencies : ndarray, optional
        Frequencies (rad/s) to evaluate at; default :func:`margin_frequencies`
        plus the angles of the model's oscillatory poles (where lightly
        damped modes put narrow features a log grid would step over).

    Returns
    -------
    float
        ``alpha`` (0 where ``I + L`` is singular or not finite).
    """
    n, r = b.shape
    m = c.shape[0]
    g_x = gain[:, :n]
    if frequencies is None:
        z_poles = np.linalg.eigvals(a)
        angles = np.abs(np.angle(z_poles[np.abs(z_poles.imag) > 1e-9])) / dt
        frequencies = np.concatenate([margin_frequencies(dt), angles])
    w = np.asarray(frequencies, dtype=float)
    zs = np.exp(1j * w * dt)[:, None, None]
    # plant with the integral: u -> (y, z)
    if gain.shape[1] > n:
        a_p, b_p = augment_integral(a, b, c[att_rows], dt)
        n_int = gain.shape[1] - n
        c_p = np.zeros((m + n_int, n + n_int))
        c_p[:m, :n] = c
        c_p[m:, n:] = np.eye(n_int)
        g_z = gain[:, n:]
    else:
        a_p, b_p, c_p, n_int, g_z = a, b, c, 0, np.zeros((r, 0))
    a_c = a - k @ c - b @ g_x          # compensator: (y, z) -> -u
    b_c = np.hstack([k, -b @ g_z])
    try:
        plant = c_p @ _resolvent_times(zs, a_p, b_p)
        comp = g_x @ _resolvent_times(zs, a_c, b_c)
    except np.linalg.LinAlgError:
        # a pole exactly on the unit circle at one of the frequencies: |L| is
        # infinite there, far from the minimum; leave those frequencies out
        keep = [i for i in range(w.size)
                if np.linalg.cond(zs[i] * np.eye(a_p.shape[0]) - a_p) < 1e12
                and np.linalg.cond(zs[i] * np.eye(n) - a_c) < 1e12]
        if not keep:
            return 0.0
        zs = zs[keep]
        plant = c_p @ _resolvent_times(zs, a_p, b_p)
        comp = g_x @ _resolvent_times(zs, a_c, b_c)
    if n_int:
        comp[:, :, m:] += g_z
    ret = np.eye(r) + comp @ plant
    if not np.isfinite(ret).all():
        return 0.0
    return float(np.linalg.svd(ret, compute_uv=False)[:, -1].min())


def stable_under_input_gains(a: np.ndarray, b: np.ndarray, c: np.ndarray, k: np.ndarray,
                             gain: np.ndarray, att_rows: np.ndarray, dt: float,
                             gains: np.ndarray) -> bool:
    """Whether the loop of :func:`input_disk_margin` is stable with its input scaled.

    The plant ``(A, s B, C)`` (and the attitude integral) under the compensator
    designed on ``(A, B, C)``: ``xhat+ = A xhat + B u + K (y - C xhat)``,
    ``u = -G_x xhat - G_z z``, for every real scale ``s`` of ``gains``. A real,
    common change of the torque's gain (an actuator's efficiency, a rigid-body
    gain off in size) is what an identifier's uncertainty of the rigid-body gain
    describes; the disk margin covers any change of gain and phase, on every
    channel at once, and asks more.

    Parameters
    ----------
    a, b, c, k, gain, att_rows, dt
        As :func:`input_disk_margin`.
    gains : (q,) array_like
        Input scales ``s`` (1: the model itself).

    Returns
    -------
    bool
        True if the closed loop's spectral radius is below 1 at every scale.
    """
    n, r = b.shape
    g_x = gain[:, :n]
    if gain.shape[1] > n:
        a_p, b_p = augment_integral(a, b, c[att_rows], dt)
        f_p = np.hstack([np.zeros((r, n)), gain[:, n:]])
    else:
        a_p, b_p, f_p = a, b, np.zeros((r, n))
    kc = k @ c
    lower = np.hstack([np.hstack([kc, np.zeros((n, a_p.shape[0] - n))]) - b @ f_p,
                       a - kc - b @ g_x])
    bf, bg = b_p @ f_p, b_p @ g_x            # the plant's input terms, scaled below
    for scale in np.asarray(gains, dtype=float).ravel():
        upper = np.hstack([a_p - scale * bf, -scale * bg])
        loop = np.vstack([upper, lower])
        if not np.isfinite(loop).all() or spectral_radius(loop) >= 1.0:
            return False
    return True


def _resolvent_times(zs: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(z I - A)^-1 B`` for every ``z`` of ``zs`` (shape ``(F, 1, 1)``): ``(F, n, r)``."""
    return np.linalg.solve(zs * np.eye(a.shape[0]) - a, np.broadcast_to(b, (zs.shape[0], *b.shape)))


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
    x_p, x_d = unit_states(a, c, att_rows, rate_rows)
    return gain_x @ x_p, gain_x @ x_d


def unit_states(a: np.ndarray, c: np.ndarray, att_rows: np.ndarray,
                rate_rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The model states of a unit attitude at rest and of a unit rate, per axis.

    Returns
    -------
    X_p, X_d : (n, 3) ndarray
        Column j of ``X_p``: the zero-input equilibrium with attitude ``e_j``
        (least squares, :func:`controllers.lqg.equilibrium_state`); of
        ``X_d``: the least-norm state with rate ``e_j``, zero attitude and
        zero other outputs. They depend on the model only, not on a gain.
    """
    n = a.shape[0]
    if not n:
        return np.zeros((0, 3)), np.zeros((0, 3))
    eye = np.eye(3)
    x_p = equilibrium_map(a, c[att_rows])
    rows = np.concatenate([att_rows, rate_rows])
    others = np.setdiff1d(np.arange(c.shape[0]), rows)
    lhs_d = np.vstack([c[rows], c[others]])
    rhs_d = np.vstack([np.zeros((3, 3)), eye, np.zeros((others.size, 3))])
    x_d = np.linalg.lstsq(lhs_d, rhs_d, rcond=None)[0]
    return x_p, x_d


def _softest(matrix: np.ndarray) -> float:
    """Smallest eigenvalue of the symmetric part of a square matrix."""
    return float(_smallest_symmetric_eigenvalue(np.ascontiguousarray(matrix, dtype=float)))


@njit(cache=True, nogil=True)
def _smallest_symmetric_eigenvalue(matrix: np.ndarray) -> float:
    """Compiled: numpy's per-call overhead is most of the cost at 3 x 3."""
    return np.linalg.eigvalsh(0.5 * (matrix + matrix.T)).min()


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
    min_disk_margin : float
        Smallest disk margin at the plant input (:func:`input_disk_margin`;
        0.4: gain within [0.71, 1.67] and phase within 23 deg on all axes at
        once).
    """

    floor: float = 0.3
    max_prediction_error: float = 2.0
    min_disk_margin: float = 0.4

    def __post_init__(self) -> None:
        if not 0 <= self.floor:
            raise ValueError(f"floor must be >= 0, got {self.floor}")
        if not self.max_prediction_error > 0:
            raise ValueError(f"max_prediction_error must be > 0, got {self.max_prediction_error}")
        if not 0 <= self.min_disk_margin < 1:
            raise ValueError(f"min_disk_margin must be in [0, 1), got {self.min_disk_margin}")
        #: (X_p, X_d, A_a, B_a) of the model last judged
        self._per_model: KeptWhileEqual[tuple[np.ndarray, ...]] = KeptWhileEqual()
        #: the reason (None: passed) of the gain and model last judged
        self._verdict: KeptWhileEqual[str | None] = KeptWhileEqual()

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

        The margin test (4.) is :meth:`check_margin`: the caller evaluates
        the margin, which costs more than the rest, only for a gain that
        passes these.

        Returns
        -------
        str or None
            None when the gain passes; else the first test it fails: "stiffness",
            "damping", "unstable" or "prediction".
        """
        if not np.isfinite(gain).all():
            return "non-finite gain"
        if not np.isfinite(prediction_error) or prediction_error > self.max_prediction_error:
            return "prediction"
        # the tests below depend on the model and the gain alone: a design handed back
        # unchanged for an unchanged model (RiccatiTracker) keeps its verdict
        return self._verdict.get(
            (gain, a, b, c, att_rows, rate_rows, reference, dt),
            lambda: self._design_check(a, b, c, gain, att_rows, rate_rows, reference, dt))

    def _design_check(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, gain: np.ndarray,
                      att_rows: np.ndarray, rate_rows: np.ndarray,
                      reference: tuple[float, float], dt: float) -> str | None:
        """Tests 1.-3. of :meth:`check` (stiffness, damping, stability)."""
        n = a.shape[0]
        integral = gain.shape[1] > n
        # the unit states and the augmented model depend on the model alone: a model
        # kept over several steps (an identifier exports every few samples) pays once
        x_p, x_d, a_cl, b_cl = self._per_model.get(
            (a, b, c, att_rows, rate_rows, integral, dt),
            lambda: (*unit_states(a, c, att_rows, rate_rows),
                     *(augment_integral(a, b, c[att_rows], dt) if integral else (a, b))))
        k_p, k_d = gain[:, :n] @ x_p, gain[:, :n] @ x_d
        if _softest(k_p) < self.floor * reference[0]:
            return "stiffness"
        if _softest(k_d) < self.floor * reference[1]:
            return "damping"
        if spectral_radius(a_cl - b_cl @ gain) >= 1.0:
            return "unstable"
        return None

    def check_margin(self, disk_margin: float, gain_uncertainty: float = 0.0,
                     stable_over: float = 0.0) -> str | None:
        """None if the loop's margins pass, else the reason.

        The disk margin (:func:`input_disk_margin`) must be at least
        ``min_disk_margin`` ("margin"). The loop must also tolerate the model's
        torque-gain uncertainty, a relative 2-sigma spread ``e = 2
        gain_uncertainty`` of the rigid-body gain ("uncertain"; any ``e >= 1``
        fails): either the disk margin covers it (``alpha`` tolerates any gain
        within ``[1 / (1 + alpha), 1 / (1 - alpha)]`` with any phase, so
        ``alpha >= e / (1 - e)``), or the loop was shown stable for real input
        gains ``1 -/+ e`` (``stable_over >= e``, the largest spread the caller
        checked with :func:`stable_under_input_gains`).

        Returns
        -------
        str or None
            None when the margins pass; else "margin" or "uncertain".
        """
        if not np.isfinite(disk_margin) or disk_margin < self.min_disk_margin:
            return "margin"
        spread = 2.0 * float(gain_uncertainty)
        if not np.isfinite(spread) or spread >= 1.0:
            return "uncertain"
        if disk_margin < spread / (1.0 - spread) and not stable_over >= spread:
            return "uncertain"
        return None

    @staticmethod
    def softest(a: np.ndarray, c: np.ndarray, gain_x: np.ndarray, att_rows: np.ndarray,
                rate_rows: np.ndarray) -> tuple[float, float]:
        """Softest effective stiffness and damping of a design (the reference).

        Returns
        -------
        (float, float)
            The smallest effective stiffness (N m/rad) and damping (N m s/rad) over the
            three axes.
        """
        k_p, k_d = effective_gains(a, c, gain_x, att_rows, rate_rows)
        return _softest(k_p), _softest(k_d)
