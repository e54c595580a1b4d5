"""The main job: ``spacecraft control --scenario paddle_rotation --seeds 10 --out DIR``.

Runs the controllers of :func:`CONTROLLERS` (fixed, robust and gain-scheduled
LQG, PD, adaptive LQG, the output-feedback oracle LQG and the full-state
oracle) on the same seeds of a registered environment, prints the comparison
table and writes ``metrics.json`` (per seed and aggregated: median,
quartiles, mean, spread, verdicts), ``results.csv`` (one row per controller
and seed) and ``comparison.png`` (median and interquartile band over seeds of
the attitude error, vibration and torque; the identified rigid-body gain's
error and modal frequencies).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import time
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym

from controllers import (
    PD,
    AdaptiveLQG,
    BinaryExcitation,
    ClairvoyantLQG,
    ComparisonInterrupted,
    FixedLQG,
    LQRWeights,
    OracleLQG,
    OracleLQR,
    RobustLQG,
    ScheduledLQG,
    TrueModelIdentifier,
    compare,
    episode_metrics,
    fast_identifier,
    run_episode,
    same_start_ceiling,
    set_integral_settle,
    structured_identifier,
    window_ceiling,
)
from controllers.lqg import INTEGRAL_SETTLE_S, check_settle_time
from identifiers import PhysicalFitIdentifier
from spacecraft_conventions import single_threaded_blas
from spacecraft_env import (
    DEFAULT_SNR_DB,
    ENV_IDS,
    SCENARIOS,
    ConstantScenario,
    DockingModule,
    DockingScenario,
    Fault,
    FaultInjection,
    SolarRotationScenario,
    check_parameter,
    env_id,
)
from spacecraft_lab.plots import plot_control_comparison
from spacecraft_lab.reporting import (
    CEILING,
    FAST_ADAPTIVE_LQG,
    SAME_START_CEILING,
    WINDOW_CEILING,
    control_table,
)
from spacecraft_lab.sweeps.backends import check_workers

__all__ = [
    "ALL_CONTROLLER_NAMES",
    "CEILING",
    "CONTROLLERS",
    "CONTROLLER_KEYS",
    "CONTROLLER_NAMES",
    "FAST",
    "ORACLE",
    "PHYSICAL",
    "SAME_LAW",
    "SAME_START_CEILING",
    "SCENARIO_NAMES",
    "STRUCTURED_RPBSID",
    "WINDOW_CEILING",
    "control_task",
    "env_kwargs_for",
    "run_control",
]

#: Scenarios with a registered environment id.
SCENARIO_NAMES = tuple(ENV_IDS.values())
#: The LQG of the adaptive loop's law re-designed every step on the true model, its
#: filter assuming the baselines' process noise (:class:`controllers.OracleLQG`); the
#: ratios are taken against :data:`CEILING` and :data:`SAME_START_CEILING`.
ORACLE = "oracle LQG"
#: The adaptive loop's own law flown on the true model: what identification costs.
SAME_LAW = "same-law oracle"


def _build(name: str, weights: LQRWeights, env: gym.Env,
           integral_settle_s: float | None = None) -> Any:
    """The controller ``name`` (a key of :func:`CONTROLLERS`) for ``env``, its LQG
    laws' integral waiting ``integral_settle_s`` (None: the default)."""
    controller = _construct(name, weights, env)
    if integral_settle_s is not None:
        set_integral_settle(controller, integral_settle_s)
    return controller


