"""Closed-loop harness: run controllers (or RL policies) on the environments.

:func:`run_episode` rolls one episode and returns a :class:`Trajectory`;
:func:`episode_metrics` scores it; :func:`compare` runs several controllers
on the same seeds and collects mean and spread. Tables and plots of the
results are the application layer's (``spacecraft_lab``).
"""

from __future__ import annotations

import json
import multiprocessing
import os
import zipfile
import zlib
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from controllers.actuator_monitor import AXIS_LOST
from controllers.base import Controller
from identifiers import relative_gain_error, rigid_body_gain
from spacecraft_conventions import (
    AXIS_NAMES,
    COST_WEIGHTS,
    DEG_PER_RAD,
    NOMINAL_SCALE,
    CostWeights,
    exit_with_parent,
    output_cost_weights,
    single_threaded_blas,
)

__all__ = ["AGGREGATED", "COST_PARTS", "COST_WEIGHTS", "ENVELOPE_FLOOR", "GROWTH_LIMIT", "GROWTH_T",
           "JUDGED_FROM_S", "SAME_START_S", "SCORED_FROM_S", "SLOW_GROWTH_LIMIT",
           "ComparisonInterrupted",
           "Trajectory", "compare", "controller_shares", "episode_metrics", "fallback_causes",
           "run_episode", "stage_costs"]

# COST_WEIGHTS (re-exported): the weights of the common quadratic cost by which every
# controller is scored, which every LQG here minimizes and whose negative is the env's
# reward="cost", defined once in spacecraft_conventions.cost.
#: The parts of the common cost, in the order :func:`stage_costs` returns them.
COST_PARTS = ("attitude", "rate", "deflection", "torque", "excitation")


@dataclass
class Trajectory:
    """One closed-loop episode.

    Attributes
    ----------
    time : (N,) ndarray
        Time of each observation after a step, s.
    observations : (N + 1, o) ndarray
    actions : (N, 3) ndarray
        Normalized actions.
    torque : (N, 3) ndarray
        Applied torque, N m.
    states : (N + 1, n) ndarray
        True states (``info["state"]``), starting with the reset state.
    reference : (N + 1, 3) ndarray
        Reference attitude, rad.
    rewards : (N,) ndarray
    terminated : bool
    events : tuple of float
        Scenario event times (docking), s.
    identified_frequencies : (K, f) ndarray or None
        First identified natural frequencies (Hz) every ``freq_every`` steps
        (controllers with an ``identifier``), NaN before warm-up.
    true_frequencies : (K, f) ndarray or None
    frequency_time : (K,) ndarray or None
    gain_error : (K,) ndarray or None
        Relative error of the identified rigid-body gain against the true
        ``J(t)^-1`` (times the env's ``actuator_gain``, the family's drawn
        efficiency: the gain from commanded torque to rate)
        (:func:`identifiers.relative_gain_error`) at ``frequency_time``, NaN
        before warm-up.
    gain_covered : (K,) ndarray or None
        1 where the identifier's own calibrated rigid-body gain
        (``identifier.rigid_gain``, :class:`identifiers.RigidGainEstimate`)
        covers the true ``J(t)^-1`` with its 2-sigma (95.45 %) confidence
        region (:meth:`identifiers.RigidGainEstimate.covers`), else 0;
        NaN before warm-up and for an exact gain (zero covariance: an
        oracle's); for identifiers that report one.
    controller_stats : dict
    excitation : (N, 3) ndarray or None
        The controller's excitation torque of each step (N m), for controllers
        that add one (``last_excitation``).
    radius_time, true_radius : (K,) ndarray or None
        Spectral radius of the closed loop of the controller's current design
        with the *true* plant frozen at ``radius_time`` (controllers with a
        ``closed_loop_radius``).

    Examples
    --------
    :func:`run_episode` returns one; :meth:`save` and :meth:`load` keep it:

    >>> import tempfile
    >>> from pathlib import Path
    >>> import gymnasium as gym
    >>> from controllers import PD, Trajectory, run_episode
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraft-v2")
    >>> traj = run_episode(env, PD(env), seed=0, max_steps=20)
    >>> len(traj.time), traj.states.shape, traj.terminated
    (20, (21, 22), False)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = traj.save(Path(tmp) / "episode")
    ...     again = Trajectory.load(path)
    >>> path.name, bool((again.torque == traj.torque).all())
    ('episode.npz', True)
    >>> env.close()
    """

    time: np.ndarray
    observations: np.ndarray
    actions: np.ndarray
    torque: np.ndarray
    states: np.ndarray
    reference: np.ndarray
    rewards: np.ndarray
    terminated: bool
    events: tuple = ()
    identified_frequencies: np.ndarray | None = None
    true_frequencies: np.ndarray | None = None
    frequency_time: np.ndarray | None = None
    gain_error: np.ndarray | None = None
    gain_covered: np.ndarray | None = None
    controller_stats: dict = field(default_factory=dict)
    excitation: np.ndarray | None = None
    radius_time: np.ndarray | None = None
    true_radius: np.ndarray | None = None

    def save(self, path: str | Path) -> Path:
        """Write the trajectory to ``path`` (NumPy ``.npz``, the suffix added if
        missing); :meth:`load` reads it back.

        Returns
        -------
        pathlib.Path
            The path written (with the .npz suffix).
        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz")
        arrays: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "controller_stats":
                arrays[f.name] = np.array(json.dumps(value, default=float))
            elif f.name == "terminated":
                arrays[f.name] = np.array(bool(value))
            elif f.name == "events":
                arrays[f.name] = np.asarray(value, dtype=float)
            elif value is not None:
                arrays[f.name] = np.asarray(value)
        np.savez_compressed(path, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        """A trajectory written by :meth:`save`.

        Returns
        -------
        Trajectory
            The trajectory as it was saved.

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ValueError
            The file is not a trajectory :meth:`save` wrote (truncated, empty,
            corrupt, another format, fields missing), or its arrays disagree on
            the episode length; the message names the file and what is wrong.
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no trajectory file {path}")
        try:
            data = np.load(path, allow_pickle=False)
            if not isinstance(data, np.lib.npyio.NpzFile):
                raise ValueError("a single .npy array, not an .npz archive")
            with data:
                kwargs: dict[str, Any] = {}
                for f in fields(cls):
                    if f.name not in data:
                        continue
                    value = data[f.name]
                    if f.name == "controller_stats":
                        kwargs[f.name] = json.loads(str(value))
                    elif f.name == "terminated":
                        kwargs[f.name] = bool(value)
                    elif f.name == "events":
                        kwargs[f.name] = tuple(float(v) for v in value)
                    else:
                        kwargs[f.name] = np.array(value)
        except (OSError, ValueError, EOFError, TypeError, KeyError, zipfile.BadZipFile,
                zlib.error) as exc:
            raise ValueError(f"{path} is not a trajectory written by Trajectory.save "
                             f"({type(exc).__name__}: {exc})") from None
        required = [f.name for f in fields(cls) if f.default is MISSING
                    and f.default_factory is MISSING]
        missing = [name for name in required if name not in kwargs]
        if missing:
            raise ValueError(f"{path} is not a trajectory written by Trajectory.save "
                             f"(missing {', '.join(missing)})")
        trajectory = cls(**kwargs)
        problem = trajectory.inconsistency()
        if problem:
            raise ValueError(f"{path}: {problem}")
        return trajectory

    def inconsistency(self) -> str | None:
        """What makes the arrays disagree on the episode length N (``len(time)``), or None.

        ``observations``, ``states`` and ``reference`` hold N + 1 rows, ``actions``,
        ``torque``, ``rewards`` and ``excitation`` N; the sampled series agree
        with their own time axis.

        Returns
        -------
        str or None
            A sentence naming the arrays whose lengths disagree; None when they agree.
        """
        n = len(self.time)
        expected = {"observations": n + 1, "states": n + 1, "reference": n + 1,
                    "actions": n, "torque": n, "rewards": n, "excitation": n}
        if self.frequency_time is not None:
            k = len(self.frequency_time)
            expected.update(identified_frequencies=k, true_frequencies=k, gain_error=k,
                            gain_covered=k)
        if self.radius_time is not None:
            expected["true_radius"] = len(self.radius_time)
        wrong = [f"{name} has shape {np.shape(value)}" for name, expected_rows in expected.items()
                 if (value := getattr(self, name)) is not None and (
                     np.ndim(value) == 0 or len(value) != expected_rows)]
        if wrong:
            return (f"arrays of different lengths: time has {n} rows (N), but "
                    + ", ".join(wrong) + " (expected N + 1 for observations, states and "
                    "reference, N for actions, torque and rewards)")
        return None


