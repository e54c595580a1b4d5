"""The main job: ``spacecraft control --scenario docking --seeds 10 --out DIR``.

Runs fixed LQR (t = 0 design), PD, adaptive LQR and oracle LQR on the same
seeds of a registered environment (slew task: a random reference within
+-10 deg per axis from rest, 250 s), prints the comparison table and writes
``metrics.json`` (per seed and aggregated), ``results.csv`` (one row per
controller and seed) and ``comparison.png`` (attitude error, torque, tip
deflection, identified vs true modal frequencies for seed 0).
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym

from controllers import (
    LQR,
    PD,
    AdaptiveLQR,
    LQRWeights,
    OracleLQR,
    compare,
    episode_metrics,
    run_episode,
)
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import ENV_IDS, DockingModule, DockingScenario, SolarRotationScenario, env_id
from spacecraft_lab.plots import plot_control_comparison
from spacecraft_lab.reporting import control_table

__all__ = ["CONTROLLERS", "CONTROLLER_KEYS", "SCENARIO_NAMES", "control_task", "run_control",
           "scenario_override"]

#: Scenarios with a registered environment id.
SCENARIO_NAMES = tuple(ENV_IDS.values())


def CONTROLLERS(weights: LQRWeights) -> dict[str, Any]:
    """Name -> factory ``env -> Controller`` for the comparison."""
    return {
        "LQR (fixed)": lambda env: LQR(env, weights),
        "PD": lambda env: PD(env),
        "adaptive LQR": lambda env: AdaptiveLQR(env, weights=weights),
        "oracle LQR": lambda env: OracleLQR(env, weights),
    }


#: Short names for sweep files and the command line -> keys of :func:`CONTROLLERS`.
CONTROLLER_KEYS = {"lqr": "LQR (fixed)", "pd": "PD", "adaptive-lqr": "adaptive LQR",
                   "oracle-lqr": "oracle LQR"}


def scenario_override(module_mass: float | None = None,
                      rotation_rate: float | None = None) -> dict[str, Any]:
    """``gym.make`` keywords for a variant of the paper's scenarios.

    Parameters
    ----------
    module_mass : float, optional
        Mass of each of the two docking modules, kg (paper: 600); they dock
        at 100 s and 180 s on the yaw axis as in the paper.
    rotation_rate : float, optional
        Solar-paddle rotation rate, deg/s (paper: 0.2).

    Returns
    -------
    dict
        ``{"scenario": Scenario}`` or empty when neither is given.
    """
    if module_mass is not None and rotation_rate is not None:
        raise ValueError("give module_mass (docking) or rotation_rate (solar rotation), not both")
    if module_mass is not None:
        return {"scenario": DockingScenario(modules=(
            DockingModule(mass=float(module_mass), time=100.0, position=(0.0, 0.0, 3.0)),
            DockingModule(mass=float(module_mass), time=180.0, position=(0.0, 0.0, -3.0))))}
    if rotation_rate is not None:
        return {"scenario": SolarRotationScenario(rate_deg_s=float(rotation_rate))}
    return {}


@single_threaded_blas
def control_task(*, controller: str, seed: int, scenario: str = "docking", task: str = "slew",
                 module_mass: float | None = None, rotation_rate: float | None = None,
                 max_torque: float | None = None, snr_db: float | None = 40.0,
                 torque_weight: float | None = None, max_steps: int | None = None) -> dict:
    """One closed-loop episode: one controller on one seed (a sweep task).

    A fresh environment and controller are built, so the result is a
    function of the arguments alone.

    Parameters
    ----------
    controller : {"lqr", "pd", "adaptive-lqr", "oracle-lqr"}
        See :data:`CONTROLLER_KEYS`.
    seed : int
        Episode seed (reference, noise, dither).
    scenario : {"constant", "docking", "solar_rotation"}
    task : {"slew", "regulation"}
    module_mass, rotation_rate : float, optional
        Scenario variants (:func:`scenario_override`).
    max_torque : float, optional
        N m per unit action (environment default 10).
    snr_db : float or None
        Measurement SNR (environment default 40 dB).
    torque_weight : float, optional
        LQR torque weight per (N m)^2 (:class:`LQRWeights`, default 0.3).
    max_steps : int, optional
        Episode length in steps (default: the registered 2500 = 250 s).

    Returns
    -------
    dict
        ``{"metrics": the episode metrics of :func:`episode_metrics`,
        "timings": {"episode_s": wall time of the episode}}``.
    """
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"scenario must be one of {sorted(SCENARIO_NAMES)}, got {scenario!r}")
    if controller not in CONTROLLER_KEYS:
        raise ValueError(f"controller must be one of {sorted(CONTROLLER_KEYS)}, "
                         f"got {controller!r}")
    kwargs: dict[str, Any] = {"task": task, "snr_db": snr_db,
                              **scenario_override(module_mass, rotation_rate)}
    if max_torque is not None:
        kwargs["max_torque"] = float(max_torque)
    weights = LQRWeights() if torque_weight is None else LQRWeights(torque=float(torque_weight))
    env = gym.make(env_id(scenario), **kwargs)
    try:
        ctrl = CONTROLLERS(weights)[CONTROLLER_KEYS[controller]](env)
        start = time.perf_counter()
        traj = run_episode(env, ctrl, seed=int(seed),
                           max_steps=None if max_steps is None else int(max_steps))
        elapsed = time.perf_counter() - start
        metrics = episode_metrics(traj, env.unwrapped.model)
    finally:
        env.close()
    return {"metrics": metrics, "timings": {"episode_s": elapsed}}


def run_control(scenario: str = "docking", seeds: int = 10, out: str | Path = "results/control",
                *, env_kwargs: dict[str, Any] | None = None,
                weights: LQRWeights | None = None, progress: bool = True) -> dict:
    """Compare the controllers and write the artefacts.

    Parameters
    ----------
    scenario : {"constant", "docking", "solar_rotation"}
    seeds : int
        Episode seeds 0 .. seeds-1 (same for every controller).
    out : path
    env_kwargs : dict, optional
        Extra keywords for ``gym.make`` (default ``task="slew"``), e.g. a
        heavier docking module or a faster paddle rotation.
    weights : LQRWeights, optional
        LQR weights shared by the LQR designs.
    """
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"scenario must be one of {sorted(SCENARIO_NAMES)}, got {scenario!r}")
    kwargs = {"task": "slew", **(env_kwargs or {})}
    weights = weights or LQRWeights()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    def make_env() -> gym.Env:
        return gym.make(env_id(scenario), **kwargs)

    table, first = compare(CONTROLLERS(weights), make_env, list(range(seeds)),
                           progress=progress)
    env = make_env()
    model = env.unwrapped.model
    text = control_table(table, oracle="oracle LQR")
    metrics = {"scenario": scenario, "seeds": seeds, "env_kwargs": {k: repr(v) for k, v in
                                                                    kwargs.items()},
               "weights": weights.__dict__, "controllers": table}
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, default=float))
    (out / "table.md").write_text(text)
    with open(out / "results.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        cols = ["attitude_rms_deg", "attitude_rms_after_deg", "attitude_peak_deg",
                "vibration_rms_mm", "torque_rms_Nm", "effort_N2m2s", "return", "stable"]
        writer.writerow(["controller", "seed", *cols, "settling_s"])
        for name, row in table.items():
            for m in row["per_seed"]:
                writer.writerow([name, m["seed"], *[m[c] for c in cols],
                                 ";".join("" if s is None else f"{s:.1f}"
                                          for s in m["settling_s"])])
    plot_control_comparison(first, model, out / "comparison.png",
                    title=f"{scenario}, slew, seed 0 (dashed: docking events)")
    env.close()
    return metrics