def _construct(name: str, weights: LQRWeights, env: gym.Env) -> Any:
    if name == "fixed LQG":
        return FixedLQG(env, weights)
    if name == "robust LQG":
        return RobustLQG(env, weights)
    if name == "scheduled LQG":
        return ScheduledLQG(env, weights)
    if name == "PD":
        return PD(env)
    if name == "adaptive LQG":
        return AdaptiveLQG(env, weights=weights)
    if name == FAST:
        return AdaptiveLQG(env, weights=weights, identifier=fast_identifier(env))
    if name == PHYSICAL:
        layout = env.unwrapped.observation_layout.sensors()
        return AdaptiveLQG(env, weights=weights, identifier=PhysicalFitIdentifier(
            layout, dt=env.unwrapped.model.dt))
    if name == STRUCTURED_RPBSID:
        return AdaptiveLQG(env, weights=weights, identifier=structured_identifier(env))
    if name == SAME_LAW:
        return AdaptiveLQG(env, weights=weights, identifier=TrueModelIdentifier(env),
                           excitation=BinaryExcitation(0.0, 0.0))
    if name == ORACLE:
        return OracleLQG(env, weights)
    if name == CEILING:
        return ClairvoyantLQG(env, weights)
    if name == SAME_START_CEILING:
        return same_start_ceiling(env, weights)
    if name == WINDOW_CEILING:
        return window_ceiling(env, weights=weights)
    if name == "full-state oracle":
        return OracleLQR(env, weights)
    raise ValueError(f"unknown controller {name!r}")


#: The adaptive law on the physical model fitted to its warm-up and held
#: (:class:`identifiers.PhysicalFitIdentifier`): not in the default comparison (it
#: does not follow turning paddles; docs/results/control.md).
PHYSICAL = "adaptive LQG, physical fit"
#: The adaptive law on the structured recursive identifier
#: (:func:`controllers.fast_identifier`): the adaptive LQG's default until
#: 2026-11-28, about 0.5 s of computation per 250 s episode against 11-32 s.
FAST = FAST_ADAPTIVE_LQG
#: The adaptive law on a recursive PBSID with an exact rigid block
#: (:func:`controllers.structured_identifier`: :class:`identifiers.StructuredRPBSID` with
#: its closed-loop settings since 2026-11-28): the source paper's family of algorithms in
#: the loop (its flexible part the classical RPBSID on the deflections by default).
STRUCTURED_RPBSID = "adaptive LQG, structured RPBSID"


#: The controllers of the default comparison, in their table order.
CONTROLLER_NAMES = ("fixed LQG", "robust LQG", "scheduled LQG", "PD", "adaptive LQG", FAST,
                    SAME_LAW, ORACLE, "full-state oracle", WINDOW_CEILING, SAME_START_CEILING,
                    CEILING)
#: Every controller the comparison can fly: the default ones and the options.
ALL_CONTROLLER_NAMES = (*CONTROLLER_NAMES, PHYSICAL, STRUCTURED_RPBSID)


def CONTROLLERS(weights: LQRWeights, integral_settle_s: float | None = None) -> dict[str, Any]:
    """Name -> factory ``env -> Controller`` for every controller of
    :data:`ALL_CONTROLLER_NAMES` (picklable, so the comparison can run its seeds on a
    process pool); ``integral_settle_s``: the LQG laws' integral settle time, s
    (:func:`controllers.set_integral_settle`; None: the default).

    Returns
    -------
    dict
        Display name -> picklable factory ``env -> Controller``.
    """
    return {name: partial(_build, name, weights, integral_settle_s=integral_settle_s)
            for name in ALL_CONTROLLER_NAMES}


#: Short names for sweep files and the command line -> keys of :func:`CONTROLLERS`.
CONTROLLER_KEYS = {"fixed-lqg": "fixed LQG", "robust-lqg": "robust LQG",
                   "scheduled-lqg": "scheduled LQG", "pd": "PD", "adaptive-lqg": "adaptive LQG",
                   "adaptive-lqg-fast": FAST, "adaptive-lqg-physical": PHYSICAL,
                   "adaptive-lqg-structured-rpbsid": STRUCTURED_RPBSID, "same-law-oracle": SAME_LAW,
                   "oracle-lqg": ORACLE, "oracle-lqr": "full-state oracle",
                   "ceiling": CEILING, "same-start-ceiling": SAME_START_CEILING,
                   "window-ceiling": WINDOW_CEILING}