def _first(freqs: np.ndarray, count: int) -> np.ndarray:
    """The ``count`` lowest frequencies, NaN-padded."""
    out = np.full(count, np.nan)
    out[:min(count, freqs.size)] = freqs[:count]
    return out


def _positive_int(value: Any) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= 1


def run_episode(env: gym.Env, controller: Controller, seed: int | None = None,
                options: dict[str, Any] | None = None, max_steps: int | None = None,
                freq_every: int = 25, n_freq: int = 4, radius_every: int = 10) -> Trajectory:
    """Roll one episode of ``controller`` on ``env``.

    Parameters
    ----------
    env : gymnasium.Env
        A registered environment (wrappers allowed).
    controller : Controller
        Called as ``act(obs, info)``.
    seed : int, optional
        Seeds the env reset and the controller's dither.
    options : dict, optional
        Passed to ``env.reset``.
    max_steps : int, optional
        Step budget, at least 1; default the spec's ``max_episode_steps``
        (2500 for the registered ids), or 2500 for an env built without
        ``gym.make``, so an unwrapped env (no time limit) still ends.
    freq_every, n_freq : int
        Sampling of identified/true modal frequencies.
    radius_every : int
        Steps between evaluations of the true closed loop's spectral radius
        (controllers with a ``closed_loop_radius(model, t)``); default 10,
        every second (sampled every 10 s, a 56 s stretch above 1 went unseen).

    Raises
    ------
    TypeError
        If ``env`` is not a Gymnasium env or ``controller`` has no ``act``.
    ValueError
        If ``max_steps`` is given and is not an integer >= 1, or a sampling
        period or count is not, or ``seed`` is not an integer >= 0 or None.

    Returns
    -------
    Trajectory
        The N steps flown (N <= ``max_steps``; fewer if the env terminated or
        truncated the episode): observations, actions, applied torques (N m),
        true states, reference attitudes (rad), rewards, and what the
        controller reports (identified frequencies, gain errors, stats,
        excitation, closed-loop radius).

    Examples
    --------
    >>> import gymnasium as gym
    >>> from controllers import PD, run_episode
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraft-v2")
    >>> traj = run_episode(env, PD(env), seed=0, max_steps=20)
    >>> float(traj.time[-1]), traj.torque.shape, traj.observations.shape
    (2.0, (20, 3), (21, 10))
    >>> env.close()
    """
    if not isinstance(env, gym.Env):
        raise TypeError(f"env must be a gymnasium.Env, got {type(env).__name__}")
    if not callable(getattr(controller, "act", None)) or not callable(
            getattr(controller, "reset", None)):
        raise TypeError(f"controller must have act(obs, info) and reset(seed), got "
                        f"{type(controller).__name__}")
    base = env.unwrapped
    if max_steps is not None and not _positive_int(max_steps):
        raise ValueError(f"max_steps must be an integer >= 1 (or None), got {max_steps!r}")
    for name, value in (("freq_every", freq_every), ("n_freq", n_freq),
                        ("radius_every", radius_every)):
        if not _positive_int(value):
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    if seed is not None and not (_positive_int(seed) or (
            isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed == 0)):
        raise ValueError(f"seed must be an integer >= 0 or None, got {seed!r}")
    if max_steps is None:
        spec = getattr(env, "spec", None)
        max_steps = (spec.max_episode_steps if spec is not None and spec.max_episode_steps
                     else 2500)
    obs, info = env.reset(seed=seed, options=options)
    controller.reset(seed)
    observations, actions, torques, states, refs, rewards = [obs], [], [], [info["state"]], \
        [info["reference"]], []
    ident = getattr(controller, "identifier", None)
    freq_t, freq_id, freq_true, gain_err, covered = [], [], [], [], []
    reports_gain = ident is not None and hasattr(ident, "rigid_gain")
    layout = getattr(controller, "measured_layout", None)
    rate_rows = (layout.indices("rate") if layout is not None and "rate" in layout.names
                 else None)
    terminated = truncated = False
    k = 0
    radius_of = getattr(controller, "closed_loop_radius", None)
    radius_t, radius = [], []
    excitation = [] if hasattr(controller, "last_excitation") else None
    with single_threaded_blas:
        while not (terminated or truncated) and k < max_steps:
            action = controller.act(obs, info)
            if excitation is not None:
                excitation.append(np.asarray(controller.last_excitation, dtype=float))
            if callable(radius_of) and k % radius_every == 0:
                t = float(info["time"])
                value = radius_of(base.model, t)
                if value is not None:
                    radius_t.append(t)
                    radius.append(value)
            obs, reward, terminated, truncated, info = env.step(action)
            observations.append(obs)
            actions.append(action)
            torques.append(info["torque"])
            states.append(info["state"])
            refs.append(info["reference"])
            rewards.append(reward)
            if ident is not None and k % freq_every == 0:
                freq_t.append(info["time"])
                model = ident.model
                freq_id.append(np.full(n_freq, np.nan) if model is None
                               else _first(model.modal(unique=False)[0], n_freq))
                freq_true.append(_first(base.model.modal(info["time"])[0], n_freq))
                # the gain from commanded torque to body rate: the inverse inertia,
                # times the task family's actuator efficiency
                true_gain = base.actuator_gain * np.linalg.inv(base.model.inertia(info["time"]))
                gain_err.append(np.nan if model is None or rate_rows is None else
                                relative_gain_error(rigid_body_gain(model, rate_rows),
                                                    true_gain))
                if reports_gain:
                    estimate = ident.rigid_gain
                    # an exact gain (an oracle's: zero covariance) has no band to judge
                    covered.append(np.nan if estimate is None
                                   or not np.trace(estimate.covariance) > 0
                                   else float(estimate.covers(true_gain)))
            k += 1
    dt = base.model.dt
    return Trajectory(
        time=np.arange(1, k + 1) * dt,
        observations=np.array(observations), actions=np.array(actions),
        torque=np.array(torques), states=np.array(states), reference=np.array(refs),
        rewards=np.array(rewards), terminated=bool(terminated),
        events=tuple(base.scenario.event_times()),
        identified_frequencies=np.array(freq_id) if freq_id else None,
        true_frequencies=np.array(freq_true) if freq_true else None,
        frequency_time=np.array(freq_t) if freq_t else None,
        gain_error=np.array(gain_err) if gain_err else None,
        gain_covered=np.array(covered) if covered else None,
        controller_stats=dict(getattr(controller, "stats", {})),
        excitation=np.array(excitation).reshape(-1, 3) if excitation is not None else None,
        radius_time=np.array(radius_t) if radius_t else None,
        true_radius=np.array(radius) if radius else None,
    )


