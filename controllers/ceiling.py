"""The ceiling of the common cost: the clairvoyant LQG optimum on the true plant.

Every LQG here minimizes the common quadratic cost
(:mod:`spacecraft_conventions.cost`); its ceiling is the controller that
minimizes the same cost knowing everything a controller could know without
reading the future noise (docs/design/evaluation.md):

* the true time-varying plant over the whole episode, schedule included (the
  docking times, the paddle drive's angle, a module's captured momentum, the
  family's drawn plant and actuator efficiency, the env's constant disturbance
  torque and actuator delay);
* the true noise statistics: the sensors' noise at the env's SNR and, as
  process noise, the white disturbance torque the env actually applies (none
  by default);
* the initial state's distribution: the task's (regulation: each attitude angle
  uniform in +-``initial_attitude_deg``, so a prior of variance ``a^2 / 3`` on it;
  slew: at rest at zero), every rate and modal coordinate at rest. An episode
  whose ``reset`` options override the initial state is not what it plans for.

For that knowledge the optimum of the expected cost of the linear-Gaussian
plant is certainty equivalence: the finite-horizon time-varying Riccati
recursion over the episode's ``(A_k, B_k)`` (backward, once per episode:
:func:`finite_horizon_lqr`) acting on the time-varying Kalman filter's
``x_{k|k}`` (forward). No controller that sees only the measurements can
expect less cost on the linear plant. What the plan leaves out: the torque
limit (the ceiling saturates like every controller; on a saturating slew a
policy that plans the saturation could do better), the actuator's rate limit
(``torque_rate_limit``; unmodelled, so with it the ceiling is no bound), and
the small-angle model's range (the env is linear, so nothing else).

:class:`ClairvoyantLQG` with ``start`` flies another controller first (the
adaptive loop's warm-up: its PD and excitation, :func:`adaptive_start`) and
the clairvoyant law from ``start_steps`` on, its filter running throughout:
:func:`same_start_ceiling`, the optimum of the cost from the start's end among the
controllers that fly that start, so an adaptive loop's ratio to it over that
window is the price of identification alone. It bounds that window only: a later
window it does not bound, since its plan trades the whole remaining episode.

With ``window_start_steps`` the plan minimizes the cost of a window instead: the
state is free before it and the torque nearly so (:data:`WINDOW_TORQUE_WEIGHT`),
so it spends the steps before the window bringing the plant to rest; flown from
t = 0 it bounds every controller's cost over that window (:func:`window_ceiling`,
the bound of the stationary window from 100 s; docs/design/evaluation.md).
"""

from __future__ import annotations

import warnings
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike

from controllers.base import Controller
from controllers.baselines import PD, RobustLQG, _EnvController, _LQGController
from controllers.excitation import BinaryExcitation, MotionNeed, warmup_excitation
from controllers.harness import SCORED_FROM_S
from controllers.loop_identifiers import closed_loop_identifier
from controllers.lqg import LQRWeights
from identifiers import KalmanPredictor
from spacecraft_conventions import output_cost_weights, single_threaded_blas

__all__ = ["NOISE_FLOOR", "WINDOW_TORQUE_WEIGHT", "ClairvoyantLQG", "ExcitedStart",
           "adaptive_start", "finite_horizon_lqr", "same_start_ceiling", "window_ceiling"]

#: Smallest sensor noise the ceiling's filter assumes, as a fraction of each channel's
#: nominal level: the observations are float32 (a relative resolution of 6e-8 at ten
#: nominal levels), so a noise-free sensor is still read to about this.
NOISE_FLOOR = 1e-7

#: The torque's weight before a window, relative to the common cost's, in the plan
#: that minimizes that window's cost: the limit of a free torque (from 1e-4 to 1e-6
#: the window ceiling's cost from 100 s changes by under 1.5 % on paddle rotation and
#: docking) that keeps the Riccati recursion well conditioned.
WINDOW_TORQUE_WEIGHT = 1e-4