def env_kwargs_for(scenario: str, *, task: str = "slew", module_mass: float | None = None,
                   rotation_rate: float | None = None, paddle_angle: float | None = None,
                   snr_db: float | None = DEFAULT_SNR_DB, max_torque: float | None = None,
                   actuator_delay_steps: int = 0, torque_rate_limit: float | None = None,
                   disturbance_torque: float = 0.0, mass_centre_shift: bool = False,
                   capture_momentum: Sequence[float] | None = None,
                   initial_attitude: float | None = None,
                   disturbance_std: float = 0.0) -> dict[str, Any]:
    """``gym.make`` keywords for a registered scenario and its variants.

    Parameters
    ----------
    scenario : str
        A name of :data:`SCENARIO_NAMES`.
    task : {"slew", "regulation"}
    module_mass : float, optional
        Mass of each of the two docking modules, kg (paper: 600; docking
        only); they dock at 100 s and 180 s on the yaw axis as in the paper.
    rotation_rate : float, optional
        Paddle rotation rate, deg/s (rotation scenarios only).
    paddle_angle : float, optional
        Paddle angle at t = 0, deg (constant and rotation scenarios).
    snr_db, max_torque, actuator_delay_steps, torque_rate_limit, disturbance_torque
        Passed to :class:`spacecraft_env.FlexibleSpacecraftEnv`.
    mass_centre_shift : bool
        Docking only: the modules move the system mass centre
        (:class:`spacecraft_env.DockingScenario`).
    capture_momentum : (3,) sequence of float, optional
        Docking only: angular momentum (N m s, body frame) each module
        brings at capture, conserved by the capture (default: the modules
        arrive co-rotating, the paper's assumption).
    initial_attitude : float, optional
        Regulation only: each initial attitude angle is drawn uniformly in
        +-this, deg (default: the env's 2; 0: held at rest).
    disturbance_std : float
        Standard deviation of a white external torque on every axis, N m (default 0:
        no process noise). The ceiling's filter knows it; with it the stationary
        cost has a floor above zero.

    Returns
    -------
    dict
        The keywords, checked against the parameter limits.

    Raises
    ------
    ValueError
        For a variant the scenario does not have.
    """
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"scenario must be one of {sorted(SCENARIO_NAMES)}, got {scenario!r}")
    given = {"snr_db": snr_db, "max_torque": max_torque,
             "actuator_delay_steps": actuator_delay_steps,
             "torque_rate_limit": torque_rate_limit, "disturbance_torque": disturbance_torque,
             "module_mass": module_mass, "rotation_rate": rotation_rate,
             "paddle_angle": paddle_angle}
    checked = {k: None if v is None else check_parameter(k, v) for k, v in given.items()}
    for value in capture_momentum or ():
        check_parameter("capture_momentum", value)
    kwargs: dict[str, Any] = {"task": task, "snr_db": checked["snr_db"],
                              "actuator_delay_steps": checked["actuator_delay_steps"],
                              "torque_rate_limit": checked["torque_rate_limit"],
                              "disturbance_torque": checked["disturbance_torque"]}
    if max_torque is not None:
        kwargs["max_torque"] = checked["max_torque"]
    if disturbance_std:
        kwargs["disturbance_std"] = check_parameter("disturbance_std", disturbance_std)
    if initial_attitude is not None:
        if task != "regulation":
            raise ValueError("initial_attitude applies to the regulation task (the slew "
                             "starts at zero)")
        kwargs["initial_attitude_deg"] = check_parameter("initial_attitude_deg",
                                                         initial_attitude)
    if scenario not in SCENARIOS:
        # the task family draws its own plant every episode: no scenario variants
        variants = {"module_mass": module_mass, "rotation_rate": rotation_rate,
                    "paddle_angle": paddle_angle, "capture_momentum": capture_momentum}
        given = sorted(k for k, v in variants.items() if v is not None)
        if given or mass_centre_shift:
            raise ValueError(f"{', '.join(given) or 'mass_centre_shift'} does not apply to "
                             f"the {scenario!r} scenario (it draws its plant every episode)")
        return kwargs
    base = SCENARIOS[scenario]()
    rotating = isinstance(base, SolarRotationScenario)
    if module_mass is not None:
        if not isinstance(base, DockingScenario):
            raise ValueError(f"module_mass applies to the docking scenario, not {scenario!r}")
        base = DockingScenario(modules=(
            DockingModule(mass=float(module_mass), time=100.0, position=(0.0, 0.0, 3.0)),
            DockingModule(mass=float(module_mass), time=180.0, position=(0.0, 0.0, -3.0))))
    if mass_centre_shift or capture_momentum is not None:
        if not isinstance(base, DockingScenario):
            raise ValueError(f"mass_centre_shift and capture_momentum apply to the docking "
                             f"scenario, not {scenario!r}")
        modules = base.modules
        if capture_momentum is not None:
            modules = tuple(dataclasses.replace(m, angular_momentum=tuple(capture_momentum))
                            for m in modules)
        base = dataclasses.replace(base, modules=modules,
                                   mass_centre_shift=bool(mass_centre_shift))
    if rotation_rate is not None:
        if not rotating:
            raise ValueError(f"rotation_rate applies to the rotation scenarios, not {scenario!r}")
        base = dataclasses.replace(base, rate_deg_s=float(rotation_rate))
    if paddle_angle is not None:
        if rotating:
            base = dataclasses.replace(base, initial_angle_deg=float(paddle_angle))
        elif isinstance(base, ConstantScenario):
            base = ConstantScenario(paddle_angle_deg=float(paddle_angle))
        else:
            raise ValueError(f"paddle_angle applies to the constant and rotation scenarios, "
                             f"not {scenario!r}")
    if base != SCENARIOS[scenario]():
        kwargs["scenario"] = base
    return kwargs