#: Start of the scored window after warm-up, s (``attitude_rms_after_100s_deg``).
SCORED_FROM_S = 100.0
#: Start of the window the same-start ceiling bounds, s (``cost_after_start``): the end of
#: the adaptive loop's start, its identifier's 30 s warm-up and the first fit's 10 s
#: latency (:func:`controllers.adaptive_start`; docs/design/evaluation.md).
SAME_START_S = 40.0
#: Start of the window over which an adaptive loop's identification and design are
#: judged (fallback share, rigid-gain error and coverage), s: its warm-up is over.
JUDGED_FROM_S = 60.0
#: Length of the windows whose peaks form the envelope of the stability verdict, s.
ENVELOPE_WINDOW_S = 10.0
#: Envelope growth over 100 s above which a loop is judged unstable.
GROWTH_LIMIT = 2.0
#: A slower envelope growth over 100 s (above 1.05) is judged unstable when its trend is
#: significant: the log-peaks' slope at least :data:`GROWTH_T` standard errors above zero.
#: Any controller's trajectory is judged so, whether or not it exposes its design: the
#: fixed LQG at a 90 deg paddle angle (true closed-loop radius 1.00014 per step, 1.15x per
#: 100 s) grows 1.11-1.13x with t = 4.9-7.1, where stable loops decay (0.30-0.66x, t below
#: -4.9; docs/design/control.md, "The verdict for any controller").
SLOW_GROWTH_LIMIT = 1.05
GROWTH_T = 3.0
#: Length of the sliding window (the last part of the episode) whose envelope growth is
#: judged too, s: a fit over a long run averages early decay and late divergence.
GROWTH_WINDOW_S = 300.0
#: A true closed loop whose spectral radius exceeds 1 by this at every sample of
#: :data:`RADIUS_STRETCH_S` seconds is growing, however slowly (1.00023 per 0.1 s is
#: 1.25x per 100 s: too slow for a 250 s run's envelope to show).
RADIUS_MARGIN = 1e-5
RADIUS_STRETCH_S = 50.0
#: Envelope level (in nominal sensor scales: 1 deg, 1 cm) below which growth is not judged:
#: sensor noise and a decaying transient wander there.
ENVELOPE_FLOOR = 0.05
#: Share of the last 10 % of steps with a saturated actuator that marks a limit cycle.
SATURATION_LIMIT = 0.5
#: Window before an event in which the loop must have settled for a settling time, s.
SETTLED_BEFORE_S = 10.0