def finite_horizon_lqr(a: ArrayLike, b: ArrayLike, c: ArrayLike, q: ArrayLike,
                       q_lin: ArrayLike, r: ArrayLike, stage_weights: ArrayLike | None = None,
                       input_weights: ArrayLike | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """The finite-horizon LQ optimum of an affine time-varying system, by backward Riccati.

    Minimizes ``sum_{k=0}^{N-1} w_k (x_{k+1}^T Q x_{k+1} - 2 q_lin^T x_{k+1})
    + v_k u_k^T R u_k`` subject to ``x_{k+1} = A_k x_k + B_k u_k + c_k``: the stage
    cost charges the state each step produces, as the env's reward does (``w_k = v_k
    = 1`` by default; a window's cost: ``w_k = 0`` before it). With
    ``S = w_k Q + P_{k+1}``, ``s = w_k q_lin + p_{k+1}`` and ``H = v_k R + B_k^T S B_k``::

        K_k = H^-1 B_k^T S A_k,   f_k = H^-1 B_k^T (s - S c_k),   u_k = -K_k x_k + f_k
        M = S - S B_k H^-1 B_k^T S,   m = s - S B_k H^-1 B_k^T s
        P_k = A_k^T M A_k,   p_k = A_k^T (m - M c_k)

    from ``P_N = 0``, ``p_N = 0``; the optimal cost from ``x_0`` is
    ``x_0^T P_0 x_0 - 2 p_0^T x_0 + kappa_0`` (the constant part of the stage cost,
    e.g. ``r^T W r`` for a reference ``r``, left out).

    Parameters
    ----------
    a : (N, n, n) array_like
        Transition matrices ``A_k``.
    b : (N, n, m) array_like
        Input matrices ``B_k``.
    c : (N, n) array_like
        Known drift ``c_k`` (a constant disturbance, a captured momentum).
    q : (n, n) array_like
        State weight, symmetric positive semi-definite.
    q_lin : (n,) array_like
        Linear weight (``C^T W r`` for an output reference ``r``).
    r : (m, m) array_like
        Input weight, symmetric positive definite.
    stage_weights : (N,) array_like, optional
        ``w_k >= 0``, the share of the state's stage cost counted at step ``k``
        (default all 1).
    input_weights : (N,) array_like, optional
        ``v_k > 0``, the same for the input's (default all 1).

    Returns
    -------
    gains : (N, m, n) ndarray
        ``K_k``.
    offsets : (N, m) ndarray
        ``f_k``.
    p0 : (n, n) ndarray
        ``P_0``.
    p0_lin : (n,) ndarray
        ``p_0``.
    kappa0 : float
        ``kappa_0``, the cost-to-go's constant from the drift (0 without one).

    Raises
    ------
    ValueError
        On inconsistent shapes or non-finite entries.

    Examples
    --------
    One step of a scalar integrator ``x+ = x + u`` with ``Q = R = 1``: the optimum
    ``u = -x / 2`` costs ``x0^2 / 2``.

    >>> import numpy as np
    >>> k, f, p, _, _ = finite_horizon_lqr(np.ones((1, 1, 1)), np.ones((1, 1, 1)),
    ...                                    np.zeros((1, 1)), np.eye(1), np.zeros(1), np.eye(1))
    >>> float(k[0, 0, 0]), float(p[0, 0])
    (0.5, 0.5)
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c = np.asarray(c, dtype=float)
    q = np.asarray(q, dtype=float)
    q_lin = np.asarray(q_lin, dtype=float)
    r = np.asarray(r, dtype=float)
    if a.ndim != 3 or a.shape[1] != a.shape[2]:
        raise ValueError(f"a must have shape (N, n, n), got {a.shape}")
    horizon, n = a.shape[:2]
    if b.ndim != 3 or b.shape[:2] != (horizon, n):
        raise ValueError(f"b must have shape ({horizon}, {n}, m), got {b.shape}")
    m = b.shape[2]
    if c.shape != (horizon, n) or q.shape != (n, n) or q_lin.shape != (n,) \
            or r.shape != (m, m):
        raise ValueError(f"c must be ({horizon}, {n}), q ({n}, {n}), q_lin ({n},) and r "
                         f"({m}, {m}); got {c.shape}, {q.shape}, {q_lin.shape}, {r.shape}")
    if not all(np.isfinite(x).all() for x in (a, b, c, q, q_lin, r)):
        raise ValueError("finite_horizon_lqr needs finite matrices")
    w = _stage_scale(stage_weights, horizon, "stage_weights", positive=False)
    v = _stage_scale(input_weights, horizon, "input_weights", positive=True)
    gains = np.empty((horizon, m, n))
    offsets = np.empty((horizon, m))
    p, p_lin, kappa = np.zeros((n, n)), np.zeros(n), 0.0
    for k in range(horizon - 1, -1, -1):
        ak, bk, ck = a[k], b[k], c[k]
        s = w[k] * q + p
        s_lin = w[k] * q_lin + p_lin
        sb = s @ bk
        h = v[k] * r + bk.T @ sb
        # one factorization for the gain, the offset and the value's update
        solved = np.linalg.solve(h, np.hstack([sb.T, (bk.T @ (s_lin - s @ ck))[:, None]]))
        hbs, f = solved[:, :n], solved[:, n]                # H^-1 B^T S, f_k
        gains[k] = hbs @ ak
        offsets[k] = f
        mm = s - sb @ hbs
        mm = 0.5 * (mm + mm.T)
        m_lin = s_lin - hbs.T @ (bk.T @ s_lin)
        g0 = bk.T @ (s @ ck - s_lin)
        kappa += float(ck @ s @ ck - 2.0 * s_lin @ ck + g0 @ f)
        p = ak.T @ mm @ ak
        p = 0.5 * (p + p.T)
        p_lin = ak.T @ (m_lin - mm @ ck)
    return gains, offsets, p, p_lin, kappa


def _stage_scale(values: ArrayLike | None, horizon: int, name: str, *,
                 positive: bool) -> np.ndarray:
    """Per-step weights of :func:`finite_horizon_lqr`, validated (all 1 when None)."""
    if values is None:
        return np.ones(horizon)
    values = np.asarray(values, dtype=float)
    bound = "> 0" if positive else ">= 0"
    low = values <= 0 if positive else values < 0
    if values.shape != (horizon,) or not np.isfinite(values).all() or low.any():
        raise ValueError(f"{name} must be ({horizon},) finite values {bound}, got shape "
                         f"{values.shape}")
    return values


class ExcitedStart(Controller):
    """A controller plus a designed excitation: the start of an adaptive loop.

    Its torque is the controller's (saturated, as it sends it) plus the
    excitation's, saturated again: what :class:`controllers.AdaptiveLQG`
    applies while its identifier warms up. With ``need`` and ``idle``, until
    ``need`` has seen motion the ``idle`` controller flies without excitation
    (the adaptive loop's robust fallback at rest); both controllers act every
    step, so each keeps its filter current, and ``idle`` is told the torque
    applied.

    Parameters
    ----------
    controller : Controller
        Flies the start (the adaptive loop's ``warmup_controller``).
    excitation : BinaryExcitation
        Added to it (reset with the episode's seed).
    max_torque : float
        Torque of a unit action, N m (the env's ``max_torque``).
    need : MotionNeed, optional
        Whether there is motion to identify (default: always).
    idle : Controller, optional
        Flies while ``need`` has seen none (required with ``need``).
    """

    name = "excited start"

    def __init__(self, controller: Controller, excitation: BinaryExcitation,
                 max_torque: float, need: MotionNeed | None = None,
                 idle: Controller | None = None) -> None:
        if (need is None) != (idle is None):
            raise ValueError("ExcitedStart takes need and idle together (or neither)")
        self.controller = controller
        self.excitation = excitation
        self.max_torque = float(max_torque)
        self.need = need
        self.idle = idle
        self.last_excitation = np.zeros(3)

    def reset(self, seed: int | None = None) -> None:
        self.controller.reset(seed)
        self.excitation.reset(seed)
        if self.need is not None:
            self.need.reset()
            self.idle.reset(seed)
        self.last_excitation = np.zeros(3)

    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        needed = True
        if self.need is not None:
            idle_action = np.asarray(self.idle.act(obs, info), dtype=float)
            reference = self.idle._reference(info) if hasattr(self.idle, "_reference") \
                else np.asarray((info or {}).get("reference", np.zeros(3)), dtype=float)
            needed = self.need(obs, reference)
        action = np.asarray(self.controller.act(obs, info), dtype=float)
        if not needed:
            action = idle_action
        self.last_excitation = self.excitation(needed)
        torque = action * self.max_torque + self.last_excitation
        applied = np.minimum(np.maximum(torque / self.max_torque, -1.0), 1.0).astype(np.float32)
        if isinstance(self.idle, _LQGController):
            self.idle.applied_action = applied
        return applied


def adaptive_start(env: gym.Env) -> tuple[ExcitedStart, int]:
    """The start :class:`controllers.AdaptiveLQG` flies by default, and its length.

    The loop's warm-up PD with the binary excitation of its identifier's warm-up
    (:func:`controllers.closed_loop_identifier`'s ``warmup_amplitude`` N m per axis
    for its ``warmup`` samples, then none), seeded as the loop seeds it, or, until
    the sensors show motion beyond their noise (:class:`MotionNeed`), its robust
    fallback without excitation, until the identifier's first model can fly: the
    warm-up plus the first fit's latency (:data:`controllers.LOOP_FIT_TIMING`; 40 s on
    the registered ids).

    Parameters
    ----------
    env : gymnasium.Env
        The environment (wrappers allowed).

    Returns
    -------
    start : ExcitedStart
        PD plus the excitation, as the loop applies them.
    steps : int
        Steps the loop flies it at least (its first model's sample).
    """
    identifier = closed_loop_identifier(env)
    excitation = warmup_excitation(identifier)
    timing = getattr(identifier, "fit_timing", None)
    latency = 0 if timing is None else timing.latency_samples(float(env.unwrapped.model.dt))
    return (ExcitedStart(PD(env), excitation, float(env.unwrapped.max_torque),
                         need=MotionNeed(env), idle=RobustLQG(env)),
            excitation.warmup_steps + latency)


def same_start_ceiling(env: gym.Env, weights: LQRWeights | None = None) -> ClairvoyantLQG:
    """The ceiling flown behind the adaptive loop's start (:func:`adaptive_start`): the
    optimum of the cost from the start's end among controllers that fly that start.

    Parameters
    ----------
    env : gymnasium.Env
    weights : LQRWeights, optional

    Returns
    -------
    ClairvoyantLQG
        Named "same-start ceiling".
    """
    start, steps = adaptive_start(env)
    return ClairvoyantLQG(env, weights, start=start, start_steps=steps)


def window_ceiling(env: gym.Env, from_s: float = SCORED_FROM_S,
                   weights: LQRWeights | None = None) -> ClairvoyantLQG:
    """The ceiling of the cost from ``from_s`` on: the clairvoyant plan of that window's
    cost, flown from t = 0, a bound on every controller's cost over the window.

    Parameters
    ----------
    env : gymnasium.Env
    from_s : float
        The window's start, s (default 100 s:
        :data:`controllers.harness.SCORED_FROM_S`, the stationary window); >= 0.
    weights : LQRWeights, optional

    Returns
    -------
    ClairvoyantLQG
        Named "window ceiling".
    """
    if not np.isfinite(from_s) or from_s < 0:
        raise ValueError(f"from_s must be a finite time >= 0 in s, got {from_s!r}")
    # the harness stamps the step from k with its end, (k + 1) dt: the window's first step
    # is the one that ends at from_s
    steps = max(round(float(from_s) / float(env.unwrapped.model.dt)) - 1, 0)
    return ClairvoyantLQG(env, weights, window_start_steps=steps)


class ClairvoyantLQG(_EnvController):
    """The ceiling of the common cost: finite-horizon LQG on the true time-varying plant.

    See the module's text for what it knows. At the first step of each episode it
    starts its filter on the task's prior of the initial state and plans the
    whole episode (:func:`finite_horizon_lqr` over ``horizon_steps`` steps of the
    true ``(A_k, B_k)``, about 0.2-0.5 s); every step it runs the time-varying
    Kalman filter on the true plant with the true noise statistics and applies
    ``u_k = -K_k x_{k|k} + f_k``, saturated. Without process noise its filter's
    covariance only shrinks: knowing the model and its own torques, it needs the
    sensors only to learn the initial state. It reads ``info["time"]``,
    ``info["torque"]`` and ``info["reference"]`` every step: an oracle.

    Parameters
    ----------
    env : gymnasium.Env
        The environment it flies (wrappers allowed; its ``unwrapped`` truth
        model, noise, disturbance and actuator settings are read).
    weights : LQRWeights, optional
        The cost's weights (default: the common cost's; the integral and
        ``eps`` weights are not used: the plan needs no integral).
    horizon_steps : int, optional
        Steps of the plan: the episode's length. Default the env's
        ``spec.max_episode_steps`` (2500 for the registered ids). An episode
        that runs longer is planned again from where the plan ends.
    start : Controller, optional
        Flies the first ``start_steps`` steps instead (e.g. :func:`adaptive_start`'s;
        :func:`same_start_ceiling`). Its excitation, if it has one
        (``last_excitation``), is reported as this controller's.
    start_steps : int
        Steps ``start`` flies (default 0).
    window_start_steps : int
        The first step whose cost the plan counts (default 0: the whole episode); the
        step from ``k`` to ``k + 1`` is the harness's at time ``(k + 1) dt``.
        Before it the state's cost is zero and the torque's
        :data:`WINDOW_TORQUE_WEIGHT` times the common one: :func:`window_ceiling`.

    Examples
    --------
    >>> import gymnasium as gym
    >>> from controllers import ClairvoyantLQG, OracleLQG, run_episode, stage_costs
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraft-v2", max_episode_steps=300)
    >>> ceiling = run_episode(env, ClairvoyantLQG(env), seed=0)
    >>> oracle = run_episode(env, OracleLQG(env), seed=0)
    >>> model = env.unwrapped.model
    >>> bool(stage_costs(ceiling, model)[:, :4].sum() < stage_costs(oracle, model)[:, :4].sum())
    True
    >>> env.close()
    """

    name = "ceiling"

    def __init__(self, env: gym.Env, weights: LQRWeights | None = None, *,
                 horizon_steps: int | None = None, start: Controller | None = None,
                 start_steps: int = 0, window_start_steps: int = 0) -> None:
        spec = getattr(env, "spec", None)
        super().__init__(env)
        self.weights = weights or LQRWeights()
        if horizon_steps is None:           # the registered ids' 2500 without a spec
            horizon_steps = (spec.max_episode_steps if spec is not None
                             and spec.max_episode_steps else 2500)
        if isinstance(horizon_steps, bool) or not isinstance(horizon_steps, int | np.integer) \
                or horizon_steps < 1:
            raise ValueError(f"horizon_steps must be an integer >= 1, got {horizon_steps!r}")
        self.horizon_steps = int(horizon_steps)
        if isinstance(start_steps, bool) or not isinstance(start_steps, int | np.integer) \
                or start_steps < 0:
            raise ValueError(f"start_steps must be an integer >= 0, got {start_steps!r}")
        if isinstance(window_start_steps, bool) \
                or not isinstance(window_start_steps, int | np.integer) or window_start_steps < 0:
            raise ValueError(f"window_start_steps must be an integer >= 0, got "
                             f"{window_start_steps!r}")
        self.window_start_steps = int(window_start_steps)
        if start is not None and not callable(getattr(start, "act", None)):
            raise TypeError(f"start must be a controller with act(obs, info), got "
                            f"{type(start).__name__}")
        self.start = start
        self.start_steps = int(start_steps) if start is not None else 0
        if start is not None:
            self.name = "same-start ceiling"
        elif self.window_start_steps:
            self.name = "window ceiling"
        if self.env.torque_rate_limit is not None:
            warnings.warn("ClairvoyantLQG does not model the actuators' rate limit "
                          "(torque_rate_limit): with it the ceiling is no bound", stacklevel=2)
        self.reset()

    # ------------------------------------------------------------ the plan
    def _sensor_noise(self) -> np.ndarray:
        """Variance of each measured channel (its SNR's, floored at :data:`NOISE_FLOOR`)."""
        env = self.env
        scales = env.model.output_layout.scales()[self._meas_rows]
        return np.maximum(env.noise_std[self._meas_rows], NOISE_FLOOR * scales) ** 2

    def _capture_map(self, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        """``(T, h)`` of the capture at the step from ``k``: ``x -> T x + h``; None if none."""
        model = self.env.model
        if k not in self._captures:
            return None
        if k not in self._capture_maps:
            t = k * self.dt
            h = model.capture(np.zeros(model.n), t)
            cols = [model.capture(e, t) - h for e in np.eye(model.n)]
            self._capture_maps[k] = (np.column_stack(cols), h)
        return self._capture_maps[k]

    def _transition(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The plant's step from ``k``: ``x+ = A x + B_d (g u + d) + c`` as
        ``(A, B_d, c + B_d d)``, a capture at that step folded in."""
        model = self.env.model
        ad, bd = model._discrete_ab(k * self.dt)
        drift = bd @ np.asarray(self.env.disturbance_torque, dtype=float)
        capture = self._capture_map(k)
        if capture is None:
            return ad, bd, drift
        return ad @ capture[0], bd, ad @ capture[1] + drift

    def problem(self, first: int, reference: ArrayLike) -> tuple[np.ndarray, ...]:
        """The linear-quadratic problem the ceiling plans over ``horizon_steps`` steps
        from step ``first`` for the attitude ``reference`` (rad, (3,)), in the form of
        :func:`finite_horizon_lqr` on the true plant of the current episode.

        The state is the plant's, followed by the commands still in the actuator's
        delay line (oldest first) when the env has a delay.

        Parameters
        ----------
        first : int
            The plan's first step.
        reference : (3,) array_like
            The reference attitude, rad.

        Returns
        -------
        a, b, c, q, q_lin, r : ndarray
            The arguments of :func:`finite_horizon_lqr`.
        constant : float
            The stage cost's constant part, ``r^T W r`` per step.
        """
        env, model = self.env, self.env.model
        n, d = model.n, int(env.actuator_delay_steps)
        na = n + 3 * d
        horizon = self.horizon_steps
        gain = float(env.actuator_gain)
        a = np.zeros((horizon, na, na))
        b = np.zeros((horizon, na, 3))
        c = np.zeros((horizon, na))
        for j in range(horizon):
            a_x, bd, c_x = self._transition(first + j)
            a[j, :n, :n] = a_x
            c[j, :n] = c_x
            if d == 0:
                b[j, :n] = gain * bd
            else:
                # the command of k - d acts now; the buffer shifts and takes u_k
                a[j, :n, n:n + 3] = gain * bd
                a[j, n:na - 3, n + 3:na] = np.eye(3 * (d - 1))
                b[j, na - 3:] = np.eye(3)
        weights = output_cost_weights(model.output_layout, self.weights)
        cq = model.C.T * weights
        q = np.zeros((na, na))
        q[:n, :n] = cq @ model.C
        q_lin = np.zeros(na)
        r_out = np.zeros(model.C.shape[0])
        r_out[model.output_layout.slice("attitude")] = np.asarray(reference, dtype=float)
        q_lin[:n] = cq @ r_out
        r = self.weights.torque * np.eye(3)
        return a, b, c, q, q_lin, r, float(r_out @ (weights * r_out))

    def _plan(self, first: int, reference: np.ndarray) -> None:
        """The episode's plan from step ``first`` over ``horizon_steps`` steps."""
        *problem, _ = self.problem(first, reference)
        counted = first + np.arange(self.horizon_steps) >= self.window_start_steps
        self._gains, self._offsets, *_ = finite_horizon_lqr(
            *problem, stage_weights=counted.astype(float),
            input_weights=np.where(counted, 1.0, WINDOW_TORQUE_WEIGHT))
        self._first = first
        self._reference_planned = np.array(reference, dtype=float)

    # ------------------------------------------------------------ episode
    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        if self.start is not None:
            self.start.reset(seed)
        self._kf: KalmanPredictor | None = None
        self._gains = self._offsets = None
        self._first = 0
        self._reference_planned = None
        self._captures = frozenset()
        self._commands: deque = deque()
        self.last_excitation = np.zeros(3)
        self._process_var = float(self.env.disturbance_std) ** 2

    def _begin(self, info: dict[str, Any]) -> None:
        """A new episode: the initial state, the filter on it, the plan."""
        env, model = self.env, self.env.model
        self._captures = model.capture_steps()
        self._noise_var = self._sensor_noise()
        self._c = model.C[self._meas_rows]
        self._capture_maps: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._kf = KalmanPredictor(model.n, initial_covariance=0.0)
        # the task's prior: the attitude uniform in +-initial_attitude (regulation) or
        # zero (slew), the rates and modal coordinates at rest
        if env.task == "regulation":
            self._kf.P[np.arange(3), np.arange(3)] = env.initial_attitude**2 / 3.0
        self._commands = deque([np.zeros(3)] * int(env.actuator_delay_steps))
        self._plan(0, np.asarray(info["reference"], dtype=float))

    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        if info is None or not {"time", "torque", "reference"} <= set(info):
            raise ValueError("ClairvoyantLQG needs the env's info dict with 'time', 'torque' "
                             "and 'reference'")
        obs = self._observation(obs)
        k = round(float(info["time"]) / self.dt)
        if k == 0 or self._kf is None:
            self._begin(info)
        else:
            # the step just flown, with the torque applied and the drift as an input
            a, bd, drift = self._transition(k - 1)
            b = np.hstack([self.env.actuator_gain * bd, drift[:, None]])
            # no floor: without process noise a known state stays known (P stays 0)
            q = self._process_var * (bd @ bd.T)
            applied = np.append(np.asarray(info["torque"], dtype=float), 1.0)
            self._kf.predict(a, b, q, applied)
        y = obs[self._meas_obs]
        x = self._kf.correct(self._c, self._noise_var, np.where(np.isfinite(y), y, np.nan))
        reference = np.asarray(info["reference"], dtype=float)
        if k >= self._first + self.horizon_steps or (
                self._reference_planned is not None
                and not np.array_equal(reference, self._reference_planned)):
            self._plan(k, reference)             # past the plan, or a new reference
        if k < self.start_steps:
            action = np.asarray(self.start.act(obs, info), dtype=np.float32)
            self.last_excitation = np.asarray(getattr(self.start, "last_excitation",
                                                      np.zeros(3)), dtype=float)
            self._last = action
        else:
            j = k - self._first
            state = np.concatenate([x, *self._commands]) if self._commands else x
            torque = -self._gains[j] @ state + self._offsets[j]
            self.last_excitation = np.zeros(3)
            action = self._to_action(torque)
        if self._commands:
            self._commands.append(action.astype(float) * self.max_torque)
            self._commands.popleft()
        return action