def _check_control(*, controller: str, seed: int | None = None,
                   scenario: str = "paddle_rotation", task: str = "slew",
                   module_mass: float | None = None, rotation_rate: float | None = None,
                   paddle_angle: float | None = None, max_torque: float | None = None,
                   snr_db: float | None = DEFAULT_SNR_DB, torque_weight: float | None = None,
                   max_steps: int | None = None) -> dict[str, Any]:
    """:func:`control_task`'s values checked without running it; its ``gym.make``
    keywords (a sweep file is checked with it before any task runs).

    Raises
    ------
    ValueError
        An unknown controller, scenario or task, a variant the scenario does not
        have, a non-positive torque weight or episode length.
    """
    if controller not in CONTROLLER_KEYS:
        raise ValueError(f"controller must be one of {sorted(CONTROLLER_KEYS)}, "
                         f"got {controller!r}")
    if task not in ("slew", "regulation"):
        raise ValueError(f"task must be 'slew' or 'regulation', got {task!r}")
    if torque_weight is not None:
        check_parameter("torque_weight", torque_weight)
    if max_steps is not None:
        check_parameter("max_steps", max_steps)
    return env_kwargs_for(scenario, task=task, module_mass=module_mass,
                          rotation_rate=rotation_rate, paddle_angle=paddle_angle,
                          snr_db=snr_db, max_torque=max_torque)


@single_threaded_blas
def control_task(*, controller: str, seed: int, scenario: str = "paddle_rotation",
                 task: str = "slew", module_mass: float | None = None,
                 rotation_rate: float | None = None, paddle_angle: float | None = None,
                 max_torque: float | None = None, snr_db: float | None = DEFAULT_SNR_DB,
                 torque_weight: float | None = None, max_steps: int | None = None) -> dict:
    """One closed-loop episode: one controller on one seed (a sweep task).

    A fresh environment and controller are built, so the result is a
    function of the arguments alone.

    Parameters
    ----------
    controller : str
        A key of :data:`CONTROLLER_KEYS`.
    seed : int
        Episode seed (reference, noise, excitation).
    scenario : str
        A name of :data:`SCENARIO_NAMES`.
    task, module_mass, rotation_rate, paddle_angle, max_torque, snr_db
        See :func:`env_kwargs_for`.
    torque_weight : float, optional
        LQR torque weight per (N m)^2 (:class:`LQRWeights`' default otherwise).
    max_steps : int, optional
        Episode length in steps (default: the registered 2500 = 250 s).

    Returns
    -------
    dict
        ``{"metrics": the episode metrics of :func:`episode_metrics`,
        "timings": {"episode_s": wall time of the episode}}``.
    """
    kwargs = _check_control(controller=controller, scenario=scenario, task=task,
                            module_mass=module_mass, rotation_rate=rotation_rate,
                            paddle_angle=paddle_angle, max_torque=max_torque, snr_db=snr_db,
                            torque_weight=torque_weight, max_steps=max_steps)
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