def controller_shares(stats: dict[str, Any]) -> dict[str, float]:
    """Excitation RMS torque (N m) and the shares of steps with a rejected gain and
    flown by a fallback (all steps, and from :data:`JUDGED_FROM_S` on: after the
    identifier's warm-up), from a controller's ``stats`` (0 for controllers
    without them).

    Parameters
    ----------
    stats : dict
        A controller's ``stats`` (:attr:`Trajectory.controller_stats`); the
        keys read are ``steps``, ``steps_after_60s``, ``excitation_rms_Nm``,
        ``rejected``, ``fallback_steps`` and ``fallback_steps_after_60s``
        (as :class:`controllers.adaptive.AdaptiveLQG` keeps them), each
        missing one taken as 0.

    Returns
    -------
    dict
        ``excitation_rms_Nm`` (N m), and ``rejected_share``,
        ``fallback_share`` and ``fallback_share_after_60s``: shares of the
        steps (of those from :data:`JUDGED_FROM_S` on for the last);
        ``fallback_causes_after_60s``: cause -> share of the steps from
        :data:`JUDGED_FROM_S` on that the fallback flew for that cause (from
        ``stats["fallback_by_after_60s"]``, the causes of
        :data:`controllers.adaptive.FALLBACK_CAUSES`; they sum to
        ``fallback_share_after_60s``; empty for controllers without them).
    """
    steps = max(1, int(stats.get("steps", 0)))
    late = max(1, int(stats.get("steps_after_60s", 0)))
    return {"excitation_rms_Nm": float(stats.get("excitation_rms_Nm", 0.0)),
            "rejected_share": stats.get("rejected", 0) / steps,
            "fallback_share": stats.get("fallback_steps", 0) / steps,
            "fallback_share_after_60s": stats.get("fallback_steps_after_60s", 0) / late,
            "fallback_causes_after_60s": {
                cause: count / late
                for cause, count in sorted(stats.get("fallback_by_after_60s", {}).items())}}


def fallback_causes(per_seed: list[dict[str, Any]]) -> dict[str, float]:
    """Why the fallback flew, over seeds: each cause's mean share of the steps.

    Parameters
    ----------
    per_seed : list of dict
        Episode metrics (:func:`episode_metrics`), one per seed, each with the
        ``fallback_causes_after_60s`` of :func:`controller_shares` (a metric
        without it, or a cause a seed did not meet, counts 0).

    Returns
    -------
    dict
        Cause (:data:`controllers.adaptive.FALLBACK_CAUSES`) -> mean over the
        seeds of its share of the steps from :data:`JUDGED_FROM_S` on, largest
        first: for seeds of equal length, the share of all their steps from
        then on. Empty for controllers without a fallback.

    Examples
    --------
    >>> fallback_causes([{"fallback_causes_after_60s": {"prediction": 0.4}},
    ...                  {"fallback_causes_after_60s": {"dwell": 0.1, "prediction": 0.2}}])
    {'prediction': 0.30000000000000004, 'dwell': 0.05}
    """
    if not per_seed:
        return {}
    causes = {c for m in per_seed for c in m.get("fallback_causes_after_60s", {})}
    mean = {c: float(np.mean([m.get("fallback_causes_after_60s", {}).get(c, 0.0)
                              for m in per_seed])) for c in causes}
    return dict(sorted(mean.items(), key=lambda item: (-item[1], item[0])))


def _envelope_growth(time: np.ndarray, level: np.ndarray,
                     start_s: float) -> tuple[float, float, float]:
    """Growth per 100 s of the windowed peaks of ``level`` from ``start_s``, the last
    peak, and the t-statistic of the growth.

    The peaks of consecutive :data:`ENVELOPE_WINDOW_S` windows are fitted by
    a straight line in log scale; the growth is ``exp(100 * slope)`` and the
    t-statistic the slope over its standard error (residual variance on
    ``count - 2`` degrees of freedom; NaN below four windows).
    """
    dt = time[1] - time[0] if time.size > 1 else 1.0
    width = max(1, round(ENVELOPE_WINDOW_S / dt))
    late = level[time >= start_s]
    count = late.size // width
    if count < 3:
        last = float(np.max(level[-width:])) if level.size else float("nan")
        return float("nan"), last, float("nan")
    peaks = late[late.size - count * width:].reshape(count, width).max(axis=1)
    centres = np.arange(count) * width * dt
    logs = np.log(np.maximum(peaks, 1e-12))
    slope, intercept = np.polyfit(centres, logs, 1)
    t_stat = float("nan")
    if count >= 4:
        residual = logs - (slope * centres + intercept)
        spread = float(np.sum((centres - centres.mean()) ** 2))
        error = np.sqrt(float(residual @ residual) / (count - 2) / spread)
        t_stat = float(slope / error) if error > 0 else float(np.sign(slope) * np.inf)
    return float(np.exp(100.0 * slope)), float(peaks[-1]), t_stat


def _slowly_growing(growth: float, t_stat: float, last_peak: float) -> bool:
    """A slow but significant growth of the envelope (see :data:`SLOW_GROWTH_LIMIT`)."""
    return (np.isfinite(growth) and growth > SLOW_GROWTH_LIMIT and t_stat > GROWTH_T
            and last_peak > ENVELOPE_FLOOR)


