"""Closed-loop harness: run controllers (or RL policies) on the environments.

:func:`run_episode` rolls one episode and returns a :class:`Trajectory`;
:func:`episode_metrics` scores it; :func:`compare` runs several controllers
on the same seeds and collects mean and spread. Tables and plots of the
results are the application layer's (``spacecraft_lab``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from controllers.base import Controller
from spacecraft_conventions import DEG_PER_RAD, single_threaded_blas

__all__ = ["Trajectory", "compare", "episode_metrics", "run_episode"]


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
    controller_stats : dict
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
    controller_stats: dict = field(default_factory=dict)


def _first(freqs: np.ndarray, count: int) -> np.ndarray:
    """The ``count`` lowest frequencies, NaN-padded."""
    out = np.full(count, np.nan)
    out[:min(count, freqs.size)] = freqs[:count]
    return out


def run_episode(env: gym.Env, controller: Controller, seed: int | None = None,
                options: dict[str, Any] | None = None, max_steps: int | None = None,
                freq_every: int = 25, n_freq: int = 4) -> Trajectory:
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
        Step budget; default the spec's ``max_episode_steps`` (2500 for the
        registered ids), or 2500 for an env built without ``gym.make``, so an
        unwrapped env (no time limit) still ends.
    freq_every, n_freq : int
        Sampling of identified/true modal frequencies.
    """
    base = env.unwrapped
    if max_steps is None:
        spec = getattr(env, "spec", None)
        max_steps = (spec.max_episode_steps if spec is not None and spec.max_episode_steps
                     else 2500)
    obs, info = env.reset(seed=seed, options=options)
    controller.reset(seed)
    observations, actions, torques, states, refs, rewards = [obs], [], [], [info["state"]], \
        [info["reference"]], []
    ident = getattr(controller, "identifier", None)
    freq_t, freq_id, freq_true = [], [], []
    terminated = truncated = False
    k = 0
    with single_threaded_blas:
        while not (terminated or truncated) and k < max_steps:
            action = controller.act(obs, info)
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
                               else _first(model.modal()[0], n_freq))
                freq_true.append(_first(base.model.modal(info["time"])[0], n_freq))
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
        controller_stats=dict(getattr(controller, "stats", {})),
    )


def episode_metrics(traj: Trajectory, model: Any, settle_tol_deg: float = 0.05,
                    stable_bound_deg: float = 1.0, after_s: float = 50.0) -> dict[str, Any]:
    """Scores of one episode.

    Returns
    -------
    dict
        ``attitude_rms_deg`` and ``attitude_peak_deg`` (true attitude error,
        all axes, after the first step), ``attitude_rms_after_deg`` (the same
        RMS from ``after_s`` on, e.g. once an identifier has warmed up),
        ``settling_s`` (per scenario event: time after the event until the
        error stays below ``settle_tol_deg``;
        None if it never does), ``vibration_rms_mm`` (true tip deflections),
        ``torque_rms_Nm`` and ``effort_N2m2s`` (integral of |u|^2),
        ``return``, ``stable`` (not terminated, finite, and the error over the
        last 10 % of the episode below ``stable_bound_deg``).
    """
    layout = model.output_layout
    err = (traj.states[1:] @ model.C[layout.slice("attitude")].T - traj.reference[1:]) \
        * DEG_PER_RAD
    err_norm = np.abs(err).max(axis=1)
    defl = traj.states[1:] @ model.C[layout.slice("deflection")].T * 1e3
    dt = model.dt
    settling = []
    for event in traj.events or ():
        after = traj.time >= event
        if not after.any():
            settling.append(None)
            continue
        outside = np.flatnonzero(after & (err_norm > settle_tol_deg))
        if outside.size == 0:
            settling.append(0.0)
        elif outside[-1] == len(err_norm) - 1:
            settling.append(None)
        else:
            settling.append(float(traj.time[outside[-1] + 1] - event))
    tail = err_norm[-max(1, len(err_norm) // 10):]
    finite = bool(np.all(np.isfinite(traj.states)))
    late = traj.time >= after_s
    return {
        "attitude_rms_deg": float(np.sqrt(np.mean(err**2))),
        "attitude_rms_after_deg": (float(np.sqrt(np.mean(err[late] ** 2))) if late.any()
                                   else float("nan")),
        "attitude_peak_deg": float(err_norm.max()),
        "settling_s": settling,
        "vibration_rms_mm": float(np.sqrt(np.mean(defl**2))),
        "torque_rms_Nm": float(np.sqrt(np.mean(traj.torque**2))),
        "effort_N2m2s": float(np.sum(traj.torque**2) * dt),
        "return": float(traj.rewards.sum()),
        "stable": bool(finite and not traj.terminated and tail.max() < stable_bound_deg),
    }


def compare(controllers: dict[str, Callable[[Any], Controller]], make_env: Callable[[], Any],
            seeds: Sequence[int], options: dict[str, Any] | None = None,
            progress: bool = True) -> tuple[dict[str, dict], dict[str, Trajectory]]:
    """Run every controller on the same seeds.

    Parameters
    ----------
    controllers : dict
        Name -> factory ``env -> Controller``.
    make_env : callable
        Returns a fresh environment.
    seeds : sequence of int
    options : dict, optional
        ``env.reset`` options.

    Returns
    -------
    table : dict
        Name -> {"per_seed": [metrics...], "mean": {...}, "std": {...},
        "stable_runs": int, "runs": int}.
    first : dict
        Name -> trajectory of the first seed (for plots).
    """
    table, first = {}, {}
    bar = tqdm(total=len(controllers) * len(seeds), desc="closed loop", disable=not progress)
    for name, factory in controllers.items():
        env = make_env()
        ctrl = factory(env)
        per_seed = []
        for i, seed in enumerate(seeds):
            traj = run_episode(env, ctrl, seed=seed, options=options)
            m = episode_metrics(traj, env.unwrapped.model)
            m["seed"] = int(seed)
            m["controller_stats"] = traj.controller_stats
            per_seed.append(m)
            if i == 0:
                first[name] = traj
            bar.update()
        env.close()
        keys = ["attitude_rms_deg", "attitude_rms_after_deg", "attitude_peak_deg",
                "vibration_rms_mm", "torque_rms_Nm", "effort_N2m2s", "return"]
        arr = {k: np.array([m[k] for m in per_seed]) for k in keys}
        table[name] = {
            "per_seed": per_seed,
            "mean": {k: float(np.mean(v)) for k, v in arr.items()},
            "std": {k: float(np.std(v)) for k, v in arr.items()},
            "stable_runs": int(sum(m["stable"] for m in per_seed)),
            "runs": len(per_seed),
        }
    bar.close()
    return table, first