control_task.check_params = _check_control      # type: ignore[attr-defined]


def run_control(scenario: str = "paddle_rotation", seeds: int = 10,
                out: str | Path = "results/control", *, env_kwargs: dict[str, Any] | None = None,
                weights: LQRWeights | None = None, controllers: Sequence[str] | None = None,
                steps: int | None = None, progress: bool = True,
                save_trajectories: bool = False, workers: int | None = None,
                integral_settle_s: float | None = None, faults: Sequence[Fault] = ()) -> dict:
    """Compare the controllers and write the artefacts.

    Parameters
    ----------
    scenario : str
        A name of :data:`SCENARIO_NAMES`.
    seeds : int
        Episode seeds 0 .. seeds-1 (same for every controller).
    out : path
    env_kwargs : dict, optional
        ``gym.make`` keywords (:func:`env_kwargs_for`; default: its defaults,
        the slew task).
    weights : LQRWeights, optional
        LQR weights shared by the LQG designs.
    controllers : sequence of str, optional
        Keys of :data:`CONTROLLER_KEYS` (default: those of :data:`CONTROLLER_NAMES`,
        i.e. all but ``adaptive-lqg-physical`` and ``adaptive-lqg-structured-rpbsid``).
    steps : int, optional
        Episode length, steps of 0.1 s (default: the registered 2500).
    save_trajectories : bool
        Also write every episode as ``trajectories/<controller>-seed<k>.npz``
        (:meth:`controllers.Trajectory.save`).
    workers : int, optional
        Processes that run the seeds side by side (default: one per core,
        at most one per seed); the results do not depend on it.
    integral_settle_s : float, optional
        Seconds every attitude error must stay in the integral's band before
        the LQG designs integrate (default: :data:`controllers.lqg.INTEGRAL_SETTLE_S`;
        0 reproduces the integral at once of versions before 2026-11-26).
    faults : sequence of spacecraft_env.Fault
        Faults injected on schedule (:class:`spacecraft_env.FaultInjection`; default
        none). The ceilings do not know them: under a fault they are no bound.

    Returns
    -------
    dict
        What ``metrics.json`` holds: the table per controller, the settings and the
        files written.
    """
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"scenario must be one of {sorted(SCENARIO_NAMES)}, got {scenario!r}")
    kwargs = env_kwargs if env_kwargs is not None else env_kwargs_for(scenario)
    if steps is not None:
        kwargs = {**kwargs, "max_episode_steps": int(steps)}
    weights = weights or LQRWeights()
    if integral_settle_s is not None:
        check_settle_time(integral_settle_s)
    factories = CONTROLLERS(weights, integral_settle_s)
    if controllers is None:
        factories = {name: factories[name] for name in CONTROLLER_NAMES}
    else:
        unknown = sorted(set(controllers) - set(CONTROLLER_KEYS))
        if unknown:
            raise ValueError(f"unknown controllers {unknown}; expected {sorted(CONTROLLER_KEYS)}")
        factories = {CONTROLLER_KEYS[k]: factories[CONTROLLER_KEYS[k]] for k in controllers}
    check_workers(workers)           # before anything is written
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    faults = tuple(faults)
    make_env = partial(_make_env, env_id(scenario), faults, kwargs)
    workers = (os.cpu_count() or 1) if workers is None else workers
    try:
        table, runs = compare(factories, make_env, list(range(seeds)), progress=progress,
                              workers=workers)
    except ComparisonInterrupted as stop:
        # Ctrl-C: write what the completed seeds say, then let the interrupt go on
        if stop.completed:
            _write_control(out, scenario, stop.completed, kwargs, weights, stop.table,
                           stop.trajectories, steps, make_env, interrupted=stop.total,
                           integral_settle_s=integral_settle_s)
        raise
    if save_trajectories:
        folder = out / "trajectories"
        folder.mkdir(exist_ok=True)
        for name, trajs in runs.items():
            for seed, traj in enumerate(trajs):
                traj.save(folder / f"{name.replace(' ', '-')}-seed{seed}.npz")
    return _write_control(out, scenario, seeds, kwargs, weights, table, runs, steps, make_env,
                          integral_settle_s=integral_settle_s)