def stage_costs(traj: Trajectory, model: Any,
                weights: CostWeights = COST_WEIGHTS) -> np.ndarray:
    """The common quadratic cost of every step, split into its parts, (N, 5).

    Columns (:data:`COST_PARTS`): ``attitude * |e / 1 deg|^2``, ``rate *
    |omega / 0.1 deg/s|^2``, ``deflection * |d / 1 cm|^2`` (true states after the
    step: attitude error against the reference, body rates, tip deflections),
    ``torque * |u / 1 N m|^2`` of the applied torque, and the part of that
    torque term due to the controller's excitation (``torque * |u_exc|^2``,
    0 without one; it is included in the torque column, not added to it).
    The weights are those every LQG design here minimizes, and the sum of the
    first four columns is minus the env's ``reward="cost"`` of the same step
    (:mod:`spacecraft_conventions.cost`).

    Parameters
    ----------
    traj : Trajectory
        The episode (its ``states``, ``reference``, ``torque`` and
        ``excitation``).
    model : FlexibleSpacecraftModel
        The truth model the episode ran on (``env.unwrapped.model``), whose
        ``C`` and ``output_layout`` read attitude, rates and deflections from
        the true states.
    weights : CostWeights
        The cost's weights (default :data:`COST_WEIGHTS`; an
        :class:`controllers.lqg.LQRWeights` is one).

    Returns
    -------
    (N, 5) ndarray
        One row per step, the columns of :data:`COST_PARTS`, dimensionless.
    """
    layout = model.output_layout
    err = traj.states[1:] @ model.C.T           # the true outputs, in layout order
    err[:, layout.slice("attitude")] -= traj.reference[1:]
    # the same per-channel weights as the env's reward (spacecraft_conventions.cost)
    weighted = output_cost_weights(layout, weights) * err**2
    torque = traj.torque
    exc = traj.excitation if traj.excitation is not None else np.zeros_like(torque)
    return np.column_stack([*(weighted[:, layout.slice(g)].sum(axis=1)
                              for g in ("attitude", "rate", "deflection")),
                            weights.torque * np.sum(torque**2, axis=1),
                            weights.torque * np.sum(exc**2, axis=1)])


def _sustained_radius(traj: Trajectory, start_s: float) -> bool:
    """Whether the true closed loop's radius exceeds 1 at every sample of some
    :data:`RADIUS_STRETCH_S` stretch from ``start_s`` on."""
    if traj.true_radius is None or traj.radius_time is None:
        return False
    keep = traj.radius_time >= start_s
    t, r = traj.radius_time[keep], traj.true_radius[keep]
    run_start = None
    for ti, ri in zip(t, r, strict=True):
        if ri > 1.0 + RADIUS_MARGIN:
            run_start = ti if run_start is None else run_start
            if ti - run_start >= RADIUS_STRETCH_S:
                return True
        else:
            run_start = None
    return False