#: The common cost over the whole episode, from the end of the adaptive loop's start and
#: from 100 s, and their splits, first in ``results.csv``.
COST_COLUMNS = ("cost", "cost_attitude", "cost_rate", "cost_deflection", "cost_torque",
                "cost_excitation", "cost_after_start", "cost_after_100s",
                "cost_attitude_after_100s", "cost_rate_after_100s",
                "cost_deflection_after_100s", "cost_torque_after_100s",
                "cost_excitation_after_100s")


def _make_env(name: str, faults: tuple[Fault, ...], kwargs: dict[str, Any]) -> gym.Env:
    """``gym.make(name, **kwargs)``, behind :class:`spacecraft_env.FaultInjection` when
    ``faults`` are given (module level: picklable for the process pool)."""
    env = gym.make(name, **kwargs)
    return FaultInjection(env, faults) if faults else env


def _write_control(out: Path, scenario: str, seeds: int, kwargs: dict[str, Any],
                   weights: LQRWeights, table: dict, runs: dict, steps: int | None,
                   make_env: Any, interrupted: int | None = None,
                   integral_settle_s: float | None = None) -> dict:
    """``metrics.json``, ``table.md``, ``results.csv`` and ``comparison.png`` of a comparison
    (``interrupted``: the number of seeds asked for, when fewer finished)."""
    env = make_env()
    model = env.unwrapped.model
    text = control_table(table, ceiling=CEILING if CEILING in table else None,
                         same_start=SAME_START_CEILING if SAME_START_CEILING in table else None,
                         window=WINDOW_CEILING if WINDOW_CEILING in table else None)
    if interrupted is not None:
        text = (f"Interrupted: {seeds} of {interrupted} seeds completed; the table holds "
                f"those.\n\n{text}")
    metrics = {"scenario": scenario, "seeds": seeds, "seeds_requested": interrupted or seeds,
               "env_kwargs": {k: repr(v) for k, v in kwargs.items()},
               "faults": [dataclasses.asdict(f) for f in getattr(env, "faults", ())],
               "weights": weights.__dict__,
               "integral_settle_s": (INTEGRAL_SETTLE_S if integral_settle_s is None
                                     else float(integral_settle_s)),
               "controllers": table}
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, default=float))
    (out / "table.md").write_text(text)
    cols = [*COST_COLUMNS, "attitude_rms_after_100s_deg", "vibration_rms_after_100s_mm",
            "attitude_rms_deg", "attitude_peak_deg", "vibration_rms_mm", "torque_rms_Nm",
            "effort_N2m2s", "return",
            "envelope_growth_per_100s", "excitation_rms_Nm", "rejected_share",
            "fallback_share", "fallback_share_after_60s", "gain_error_after_60s",
            "gain_coverage_after_60s", "verdict"]
    with open(out / "results.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["controller", "seed", *cols, "settling_s",
                         "fallback_causes_after_60s"])
        for name, row in table.items():
            for m in row["per_seed"]:
                writer.writerow([name, m["seed"], *[m[c] for c in cols],
                                 ";".join("" if s is None else f"{s:.1f}"
                                          for s in m["settling_s"]),
                                 ";".join(f"{cause}:{share:.4f}" for cause, share
                                          in m.get("fallback_causes_after_60s", {}).items())])
    angle = ""
    scen = model.scenario
    if isinstance(scen, SolarRotationScenario):
        t_end = (steps or env.spec.max_episode_steps) * model.dt
        angle = (f", paddles {scen.initial_angle_deg:g} -> "
                 f"{scen.initial_angle_deg + scen.rate_deg_s * t_end:g} deg")
    plot_control_comparison(runs, model, out / "comparison.png",
                            title=f"{scenario}{angle}, {kwargs.get('task', 'slew')}, "
                                  f"{seeds} seeds: median and interquartile band\n"
                                  + ("(dashed: events, " if model.scenario.event_times()
                                     else "(") + "dotted: 40 s and 100 s)")
    env.close()
    return metrics