def episode_metrics(traj: Trajectory, model: Any, settle_tol_deg: float = 0.05,
                    stable_bound_deg: float = 1.0, start_s: float = SAME_START_S
                    ) -> dict[str, Any]:
    """Scores of one episode.

    Parameters
    ----------
    traj : Trajectory
    model : spacecraft_env.FlexibleSpacecraftModel
        The env's truth model (output layout, sample time).
    settle_tol_deg : float
        Attitude-error band of the settling times, deg.
    stable_bound_deg : float
        Attitude error the last 10 % of a stable episode stays below, deg.
    start_s : float
        Start of the window ``cost_after_start`` averages, s (default
        :data:`SAME_START_S`: where the same-start ceiling takes over).

    Returns
    -------
    dict
        ``cost`` (the common quadratic cost, :func:`stage_costs`, averaged over
        the whole episode: the quantity every LQG here minimizes and the
        ceiling, :class:`controllers.ClairvoyantLQG`, bounds) and its parts
        ``cost_attitude``, ``cost_rate``, ``cost_deflection``, ``cost_torque``
        and ``cost_excitation``; ``cost_after_start`` (the same from
        ``start_s`` on, the window the same-start ceiling bounds);
        ``cost_after_100s`` (the same from :data:`SCORED_FROM_S` on: a
        stationary window, which no flown ceiling bounds) and its parts
        ``cost_attitude_after_100s``,
        ``cost_rate_after_100s``, ``cost_deflection_after_100s``,
        ``cost_torque_after_100s`` and ``cost_excitation_after_100s`` (the
        share of the torque term due to an excitation), all infinite for an
        episode that crashed (verdict ``"diverged"`` or ``"terminated"``),
        whenever it crashed; ``true_radius_max``
        (largest spectral radius of the true closed loop sampled from 100 s,
        None when the controller does not expose one);
        ``attitude_rms_deg`` and ``attitude_peak_deg`` (true attitude error,
        all axes, after the first step); ``attitude_rms_after_100s_deg`` and
        ``vibration_rms_after_100s_mm`` (from :data:`SCORED_FROM_S` on, once
        an identifier has warmed up); ``settling_s`` (per scenario event: time
        after the event until the error stays below ``settle_tol_deg``; None
        if it never does, or if the loop had not settled in the
        :data:`SETTLED_BEFORE_S` before the event, which
        ``settled_before_event`` tells); ``vibration_rms_mm`` (true tip
        deflections); ``torque_rms_Nm`` and ``effort_N2m2s`` (integral of
        |u|^2); ``return``; ``envelope_growth_per_100s`` (growth of the
        windowed peaks of the attitude error and the deflections, in their
        nominal scales, from t = 100 s, or from the middle of a shorter
        episode) and ``envelope_growth_t`` (its t-statistic: the log-peaks'
        slope over its standard error); ``saturated_share`` (share of the
        last 10 % of steps with an actuator at its limit); ``verdict``,
        ``verdict_reason`` (why a verdict other than stable is no fault of the law:
        an axis the controller reported lost, kind "axis lost" in its
        ``stats["faults"]``; else None) and ``stable``; and the
        controller's ``excitation_rms_Nm``, ``rejected_share`` and
        ``fallback_share`` and ``fallback_share_after_60s``
        (:func:`controller_shares`); for controllers with an identifier,
        ``gain_error_after_60s`` (median relative error of the identified
        rigid-body gain from :data:`JUDGED_FROM_S` on) and
        ``gain_coverage_after_60s`` (share of those samples whose reported
        2-sigma band covers the truth; None without a reported uncertainty).

    Notes
    -----
    The verdict is the first that applies of ``"diverged"`` (non-finite
    state), ``"terminated"`` (attitude bound left), ``"growing"`` (envelope
    growth above :data:`GROWTH_LIMIT` per 100 s with the last peak above
    :data:`ENVELOPE_FLOOR`, fitted from t = 100 s and over the last
    :data:`GROWTH_WINDOW_S`; or a slower growth, above
    :data:`SLOW_GROWTH_LIMIT`, whose t-statistic exceeds :data:`GROWTH_T`,
    judged so for any controller, wrappers and agents included; or, where
    the controller exposes its design, the true closed loop's spectral
    radius above 1 for :data:`RADIUS_STRETCH_S`: an unstable loop, however
    slowly it grows),
    ``"saturated"`` (a limit cycle: an actuator at its limit for more than
    :data:`SATURATION_LIMIT` of the last 10 %), ``"offset"`` (the last 10 %
    of the error above ``stable_bound_deg``), else ``"stable"``. A final
    error alone cannot tell an unstable loop that has not yet grown large
    from a stable one.
    """
    layout = model.output_layout
    err = (traj.states[1:] @ model.C[layout.slice("attitude")].T - traj.reference[1:]) \
        * DEG_PER_RAD
    err_norm = np.abs(err).max(axis=1)
    defl_m = traj.states[1:] @ model.C[layout.slice("deflection")].T
    defl = defl_m * 1e3
    dt = model.dt
    time = traj.time
    settling, settled_before = [], []
    before_steps = round(SETTLED_BEFORE_S / dt)
    for event in traj.events or ():
        after = time >= event
        if not after.any():
            settling.append(None)
            settled_before.append(None)
            continue
        first = int(np.argmax(after))
        window = err_norm[max(0, first - before_steps):first]
        calm = bool(window.size and window.max() <= settle_tol_deg)
        settled_before.append(calm)
        outside = np.flatnonzero(after & (err_norm > settle_tol_deg))
        if not calm or (outside.size and outside[-1] == len(err_norm) - 1):
            settling.append(None)
        elif outside.size == 0:
            settling.append(0.0)
        else:
            settling.append(float(time[outside[-1] + 1] - event))
    level = np.maximum(err_norm / (NOMINAL_SCALE["attitude"] * DEG_PER_RAD),
                       np.abs(defl_m).max(axis=1) / NOMINAL_SCALE["deflection"])
    finite = bool(np.all(np.isfinite(traj.states)))
    scored_from = SCORED_FROM_S if time.size and time[-1] > 1.5 * SCORED_FROM_S \
        else (0.5 * time[-1] if time.size else 0.0)
    nan3 = (float("nan"),) * 3
    growth, last_peak, growth_t = (_envelope_growth(time, level, scored_from) if finite
                                   else nan3)
    window_start = max(scored_from, float(time[-1]) - GROWTH_WINDOW_S) if time.size else 0.0
    late_growth, _, late_t = (_envelope_growth(time, level, window_start) if finite
                              else nan3)
    radius_growing = _sustained_radius(traj, scored_from)
    tail_n = max(1, len(err_norm) // 10)
    saturated = (float(np.mean(np.any(np.abs(traj.actions[-tail_n:]) >= 0.999, axis=1)))
                 if traj.actions.size else 0.0)
    if not finite:
        verdict = "diverged"
    elif traj.terminated:
        verdict = "terminated"
    elif ((max((g for g in (growth, late_growth) if np.isfinite(g)), default=0.0)
           > GROWTH_LIMIT and last_peak > ENVELOPE_FLOOR) or radius_growing
          or _slowly_growing(growth, growth_t, last_peak)
          or _slowly_growing(late_growth, late_t, last_peak)):
        verdict = "growing"
    elif saturated > SATURATION_LIMIT:
        verdict = "saturated"
    elif err_norm[-tail_n:].max() >= stable_bound_deg:
        verdict = "offset"
    else:
        verdict = "stable"
    late = time >= SCORED_FROM_S
    after_start = time >= start_s
    costs = stage_costs(traj, model)
    nan = np.full(len(COST_PARTS), np.nan)
    cost = costs[late].mean(axis=0) if late.any() else nan
    whole = costs.mean(axis=0) if len(costs) else nan
    cost_after_start = costs[after_start, :4].sum(axis=1).mean() if after_start.any() \
        else float("nan")
    # a controller that reported an axis it cannot hold says why the loop is not stable
    lost = [f for f in (traj.controller_stats or {}).get("faults", [])
            if f.get("kind") == AXIS_LOST]
    verdict_reason = None
    if verdict != "stable" and lost:
        axes = ", ".join(AXIS_NAMES[f["axis"]] for f in lost)
        verdict_reason = (f"{axes} lost: its wheel does not answer (reported at "
                          f"{min(f['detected_s'] for f in lost):.0f} s); with one wheel per "
                          "axis no controller can hold it")
    crashed = verdict in ("diverged", "terminated")
    if crashed:
        # a crash costs infinity whenever it happens: averaged over the steps that exist,
        # one after 100 s would look cheaper than a loop that flew to the end
        cost = whole = np.full(len(COST_PARTS), np.inf)
        cost_after_start = float("inf")
    gain_error = gain_coverage = None
    if traj.gain_error is not None and traj.frequency_time is not None:
        judged = traj.frequency_time >= JUDGED_FROM_S
        errors = traj.gain_error[judged]
        errors = errors[np.isfinite(errors)]
        gain_error = float(np.median(errors)) if errors.size else None
        if traj.gain_covered is not None:
            covered = traj.gain_covered[judged]
            covered = covered[np.isfinite(covered)]
            gain_coverage = float(covered.mean()) if covered.size else None
    radius_max = None
    if traj.true_radius is not None and traj.radius_time is not None:
        scored = traj.true_radius[traj.radius_time >= scored_from]
        radius_max = float(scored.max()) if scored.size else None
    return {
        "cost": float(np.sum(whole[:4])),
        **{f"cost_{part}": float(value) for part, value in zip(COST_PARTS, whole, strict=True)},
        "cost_after_start": float(cost_after_start),
        "cost_after_100s": float(np.sum(cost[:4])),
        **{f"cost_{part}_after_100s": float(value)
           for part, value in zip(COST_PARTS, cost, strict=True)},
        "true_radius_max": radius_max,
        "gain_error_after_60s": gain_error,
        "gain_coverage_after_60s": gain_coverage,
        "attitude_rms_deg": float(np.sqrt(np.mean(err**2))),
        "attitude_rms_after_100s_deg": (float(np.sqrt(np.mean(err[late] ** 2))) if late.any()
                                        else float("nan")),
        "attitude_peak_deg": float(err_norm.max()),
        "settling_s": settling,
        "settled_before_event": settled_before,
        "vibration_rms_mm": float(np.sqrt(np.mean(defl**2))),
        "vibration_rms_after_100s_mm": (float(np.sqrt(np.mean(defl[late] ** 2))) if late.any()
                                        else float("nan")),
        "torque_rms_Nm": float(np.sqrt(np.mean(traj.torque**2))),
        "effort_N2m2s": float(np.sum(traj.torque**2) * dt),
        "return": float(traj.rewards.sum()),
        "envelope_growth_per_100s": growth,
        "envelope_growth_t": growth_t,
        "saturated_share": saturated,
        "verdict": verdict,
        "verdict_reason": verdict_reason,
        "stable": verdict == "stable",
        **controller_shares(traj.controller_stats),
    }


#: Scalar metrics aggregated by :func:`compare` (median and spread over seeds).
AGGREGATED = ("cost", "cost_attitude", "cost_rate", "cost_deflection", "cost_torque",
              "cost_excitation", "cost_after_start", "cost_after_100s",
              "cost_attitude_after_100s", "cost_rate_after_100s",
              "cost_deflection_after_100s", "cost_torque_after_100s",
              "cost_excitation_after_100s",
              "attitude_rms_deg", "attitude_rms_after_100s_deg", "attitude_peak_deg",
              "vibration_rms_mm", "vibration_rms_after_100s_mm", "torque_rms_Nm",
              "effort_N2m2s", "return", "envelope_growth_per_100s", "excitation_rms_Nm",
              "rejected_share", "fallback_share", "fallback_share_after_60s",
              "gain_error_after_60s", "gain_coverage_after_60s")


class ComparisonInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`compare`, carrying what was complete.

    Attributes
    ----------
    table, trajectories
        As :func:`compare` returns them, over the seeds every controller
        finished (empty dicts if none).
    """

    def __init__(self, table: dict[str, dict], trajectories: dict[str, list[Trajectory]],
                 completed: int, total: int) -> None:
        super().__init__(f"interrupted after {completed} of {total} seeds")
        self.table, self.trajectories = table, trajectories
        self.completed, self.total = completed, total


def _over_seeds(values: np.ndarray, statistic: Callable[[np.ndarray], Any]) -> float:
    """``statistic`` of the values that exist; NaN (silently) when there is none, e.g. a
    metric scored from 100 s on episodes shorter than that. An infinite value (the
    cost of a crash) counts: it is a result, not a missing one."""
    finite = values[~np.isnan(values)]
    return float(statistic(finite)) if finite.size else float("nan")


def _aggregate(per_seed: list[dict[str, Any]]) -> dict[str, Any]:
    arr = {k: np.array([m[k] for m in per_seed], dtype=float) for k in AGGREGATED}
    return {
        "per_seed": per_seed,
        "median": {k: _over_seeds(v, np.median) for k, v in arr.items()},
        "q25": {k: _over_seeds(v, lambda x: np.percentile(x, 25)) for k, v in arr.items()},
        "q75": {k: _over_seeds(v, lambda x: np.percentile(x, 75)) for k, v in arr.items()},
        "mean": {k: _over_seeds(v, np.mean) for k, v in arr.items()},
        "std": {k: _over_seeds(v, np.std) for k, v in arr.items()},
        "stable_runs": int(sum(m["stable"] for m in per_seed)),
        "verdicts": {v: sum(m["verdict"] == v for m in per_seed)
                     for v in sorted({m["verdict"] for m in per_seed})},
        "fallback_causes_after_60s": fallback_causes(per_seed),
        "runs": len(per_seed),
    }


def _run_seed(controllers: dict[str, Callable[[Any], Controller]], make_env: Callable[[], Any],
              seed: int, options: dict[str, Any] | None
              ) -> dict[str, tuple[dict[str, Any], Trajectory]]:
    """Every controller on one seed, each built fresh on a fresh environment, so the
    result depends on the seed alone (not on which seeds ran before, or where)."""
    return {name: _run_one(factory, make_env, seed, options)
            for name, factory in controllers.items()}


def _run_one(factory: Callable[[Any], Controller], make_env: Callable[[], Any], seed: int,
             options: dict[str, Any] | None) -> tuple[dict[str, Any], Trajectory]:
    """One controller's episode on one seed, on a fresh environment: its metrics (with
    the seed and the controller's stats) and trajectory."""
    env = make_env()
    try:
        ctrl = factory(env)
        traj = run_episode(env, ctrl, seed=seed, options=options)
        metrics = episode_metrics(traj, env.unwrapped.model)
    finally:
        env.close()
    metrics["seed"] = int(seed)
    metrics["controller_stats"] = traj.controller_stats
    return metrics, traj


def compare(controllers: dict[str, Callable[[Any], Controller]], make_env: Callable[[], Any],
            seeds: Sequence[int], options: dict[str, Any] | None = None,
            progress: bool = True, workers: int = 1
            ) -> tuple[dict[str, dict], dict[str, list[Trajectory]]]:
    """Run every controller on the same seeds.

    Every episode runs on a fresh environment with a freshly built
    controller, so each result depends on its seed alone: the serial run
    and any number of workers give the same numbers (test). Ctrl-C raises
    :class:`ComparisonInterrupted` holding the table of the first seeds
    every controller finished.

    Parameters
    ----------
    controllers : dict
        Name -> factory ``env -> Controller``. With ``workers > 1`` the
        factories and ``make_env`` must be picklable (module-level functions
        or :func:`functools.partial` of them, not lambdas).
    make_env : callable
        Returns a fresh environment.
    seeds : sequence of int
    options : dict, optional
        ``env.reset`` options.
    progress : bool
        Show a progress bar (episodes done, with an estimate of the time left).
    workers : int
        Processes that run episodes side by side (default 1: this process): each
        controller's episode on each seed is one task, so a slow controller does not
        hold its seed's others back. Each worker runs its episodes with
        single-threaded BLAS, as the serial run does.

    Returns
    -------
    table : dict
        Name -> {"per_seed": [metrics...], "median", "q25", "q75", "mean",
        "std": {metric: value} over :data:`AGGREGATED`, "stable_runs": int,
        "verdicts": {verdict: count}, "runs": int}.
    trajectories : dict
        Name -> the trajectory of every seed (for plots of the spread).

    Raises
    ------
    ComparisonInterrupted
        On Ctrl-C, with the complete seeds' results.
    ValueError
        If ``workers`` is not a positive integer.

    Examples
    --------
    Two controllers on the same two seeds (20 s episodes):

    >>> import gymnasium as gym
    >>> from controllers import PD, FixedLQG, compare
    >>> def make_env():
    ...     return gym.make("spacecraft_env:FlexibleSpacecraft-v2", max_episode_steps=200)
    >>> table, runs = compare({"pd": PD, "lqg": FixedLQG}, make_env, seeds=[0, 1],
    ...                       progress=False)
    >>> table["lqg"]["runs"], table["lqg"]["verdicts"], len(runs["pd"])
    (2, {'stable': 2}, 2)
    >>> sorted(table["lqg"]["median"])[:3]     # medians over seeds of episode_metrics
    ['attitude_peak_deg', 'attitude_rms_after_100s_deg', 'attitude_rms_deg']
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    seeds = [int(s) for s in seeds]
    results: dict[int, dict[str, tuple[dict[str, Any], Trajectory]]] = {}
    pool = None
    try:
        # one tick per seed (all its controllers), the time left from the mean rate so far
        # (smoothing 0): with a pool the seeds end in bursts, and the default smoothing
        # made the estimate jump tenfold
        with tqdm(total=len(seeds), desc=f"closed loop ({len(controllers)} controllers)",
                  unit="seed", smoothing=0, disable=not progress) as bar:
            if workers == 1 or len(seeds) < 2:
                for seed in seeds:
                    results[seed] = _run_seed(controllers, make_env, seed, options)
                    bar.update()
            else:
                tasks = [(seed, name) for seed in seeds for name in controllers]
                pool = ProcessPoolExecutor(min(workers, len(tasks)),
                                           mp_context=multiprocessing.get_context("spawn"),
                                           initializer=exit_with_parent,
                                           initargs=(1.0, os.getpid()))
                futures = {pool.submit(_run_one, controllers[name], make_env, seed, options):
                           (seed, name) for seed, name in tasks}
                for future in as_completed(futures):
                    seed, name = futures[future]
                    results.setdefault(seed, {})[name] = future.result()
                    if len(results[seed]) == len(controllers):
                        bar.update()
    except KeyboardInterrupt:
        if pool is not None:
            for proc in list(getattr(pool, "_processes", {}).values()):
                proc.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            pool = None
        done = 0                       # the first seeds that all finished
        while done < len(seeds) and len(results.get(seeds[done], {})) == len(controllers):
            done += 1
        table, runs = _collect(controllers, [results[s] for s in seeds[:done]])
        raise ComparisonInterrupted(table if done else {}, runs if done else {},
                                    done, len(seeds)) from None
    finally:
        if pool is not None:
            pool.shutdown()
    return _collect(controllers, [results[s] for s in seeds])


def _collect(controllers: dict[str, Any],
             per_seed_results: list[dict[str, tuple[dict[str, Any], Trajectory]]]
             ) -> tuple[dict[str, dict], dict[str, list[Trajectory]]]:
    """The aggregated table and the trajectories, in seed order."""
    table = {name: _aggregate([r[name][0] for r in per_seed_results]) for name in controllers}
    runs = {name: [r[name][1] for r in per_seed_results] for name in controllers}
    return table, runs
