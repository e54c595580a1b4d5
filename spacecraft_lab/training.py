"""Training stable-baselines3 agents on the spacecraft environments.

``spacecraft train --algo ppo|sac --features F --timesteps N --seeds S
[--scenario family] [--randomize] --out DIR`` calls :func:`run_training`:
for each seed it trains an agent on a registered environment (slew task;
``--scenario family`` flies a new plant of
:class:`spacecraft_env.TaskFamily` every episode, the task where a model
matters; ``--randomize`` draws a scenario variant every episode, e.g.
docking masses, times and offsets), Monitor-wrapped, with observations and
rewards normalized by ``VecNormalize``.

``F`` (:data:`FEATURES`) appends nothing (``none``), or observes the attitude
error and the rate alone, in nominal units (``attitude-error``: 1 deg, 0.1 deg/s;
:class:`spacecraft_env.NominalUnits`), the observation of the linear policies ARS
(``--algo ars``) trains; the identifier's
physical estimates, :class:`controllers.PhysicalFeatures` (``physical``:
rigid-body gain, dominant modes, their uncertainty and a change flag in a
fixed normalized frame) or the same vector from the truth,
:class:`controllers.PrivilegedFeatures` (``privileged``, the ceiling); the
identifier's raw model features, :class:`controllers.IdentifiedModelFeatures`
(``identified``: the identifier restarts every episode;
``identified-kept``: it is carried over episode resets;
``identified-kept-no-state``: carried over, without its state estimate) or
their truth version :class:`controllers.OracleModelFeatures` (``oracle``).
Settings named residual-* use a model through a controller instead (residual RL,
:class:`controllers.ResidualControl`): the agent's action is added to that
of the self-tuning LQG on the identified model (``residual-adaptive``), of
the fixed LQG on the nominal model (``residual-fixed``), of the fixed LQG
with the physical estimates observed (``residual-fixed-physical``), of the
gain-scheduled LQG (``residual-scheduled``), or of that one with the attitude
error, the last torque and the base's state estimate observed
(``residual-scheduled-observed``, :class:`controllers.ResidualObservations`), or
of that one with the identifier's physical estimates observed
(``residual-scheduled-physical``: the draw's rigid gain and modes, which the
schedule on the paddle angle does not know), or the same vector from the truth
(``residual-scheduled-privileged``, or on the fixed LQG,
``residual-fixed-privileged``: the policies that :mod:`spacecraft_lab.adaptation`
evaluates with true, estimated and nominal parameters). ``residual-fixed-averaged``
and ``residual-scheduled-averaged`` show the agent of the fixed or the scheduled LQG
what the linear agent without a base sees (the attitude error and the rate in nominal
units, each the mean of the second since its last decision, one decision a second),
with full torque as its authority: ARS's linear policy on it is a PD correction of
the base law. ``residual-scheduled-averaged-privileged`` adds the truth's parameter
vector to that one, and shows the agent the averaged error and rate followed by their
products with the rigid-body gain's channels (:data:`SCHEDULE_CHANNELS`,
:class:`spacecraft_env.ObservationProducts`): ARS's linear policy on it is a PD
correction whose gains move with the plant's gain, the policy
:mod:`spacecraft_lab.adaptation` flies with the true, estimated and nominal vectors.
``residual-scheduled-averaged-deflection`` shows it the tip deflections too, averaged
the same way, in units of :data:`AVERAGED_DEFLECTION_LEVEL`: a linear correction that
can feed back the modes a static correction of the attitude and rate cannot damp.
``residual-adaptive-averaged`` is the same averaged correction on the adaptive LQG
(:func:`fast_adaptive_lqg`): a base whose design follows each draw's identified
rigid gain and modes.

Every ``eval_every`` env steps, and once at the end, the current policy is
evaluated through the same harness as the controllers
(:func:`controllers.run_episode`) on the same episodes
(:data:`EVAL_SEEDS`) as the oracle, adaptive and fixed LQG and zero torque:
the common quadratic cost from 100 s (median, mean and worst episode, and
per episode), attitude RMS, vibration, return and share of stable
episodes. Each evaluation is dumped at once to SB3's logger under ``eval/``
at the env-step count (TensorBoard's x-axis for it; Monitor's
``rollout/`` curves use SB3's own count of decisions), and the final result
is the curve's last point. It writes the saved models,
``learning_curves.png``, ``metrics.json`` and, with ``--tensorboard``,
TensorBoard logs.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from controllers import (
    AdaptiveLQG,
    BaseRelativeReward,
    Controller,
    FixedLQG,
    IdentifiedModelFeatures,
    OracleLQG,
    OracleModelFeatures,
    PhysicalFeatures,
    PrivilegedFeatures,
    ResidualControl,
    ResidualObservations,
    ScheduledLQG,
    ScoredWindowReward,
    episode_metrics,
    fast_identifier,
    run_episode,
    set_integral_settle,
    window_ceiling,
)
from controllers.features import PHYSICAL_FEATURE_NAMES
from controllers.lqg import INTEGRAL_SETTLE_S
from controllers.rewards import check_window_start
from spacecraft_conventions import __version__, single_threaded_blas
from spacecraft_env import (
    ActionRepeat,
    NominalUnits,
    ObservationAverage,
    ObservationGroups,
    ObservationProducts,
    env_id,
)
from spacecraft_lab.control import SCENARIO_NAMES
from spacecraft_lab.plots import plot_learning_curves
from spacecraft_lab.random_search import paired_ars
from spacecraft_lab.reporting import COMPARATOR_NAMES
from spacecraft_lab.score_cache import ScoreCache, default_cache
from spacecraft_lab.sweeps.backends import check_workers, map_in_order

__all__ = [
    "ACTION_REPEAT",
    "ALGORITHMS",
    "AVERAGED_DEFLECTION_LEVEL",
    "AVERAGED_FEATURES",
    "AVERAGED_RESIDUAL_SCALE",
    "EVAL_SEEDS",
    "EVAL_WARMUP_SEED",
    "FEATURES",
    "HYPERPARAMETERS",
    "NOMINAL_UNITS_FEATURES",
    "POLICIES",
    "PPO_MINIBATCH",
    "PPO_ROLLOUT",
    "RESIDUAL_HYPERPARAMETERS",
    "RESIDUAL_REPEAT",
    "RESIDUAL_SCALE",
    "SCHEDULE_CHANNELS",
    "SHORTEST_ROLLOUT",
    "NormalizedPolicy",
    "ZeroTorque",
    "algorithm_class",
    "base_comparator",
    "fast_adaptive_lqg",
    "ppo_rollout",
    "provenance",
    "residual_scale",
    "run_training",
]


#: stable-baselines3 algorithms the job trains: PPO and SAC (MLP policies) and augmented
#: random search on a linear policy (sb3-contrib's ARS with each antithetic pair flown on
#: the same episode, :func:`spacecraft_lab.random_search.paired_ars`).
ALGORITHMS = ("ppo", "sac", "ars")
#: The SB3 policy each algorithm trains.
POLICIES = {"ppo": "MlpPolicy", "sac": "MlpPolicy", "ars": "LinearPolicy"}
#: What the agent gets on top of the env: observation features, or (residual-*) a
#: controller whose action it corrects.
FEATURES = ("none", "attitude-error", "attitude-error-averaged", "identified", "identified-kept",
            "identified-kept-no-state", "oracle", "physical", "privileged",
            "residual-adaptive", "residual-fixed",
            "residual-fixed-physical", "residual-scheduled", "residual-scheduled-observed",
            "residual-scheduled-physical", "residual-scheduled-privileged",
            "residual-fixed-privileged", "residual-fixed-averaged",
            "residual-scheduled-averaged", "residual-scheduled-averaged-privileged",
            "residual-scheduled-averaged-deflection", "residual-adaptive-averaged")
#: ``IdentifiedModelFeatures`` keywords of each identified-features setting.
_IDENTIFIED = {
    "identified": {"keep_identifier": False, "include_state": True},
    "identified-kept": {"keep_identifier": True, "include_state": True},
    "identified-kept-no-state": {"keep_identifier": True, "include_state": False},
}


def fast_adaptive_lqg(env: gym.Env) -> AdaptiveLQG:
    """The adaptive LQG the agents are based on and scored beside.

    The loop's default identifier, the drive-scheduled fit, computes 11-32 s
    per 250 s episode, which training on millions of env steps cannot pay; the
    agents' base and comparator fly the structured recursive identifier
    (:func:`controllers.fast_identifier`), as every RL result in the docs did.

    Parameters
    ----------
    env : gymnasium.Env
        A flexible-spacecraft environment.

    Returns
    -------
    controllers.AdaptiveLQG
        The adaptive LQG on :func:`controllers.fast_identifier`.
    """
    return AdaptiveLQG(env, identifier=fast_identifier(env))


#: Base controller of each residual setting (``ResidualControl``).
_RESIDUAL = {"residual-adaptive": fast_adaptive_lqg, "residual-fixed": FixedLQG,
             "residual-fixed-physical": FixedLQG, "residual-scheduled": ScheduledLQG,
             "residual-scheduled-observed": ScheduledLQG,
             "residual-scheduled-physical": ScheduledLQG,
             "residual-scheduled-privileged": ScheduledLQG,
             "residual-fixed-privileged": FixedLQG, "residual-fixed-averaged": FixedLQG,
             "residual-scheduled-averaged": ScheduledLQG,
             "residual-scheduled-averaged-privileged": ScheduledLQG,
             "residual-scheduled-averaged-deflection": ScheduledLQG,
             "residual-adaptive-averaged": fast_adaptive_lqg}
#: Residual settings whose agent sees what the linear agent without a base sees (the
#: attitude error and the rate in nominal units, each the mean of the samples since its
#: last decision) while its base reads the env's whole observation: a linear policy on
#: it (``--algo ars``) is a PD correction of the base law.
_AVERAGED_RESIDUAL = frozenset({"residual-fixed-averaged", "residual-scheduled-averaged",
                                "residual-scheduled-averaged-privileged",
                                "residual-scheduled-averaged-deflection",
                                "residual-adaptive-averaged"})
#: The unit of the tip deflections an averaged residual with them observed sees
#: (``residual-scheduled-averaged-deflection``), m: 10 cm, so ARS's perturbation (0.05 of
#: full torque per unit) is 0.05 N m per cm of deflection, where the nominal 1 cm would
#: make it 0.5 N m per cm, enough to tumble the base on the slew's 2 cm (measured).
AVERAGED_DEFLECTION_LEVEL = 0.1
#: The parameter channels that schedule the gains of an averaged residual with the
#: plant's parameters observed (``residual-scheduled-averaged-privileged``): the
#: rigid-body gain's log diagonal, the loop gain a law designed for the nominal
#: actuator and inertia lacks or has in excess (measured: the shipped averaged residual
#: adds gain that the family's low-gain draws need and its high-gain draws do not).
SCHEDULE_CHANNELS = ("log_gain_xx", "log_gain_yy", "log_gain_zz")
#: A trained residual's authority, as a fraction of full torque (0.5 N m on the 10 N m
#: actuators): about ten times the LQGs' torque RMS after the slew, so it can correct
#: the base's pointing without the authority to tumble the spacecraft.
RESIDUAL_SCALE = 0.05
#: The authority of the averaged residual settings' linear correction, as a fraction of
#: full torque: that of the linear agent without a base, so ARS's perturbation (0.05 of
#: full torque per degree and per 0.1 deg/s, about a tenth of the LQGs' own gains)
#: explores around the base law as it explored around zero. Its weights start at zero:
#: a fresh agent flies its base.
AVERAGED_RESIDUAL_SCALE = 1.0
#: Env steps per residual decision (0.2 s): a correction of the base's pointing must
#: act within the flexible modes' period (the 0.51 Hz mode's is 2 s), which one
#: decision a second cannot.
RESIDUAL_REPEAT = 2
#: Evaluation episode seeds (disjoint from training seeds): every point of a
#: learning curve and the final result use the same ten episodes.
EVAL_SEEDS = tuple(range(1000, 1010))
#: Seed of the discarded episode that precedes the evaluation episodes when the
#: identifier is carried over episodes (``identified-kept``): evaluated
#: episodes then start with a learnt model, as in training.
EVAL_WARMUP_SEED = 999
#: Env steps per agent decision (1 s at dt = 0.1 s), see spacecraft_env.ActionRepeat.
ACTION_REPEAT = 10
#: Settings that differ from SB3's defaults, per algorithm. PPO's initial action
#: noise is exp(-1) = 0.37 of full torque instead of 1 (3.7 N m, not 10 N m of
#: random torque, which alone tumbles the spacecraft out of the bound).
HYPERPARAMETERS: dict[str, dict[str, Any]] = {
    "ppo": {"policy_kwargs": {"log_std_init": -1.0}},
    "sac": {},
    "ars": {},       # sb3-contrib's: 8 directions, all kept, delta_std 0.05, step 0.02
}
#: The residual settings' PPO: exploration exp(-3) = 5 % of the residual's authority
#: (0.025 N m), so an untrained residual perturbs its base's cost by percents, not by
#: the 100x of log_std -1 on a 2.5 N m residual; its last layer starts at zero, so a
#: fresh residual flies exactly its base (:func:`_start_at_the_base`).
RESIDUAL_HYPERPARAMETERS: dict[str, dict[str, Any]] = {
    "ppo": {"policy_kwargs": {"log_std_init": -3.0}},
    "sac": {},
    "ars": HYPERPARAMETERS["ars"],      # its policy starts at zero: the base alone
}
#: Settings whose observation is in fixed nominal units (:class:`spacecraft_env.NominalUnits`):
#: ARS's linear policy acts on it as it is, where it acts on every other setting's
#: observation through ``VecNormalize``'s running normalization. Its weights then keep
#: their meaning while it learns (normalized torque per degree of attitude error, per
#: 0.1 deg/s of rate).
NOMINAL_UNITS_FEATURES = frozenset({"attitude-error", "attitude-error-averaged",
                                    *_AVERAGED_RESIDUAL})
#: Settings whose observation is the mean of the samples since the last decision: their
#: decision period is the window, :data:`ACTION_REPEAT` env steps.
AVERAGED_FEATURES = frozenset({"attitude-error-averaged", *_AVERAGED_RESIDUAL})


def residual_scale(features: str) -> float | None:
    """The authority of a residual setting's agent.

    Parameters
    ----------
    features : str
        One of :data:`FEATURES`.

    Returns
    -------
    float or None
        The torque an agent action of 1 adds, as a fraction of full torque:
        :data:`AVERAGED_RESIDUAL_SCALE` for the averaged residual settings,
        :data:`RESIDUAL_SCALE` for the other residual settings; None for a setting
        without a base law.
    """
    if features not in _RESIDUAL:
        return None
    return AVERAGED_RESIDUAL_SCALE if features in _AVERAGED_RESIDUAL else RESIDUAL_SCALE


#: PPO's rollout per env (decisions) and minibatch as tuned (SB3's defaults); the run's
#: rollout is the divisor of its budget nearest to it, so the budget is whole rollouts.
PPO_ROLLOUT, PPO_MINIBATCH = 2048, 64
#: Smallest PPO rollout per env chosen for a budget that allows a longer one (decisions).
SHORTEST_ROLLOUT = 64


def ppo_rollout(decisions_per_env: int, envs: int = 1) -> tuple[int, int]:
    """PPO's ``n_steps`` and ``batch_size`` for a budget of whole rollouts.

    Parameters
    ----------
    decisions_per_env : int
        The agent decisions each env trains (>= 1).
    envs : int
        Envs stepped side by side (>= 1).

    Returns
    -------
    n_steps : int
        The divisor of ``decisions_per_env`` nearest to :data:`PPO_ROLLOUT` (the larger
        on a tie), at least :data:`SHORTEST_ROLLOUT` where the budget allows: the
        budget is then ``decisions_per_env / n_steps`` whole rollouts.
    batch_size : int
        :data:`PPO_MINIBATCH` when it divides ``n_steps * envs`` (no truncated
        minibatch), else the largest divisor of ``n_steps * envs`` below it, unless that
        is under 8 (a prime rollout): then :data:`PPO_MINIBATCH`, the last minibatch
        truncated.

    Raises
    ------
    ValueError
        For ``decisions_per_env`` or ``envs`` below 1.
    """
    if decisions_per_env < 1 or envs < 1:
        raise ValueError(f"decisions_per_env and envs must be >= 1, got "
                         f"{decisions_per_env}, {envs}")
    divisors = [d for d in range(1, decisions_per_env + 1) if decisions_per_env % d == 0]
    allowed = [d for d in divisors if d >= SHORTEST_ROLLOUT] or divisors
    n_steps = min(allowed, key=lambda d: (abs(d - PPO_ROLLOUT), -d))
    buffer = n_steps * envs
    batch = max(d for d in range(1, PPO_MINIBATCH + 1) if buffer % d == 0)
    return n_steps, (batch if batch >= 8 else PPO_MINIBATCH)


def provenance(scenario: str) -> dict[str, Any]:
    """What a training run was made with, for its ``metrics.json``.

    Parameters
    ----------
    scenario : str
        The run's scenario (a name of :data:`spacecraft_lab.control.SCENARIO_NAMES`).

    Returns
    -------
    dict
        ``env_id`` (the registered id, its ``-vN`` the env's version), ``package_version``
        and ``commit`` (the checkout's ``git`` commit, with ``+dirty`` when it had
        uncommitted changes; None outside a checkout or without ``git``).
    """
    root = Path(__file__).resolve().parents[1]
    commit = None
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=root, capture_output=True, text=True, timeout=10,
                               check=True).stdout.strip()
        commit = head + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return {"env_id": env_id(scenario), "package_version": __version__, "commit": commit}


def base_comparator(features: str) -> str | None:
    """The key of :data:`COMPARATORS` a residual setting's base is (a fresh residual flies
    it exactly).

    Parameters
    ----------
    features : str
        One of :data:`FEATURES`.

    Returns
    -------
    str or None
        The comparator's key, or None for a setting without a base law.
    """
    if features not in _RESIDUAL:
        return None
    return next((key for key, make in COMPARATORS if make is _RESIDUAL[features]), None)


def algorithm_class(algo: str) -> type:
    """The class that trains and loads agents of one of :data:`ALGORITHMS`.

    Parameters
    ----------
    algo : str
        ``"ppo"``, ``"sac"`` or ``"ars"``.

    Returns
    -------
    type
        stable-baselines3's ``PPO`` or ``SAC``, or
        :func:`spacecraft_lab.random_search.paired_ars`'s class (sb3-contrib's ARS).

    Raises
    ------
    ValueError
        For another name.
    """
    if algo not in ALGORITHMS:
        raise ValueError(f"algo must be one of {ALGORITHMS}, got {algo!r}")
    if algo == "ars":
        return paired_ars()
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


class ZeroTorque(Controller):
    """The trivial baseline: no torque at all."""

    name = "zero torque"

    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        return np.zeros(3, dtype=np.float32)


class NormalizedPolicy(Controller):
    """An SB3 model trained under ``VecNormalize``, as a harness controller.

    ``repeat``: the model was trained under
    :class:`spacecraft_env.ActionRepeat`, so it decides every ``repeat``
    env steps and its action is held in between, as in training.
    """

    def __init__(self, model: Any, vec_normalize: Any, name: str, repeat: int = 1) -> None:
        self.model = model
        self.vec_normalize = vec_normalize
        self.name = name
        self.repeat = int(repeat)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self._held: np.ndarray | None = None
        self._age = 0

    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        if self._held is None or self._age >= self.repeat:
            norm = self.vec_normalize.normalize_obs(np.asarray(obs, dtype=np.float32)[None])
            action, _ = self.model.predict(norm, deterministic=True)
            self._held, self._age = np.asarray(action[0], dtype=np.float32), 0
        self._age += 1
        return self._held


def _training_env_kwargs(randomize: bool, reward: str) -> dict[str, Any]:
    """``gym.make`` keywords of the environments an agent trains and is evaluated on."""
    return {"task": "slew", "randomize": bool(randomize), "reward": reward}


def _monitored_env(scenario: str, features: str, env_kwargs: dict[str, Any],
                   repeat: int, relative_to_base: bool = False,
                   reward_from_s: float = 0.0, monitor_file: str | None = None) -> gym.Env:
    """One training env: the setting's env (with ``relative_to_base``, its reward minus
    the base's on a twin of the episode, :class:`controllers.BaseRelativeReward`; with
    ``reward_from_s`` > 0, rewarded from that time on,
    :class:`controllers.ScoredWindowReward`), its action held ``repeat`` steps,
    Monitor-wrapped, its episodes written to ``monitor_file`` (``.monitor.csv``) when
    given (module level, so a ``SubprocVecEnv`` can build it in its worker)."""
    from stable_baselines3.common.monitor import Monitor

    env = _make_env(scenario, features, env_kwargs)
    if relative_to_base:
        env = BaseRelativeReward(env)
    if reward_from_s > 0:
        env = ScoredWindowReward(env, reward_from_s)
    return Monitor(ActionRepeat(env, repeat), filename=monitor_file)


def _make_env(scenario: str, features: str, env_kwargs: dict[str, Any],
              base_settle_s: float = INTEGRAL_SETTLE_S,
              parameters: Callable[[gym.Env], gym.Env] | None = None) -> gym.Env:
    """The setting's env. ``base_settle_s``: the residual base's integral settle time
    (:func:`controllers.set_integral_settle`), so a saved agent flies the base it was
    trained on. ``parameters``: for a setting with the plant's parameters observed
    (``*-privileged``), the wrapper that appends them where the setting reads them
    (default :class:`controllers.PrivilegedFeatures`, the truth; an RMA comparison
    puts the estimated or nominal vector there)."""
    if parameters is not None and not features.endswith("privileged"):
        raise ValueError(f"features {features!r} observe no parameter vector")
    appended = parameters or PrivilegedFeatures
    if features in NOMINAL_UNITS_FEATURES and features not in _RESIDUAL:
        # the pointing error and the rate alone, in nominal units (1 deg, 0.1 deg/s);
        # -averaged: each the mean of the last second's samples
        env = gym.make(env_id(scenario), **env_kwargs, outputs=("attitude_error", "rate"))
        if features in AVERAGED_FEATURES:
            env = ObservationAverage(env, ACTION_REPEAT)
        return NominalUnits(env)
    # an averaged residual's base reads the whole observation, its agent the error group
    extra = ({"outputs": ("attitude", "rate", "deflection", "attitude_error")}
             if features in _AVERAGED_RESIDUAL else {})
    env = gym.make(env_id(scenario), **env_kwargs, **extra)
    if features in _IDENTIFIED:
        env = IdentifiedModelFeatures(env, **_IDENTIFIED[features])
    elif features == "oracle":
        env = OracleModelFeatures(env)
    elif features == "physical":
        env = PhysicalFeatures(env)
    elif features == "privileged":
        env = appended(env)
    if features in _RESIDUAL:
        base = set_integral_settle(_RESIDUAL[features](env.unwrapped), base_settle_s)
        env = ResidualControl(env, base, scale=residual_scale(features))
    if features.endswith("-physical"):
        # outside the residual wrapper: the identifier sees the whole torque
        env = PhysicalFeatures(env)
    if features.endswith("-privileged"):
        env = appended(env)
    if features.endswith("-observed"):
        # the attitude error, the last torque and the base's state estimate
        env = ResidualObservations(env)
    if features in _AVERAGED_RESIDUAL:
        # the attitude error and the rate in nominal units, each the mean of the
        # samples since the agent's last decision
        deflection = features.endswith("-deflection")
        env = ObservationGroups(
            NominalUnits(env, levels={"deflection": AVERAGED_DEFLECTION_LEVEL} if deflection
                         else None),
            ("attitude_error", "rate", "deflection") if deflection
            else ("attitude_error", "rate"))
        env = ObservationAverage(env, ACTION_REPEAT)
        if features.endswith("-privileged"):
            # the agent's linear law scheduled on the parameters: its gains move with them
            env = ObservationProducts(env, 6, [6 + PHYSICAL_FEATURE_NAMES.index(name)
                                               for name in SCHEDULE_CHANNELS])
    return env


def _evaluate(controller: Controller | Callable[[gym.Env], Controller], scenario: str,
              features: str, env_kwargs: dict[str, Any], seeds=EVAL_SEEDS,
              make_env: Callable[[], gym.Env] | None = None,
              base_settle_s: float = INTEGRAL_SETTLE_S) -> dict[str, Any]:
    """Harness scores over the evaluation episodes. ``controller``: one controller for
    every episode, or a factory called with each episode's env (a controller that
    reads its env's true model, e.g. the oracle, must fly the env it is scored on).
    ``make_env``: builds each episode's env instead of the setting's;
    ``base_settle_s``: as in :func:`_make_env`."""
    make = controller if not isinstance(controller, Controller) else (lambda env: controller)
    build = make_env or partial(_make_env, scenario, features, env_kwargs,
                                base_settle_s=base_settle_s)
    per_seed = []
    kept = _IDENTIFIED.get(features, {}).get("keep_identifier", False)
    shared = build() if kept else None
    if shared is not None:
        # one env: its identifier learns through a first, discarded episode and
        # is carried into every evaluated one
        run_episode(shared, make(shared.unwrapped), seed=EVAL_WARMUP_SEED)
    for seed in seeds:
        env = shared or build()
        traj = run_episode(env, make(env.unwrapped), seed=seed)
        per_seed.append(episode_metrics(traj, env.unwrapped.model))
        if shared is None:
            env.close()
    if shared is not None:
        shared.close()
    # an episode that left the attitude bound before the scored window has no cost
    # from 100 s: it counts as infinitely costly (a failure), not as missing
    costs = np.array([m["cost_after_100s"] for m in per_seed], dtype=float)
    costs[np.isnan(costs)] = np.inf
    return {"cost_after_100s": float(np.median(costs)),
            "cost_after_100s_mean": float(np.mean(costs)),
            "cost_after_100s_worst": float(np.max(costs)),
            "worst_episode_seed": int(seeds[int(np.argmax(costs))]),
            "cost_after_100s_per_seed": costs.tolist(),
            "attitude_rms_deg": float(np.mean([m["attitude_rms_deg"] for m in per_seed])),
            "vibration_rms_mm": float(np.mean([m["vibration_rms_mm"] for m in per_seed])),
            "return": float(np.mean([m["return"] for m in per_seed])),
            "stable_share": float(np.mean([m["stable"] for m in per_seed]))}


#: The LQG comparators every agent is scored beside (None: zero torque); each residual
#: setting's base is among them. The window ceiling (:func:`controllers.window_ceiling`)
#: is the bound of the cost from 100 s the agents are scored on: no agent can beat it.
COMPARATORS = (("adaptive_lqg", fast_adaptive_lqg), ("fixed_lqg", FixedLQG),
               ("oracle_lqg", OracleLQG), ("scheduled_lqg", ScheduledLQG), ("zero_torque", None),
               ("window_ceiling", window_ceiling))


def _score_comparator(scenario: str, env_kwargs: dict[str, Any], eval_seeds: tuple[int, ...],
                      make: Any) -> dict[str, Any]:
    """:func:`_evaluate` of one comparator (``make`` None: zero torque), single-threaded."""
    with single_threaded_blas:
        return _evaluate(ZeroTorque() if make is None else make, scenario, "none", env_kwargs,
                         eval_seeds)


def _score_comparators(scenario: str, env_kwargs: dict[str, Any], eval_seeds: tuple[int, ...],
                       workers: int | None, progress: bool,
                       when: str = "Before training",
                       cache: ScoreCache | None = None) -> dict[str, dict[str, Any]]:
    """The comparators on the evaluation episodes, on a process pool when
    ``workers`` (default: the cores) is above 1; ``when`` opens the line that says so.
    ``cache``: scores found there are read, not computed, and new ones stored
    (:mod:`spacecraft_lab.score_cache`; None: score every comparator)."""
    inputs = {key: {"scenario": scenario, "env_kwargs": env_kwargs,
                    "seeds": list(eval_seeds), "controller": key} for key, _ in COMPARATORS}
    scores = {key: cache.get(inputs[key]) for key, _ in COMPARATORS} if cache else {}
    todo = [(key, make) for key, make in COMPARATORS if scores.get(key) is None]
    if progress:
        names = ", ".join(COMPARATOR_NAMES[key] for key, _ in todo)
        found = (f"{len(COMPARATORS) - len(todo)} of the {len(COMPARATORS)} comparison "
                 f"controllers' scores on these episodes come from the cache ({cache.directory}"
                 "; --no-cache scores them again)") if len(todo) < len(COMPARATORS) else ""
        if todo:
            tqdm.write(f"{when}: scoring the {len(todo)} comparison controllers "
                       f"({names}) on the {len(eval_seeds)} evaluation episodes the agents "
                       "are judged on; each tick is one controller's episodes."
                       + (f" The other {found}." if found else ""))
        else:
            tqdm.write(f"{when}: all {found}.")
    if todo:
        with tqdm(total=len(todo), desc="comparison controllers",
                  disable=not progress) as bar:
            computed = map_in_order(partial(_score_comparator, scenario, env_kwargs,
                                            eval_seeds),
                                    [make for _, make in todo], workers, bar.update)
        for (key, _), score in zip(todo, computed, strict=True):
            scores[key] = score
            if cache is not None:
                cache.put(inputs[key], score)
    return {key: scores[key] for key, _ in COMPARATORS}


@contextmanager
def _one_torch_thread(torch) -> Iterator[None]:
    """torch on one intra-op thread inside, the caller's setting restored after.

    The policies are small MLPs updated on one env's batches: more threads do
    not pay, and a reduction split over a machine-dependent thread count
    changes the training's bits, so results would depend on the core count.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def _start_at_the_base(model: Any) -> None:
    """Zero the last layer of a residual policy's action mean (PPO's ``action_net``,
    SAC's ``actor.mu``): the deterministic residual is then 0 and a fresh agent flies
    exactly its base controller. (ARS's linear policy starts at zero already.)"""
    import torch

    layer = getattr(model.policy, "action_net", None)
    if layer is None:
        layer = model.policy.actor.mu
    with torch.no_grad():
        layer.weight.zero_()
        layer.bias.zero_()


def run_training(algo: str = "ppo", features: str = "none", timesteps: int = 100_000,
                 seeds: int = 1, out: str | Path = "results/train", *,
                 scenario: str = "docking", eval_every: int = 20_000,
                 tensorboard: str | None = None, progress: bool = True,
                 randomize: bool = False, repeat: int | None = None,
                 reward: str = "bounded", first_seed: int = 0,
                 eval_seeds: tuple[int, ...] = EVAL_SEEDS, workers: int | None = None,
                 envs: int = 1, log_std_init: float | None = None,
                 relative_to_base: bool = False, reward_from_s: float = 0.0,
                 cache: bool = True) -> dict:
    """Train, evaluate and save SB3 agents; see the module docstring.

    Seeds ``first_seed .. first_seed + seeds - 1`` are trained (so seeds can be
    split over processes; ``spacecraft rl-table`` pools directories of equal
    settings).

    ``eval_seeds``: the evaluation episodes (default :data:`EVAL_SEEDS`), the
    same for the comparators, every point of the curves and the final result.

    ``timesteps`` and ``eval_every`` count env steps (0.1 s samples), also
    under ``repeat`` (agent decisions are ``timesteps / repeat``), so runs
    with different ``repeat`` compare at equal simulated time. PPO and SAC train
    exactly ``timesteps`` env steps: the budget must be a whole number of decisions
    per env (a multiple of ``repeat * envs``; otherwise refused, naming the nearest
    valid budgets), and PPO's rollout is set from it (:func:`ppo_rollout`, recorded in
    ``hyperparameters``). ARS trains whole iterations of whole episodes (an episode
    ends when it ends), so it stops at the end of the first iteration past the budget.
    ``metrics.json``'s ``"timesteps"`` are the env steps trained (each seed's in
    ``runs[i]["env_steps"]``), ``"timesteps_requested"`` what was asked.

    The policy is evaluated every ``eval_every`` env steps at the first update boundary
    past them (the start of a rollout: never before the first update), and once at
    the end. Each evaluation writes ``metrics.json`` (``"complete": false`` until the
    run ends) and ``learning_curves.png``, so an interrupted run keeps its curve.
    SB3's log goes to the console and to ``logs/<run>/progress.csv`` beside the
    Monitor's episode record (``monitor/<run>-env<i>.monitor.csv``).

    ``workers``: processes that score the comparators (:data:`COMPARATORS`) side by side
    before training (default: one per core, at most one per comparator); every episode is
    built from its seed, so the scores do not depend on it.

    ``log_std_init``: PPO's initial log standard deviation of the action noise, in
    normalized action units (default: :data:`HYPERPARAMETERS`' -1, or
    :data:`RESIDUAL_HYPERPARAMETERS`' -3 for the residual settings, whose action is
    scaled by :data:`RESIDUAL_SCALE`); PPO only.

    ``relative_to_base``: train a residual agent (``features`` ``residual-*``) on its
    reward minus the reward its base alone earns on a twin of the same episode (same
    plant draw, same sensor noise; :class:`controllers.BaseRelativeReward`). The
    base's term does not depend on the agent's actions, so the optimal policy is the
    same; the return loses the variance the draw and the noise put in it. It costs a
    second env and base per training env. The evaluations score the harness's cost,
    as for every run; ``metrics.json`` records the choice.

    ``reward_from_s``: train on the reward of the steps from this time on (s) and the
    termination penalty whenever it comes (:class:`controllers.ScoredWindowReward`;
    100 is the window the evaluations score, the cost from 100 s); 0 (default): every
    step. The evaluations score the harness's cost as for every run; ``metrics.json``
    records it.

    ``cache``: read the comparators' scores from, and store them in,
    :func:`spacecraft_lab.score_cache.default_cache` (they depend only on the scenario,
    the env's arguments, the episodes and the code, so every run after the first with
    the same settings skips them); False scores them again.

    ``envs``: environments stepped side by side while training (default 1: one
    ``DummyVecEnv`` env in this process; above 1, a ``SubprocVecEnv`` of that many
    processes, env ``i`` seeded ``seed + i``). PPO then collects ``n_steps`` decisions
    from each env per rollout, so a run with more envs is a different (equally valid)
    run, not the same one faster. ``metrics.json`` records ``envs`` and each seed's
    training throughput (``env_steps_per_s``: env steps trained per second of
    ``learn``, evaluations included).

    Returns
    -------
    dict
        The metrics, as written to ``metrics.json``.

    Raises
    ------
    ImportError
        Before any work, when the ``rl`` extra (torch, stable-baselines3) is
        not installed; the message says how to install it.
    """
    missing = [name for name in ("torch", "stable_baselines3")
               if importlib.util.find_spec(name) is None]
    if missing:
        raise ImportError(f"training needs the 'rl' extra ({' and '.join(missing)} not "
                          "installed): run `make test`, or `pip install -c constraints.txt "
                          "\"torch==2.13.0\" && pip install -c constraints.txt -e \".[rl]\"`")
    # optional dependency (the "rl" extra): imported where it is needed
    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import configure as configure_logger
    from stable_baselines3.common.logger import make_output_format
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    if algo == "ars" and importlib.util.find_spec("sb3_contrib") is None:
        raise ImportError("--algo ars needs sb3-contrib (the 'rl' extra): `pip install -c "
                          "constraints.txt -e \".[rl]\"`")
    algorithm = algorithm_class(algo)          # refuses an unknown name
    if features not in FEATURES:
        raise ValueError(f"features must be one of {FEATURES}, got {features!r}")
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"scenario must be one of {sorted(SCENARIO_NAMES)}, got {scenario!r}")
    if timesteps < 1 or seeds < 1 or first_seed < 0:
        raise ValueError("timesteps and seeds must be >= 1, first_seed >= 0")
    if not (isinstance(envs, int) and not isinstance(envs, bool) and 1 <= envs <= 64):
        raise ValueError(f"envs must be an integer in [1, 64], got {envs!r}")
    if algo == "ars" and envs != 1:
        raise ValueError("ARS flies its candidates one episode at a time in one env "
                         f"(envs=1), got envs={envs}; run seeds as separate processes")
    check_workers(workers)
    eval_seeds = tuple(int(s) for s in eval_seeds)
    if not eval_seeds or min(eval_seeds) < 0:
        raise ValueError(f"eval_seeds must be one or more seeds >= 0, got {eval_seeds}")
    residual = features in _RESIDUAL
    if relative_to_base and not residual:
        raise ValueError(f"relative_to_base needs a residual setting (features residual-*), "
                         f"whose zero action flies a base; got features {features!r}")
    reward_from_s = check_window_start(reward_from_s, "reward_from_s")
    if repeat is None:
        repeat = (RESIDUAL_REPEAT if residual and features not in AVERAGED_FEATURES
                  else ACTION_REPEAT)
    if features in AVERAGED_FEATURES and repeat != ACTION_REPEAT:
        raise ValueError(f"features {features!r} average the {ACTION_REPEAT} samples since "
                         f"the last decision: repeat must be {ACTION_REPEAT}, got {repeat}")
    hyper = (RESIDUAL_HYPERPARAMETERS if residual else HYPERPARAMETERS)[algo]
    if log_std_init is not None:
        if algo != "ppo":
            raise ValueError(f"log_std_init applies to PPO, not {algo!r}")
        if not (np.isfinite(log_std_init) and -10.0 <= log_std_init <= 2.0):
            raise ValueError(f"log_std_init must be in [-10, 2], got {log_std_init}")
        hyper = {**hyper, "policy_kwargs": {**hyper.get("policy_kwargs", {}),
                                            "log_std_init": float(log_std_init)}}
    env_kwargs = _training_env_kwargs(randomize, reward)
    # the env checks the reward form and the wrapper the repeat, before anything is written
    ActionRepeat(gym.make(env_id(scenario), **env_kwargs), repeat).close()
    if algo != "ars" and timesteps % (repeat * envs):
        unit = repeat * envs
        below, above = timesteps // unit * unit, -(-timesteps // unit) * unit
        raise ValueError(
            f"{algo.upper()} trains whole decisions of {repeat} env steps in each of {envs} "
            f"env(s): timesteps must be a multiple of {unit}, got {timesteps:,}; the nearest "
            f"valid budgets are {', '.join(f'{b:,}' for b in (below, above) if b > 0)}")
    if algo == "ppo":
        n_steps, batch = ppo_rollout(timesteps // (repeat * envs), envs)
        hyper = {**hyper, "n_steps": n_steps, "batch_size": batch}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    comparators = _score_comparators(scenario, env_kwargs, eval_seeds, workers, progress,
                                     cache=default_cache() if cache else None)
    baseline = comparators["adaptive_lqg"]
    # the threshold on the score itself (the cost from 100 s, median episode): the
    # whole-episode attitude RMS is dominated by the slew, which every policy flies alike
    target = 2.0 * baseline["cost_after_100s"]

    runs: list[dict[str, Any]] = []
    settings = {
        "algo": algo, "features": features, "scenario": scenario, "randomize": bool(randomize),
        "repeat": repeat, "reward": reward, "relative_to_base": bool(relative_to_base),
        "reward_from_s": reward_from_s,
        "hyperparameters": hyper, "envs": envs,
        "residual_scale": residual_scale(features),
        # the comparator that is the residual's base (a fresh residual flies it exactly)
        "base_comparator": base_comparator(features),
        # the residual base's integral settle time, so a loaded agent flies that base
        "base_integral_settle_s": INTEGRAL_SETTLE_S if residual else None,
        "timesteps_requested": timesteps, "seeds": seeds, "eval_seeds": list(eval_seeds),
        # what trained it: the env id (its version), the package's version and commit
        "provenance": provenance(scenario),
        **comparators,
        "threshold": "cost_after_100s", "target_cost_after_100s": target,
    }

    def write_metrics(in_progress: dict[str, Any] | None = None) -> dict[str, Any]:
        """``metrics.json`` and ``learning_curves.png`` of the seeds done and, while
        one trains, its curve so far (``"complete": false``)."""
        metrics = {**settings, "complete": in_progress is None, "runs": runs,
                   # the env steps every seed trained, and what was asked
                   "timesteps": int(max((r["env_steps"] for r in runs), default=0))}
        if in_progress is not None:
            metrics["in_progress"] = in_progress
        if runs:
            finals = [r["final"] for r in runs]
            metrics.update({
                "final_cost_after_100s": float(np.median([f["cost_after_100s"]
                                                          for f in finals])),
                "final_attitude_rms_deg": float(np.mean([f["attitude_rms_deg"]
                                                         for f in finals])),
                "final_vibration_rms_mm": float(np.mean([f["vibration_rms_mm"]
                                                         for f in finals])),
                "final_return": float(np.mean([f["return"] for f in finals]))})
        (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
        curves = runs + ([in_progress] if in_progress is not None else [])
        plot_learning_curves(out / "learning_curves.png", {**metrics, "runs": curves})
        return metrics

    with _one_torch_thread(torch):
        settings["torch_threads"] = torch.get_num_threads()
        for seed in range(first_seed, first_seed + seeds):
            name = f"{algo}-{features}-seed{seed}"
            (out / "monitor").mkdir(exist_ok=True)
            factories = [partial(_monitored_env, scenario, features, env_kwargs, repeat,
                                 bool(relative_to_base), reward_from_s,
                                 str(out / "monitor" / f"{name}-env{i}"))
                         for i in range(envs)]
            vec = (DummyVecEnv(factories) if envs == 1
                   else SubprocVecEnv(factories, start_method="forkserver"))
            # ARS compares whole returns within an iteration: no running reward scale;
            # its linear policy acts on nominal units where the setting gives them
            venv = VecNormalize(vec, norm_obs=not (algo == "ars"
                                                   and features in NOMINAL_UNITS_FEATURES),
                                norm_reward=algo != "ars", clip_obs=10.0)
            venv.seed(seed)
            model = algorithm(POLICIES[algo], venv, seed=seed, verbose=0, **hyper)
            # SB3's log: the console and a CSV per run, and TensorBoard when asked (not
            # SB3's default logger, which makes an empty /tmp/SB3-<date> folder per model)
            model.set_logger(configure_logger(str(out / "logs" / name), ["stdout", "csv"]))
            if tensorboard:
                model.logger.output_formats.append(
                    make_output_format("tensorboard", str(Path(tensorboard) / name)))
            if residual and algo != "ars":
                _start_at_the_base(model)
            curve: list[dict[str, float]] = []

            decisions = timesteps // repeat if algo != "ars" else -(-timesteps // repeat)
            if algo == "ars" and progress and seed == first_seed:
                tqdm.write(f"ARS trains whole iterations of {model.pop_size} episodes: "
                           "it stops at the end of the first past the env steps asked "
                           "(metrics.json's 'timesteps' are those trained).")
            callback = _eval_callback(
                BaseCallback, model, venv, name, curve, decisions * repeat, eval_every,
                scenario, features, env_kwargs, progress, repeat, eval_seeds, out,
                on_evaluation=partial(write_metrics, {"seed": seed, "curve": curve}))
            started = time.perf_counter()
            model.learn(total_timesteps=decisions, callback=callback)
            seconds = time.perf_counter() - started
            # the final evaluation is the curve's last point (same episodes, same axis)
            final = callback.evaluate_now()
            venv.training = False       # saved for inference: the statistics stay fixed
            model.save(out / f"{name}.zip")
            venv.save(str(out / f"{name}_vecnormalize.pkl"))
            venv.close()
            model.logger.close()
            reached = next((c["timesteps"] for c in curve if c["cost_after_100s"] <= target),
                           None)
            runs.append({"seed": seed, "final": final, "curve": curve,
                         "steps_to_2x_adaptive": reached,
                         "env_steps": int(model.num_timesteps * repeat),
                         # training throughput on this machine (evaluations included)
                         "env_steps_per_s": float(model.num_timesteps * repeat / seconds),
                         # selected on the evaluation episodes: optimistic
                         "best_checkpoint": callback.best})
    return write_metrics()


def _eval_callback(base, model, venv, name, curve, timesteps, eval_every, scenario,
                  features, env_kwargs, progress, repeat, eval_seeds, out=None,
                  on_evaluation=None):
    """SB3 callback: tqdm progress and a harness evaluation every ``eval_every`` env
    steps (``num_timesteps`` counts agent decisions, ``repeat`` env steps each), at the
    first update boundary past them (the start of a rollout, after the update the last
    one fed: PPO's and ARS's whole rollouts, SAC's every step), never before the first
    update; ``on_evaluation()`` after each (the partial ``metrics.json``).

    Not SB3's ``EvalCallback``: that one scores returns through
    ``evaluate_policy``, while these runs are judged on the controllers' harness
    (the common cost and its verdicts, on the LQG comparators' episodes); it
    dumps its record at each evaluation as ``EvalCallback`` does."""

    class EvalCallback(base):
        def __init__(self) -> None:
            super().__init__()
            self.bar = tqdm(total=timesteps, desc=name, disable=not progress)
            self.next_eval = eval_every
            self.best: dict[str, Any] | None = None

        def evaluate_now(self) -> dict[str, Any]:
            """Evaluate the current policy, append it to the curve and dump it to the
            logger at the env-step count (TensorBoard's x-axis for ``eval/``)."""
            env_steps = int(self.num_timesteps * repeat)
            training, venv.training = venv.training, False
            score = _evaluate(NormalizedPolicy(model, venv, name, repeat), scenario,
                              features, env_kwargs, eval_seeds)
            venv.training = training
            curve.append({"timesteps": env_steps, **score})
            for key, value in score.items():
                if np.isscalar(value):
                    self.logger.record(f"eval/{key}", value)
            self.logger.record("time/env_steps", env_steps)
            # dumped now, at this env step: recorded values would otherwise wait for
            # the next rollout's dump (and only the last of several would survive)
            self.logger.dump(step=env_steps)
            cost = score["cost_after_100s_mean"]
            if out is not None and (self.best is None
                                    or cost < self.best["cost_after_100s_mean"]):
                # the best checkpoint by the mean episode's cost, the expectation the
                # agent and the LQGs minimize (the median would pass over a checkpoint's
                # rare crashes), chosen on the evaluation episodes themselves: an
                # optimistic pick, said so in metrics.json
                self.best = {"timesteps": env_steps, "cost_after_100s_mean": cost,
                             "cost_after_100s": score["cost_after_100s"]}
                model.save(out / f"{name}_best.zip")
                venv.save(str(out / f"{name}_best_vecnormalize.pkl"))
            if on_evaluation is not None:
                on_evaluation()
            return score

        def _on_rollout_start(self) -> None:
            env_steps = self.num_timesteps * repeat
            # a rollout starts after the update the last one fed (none before the first)
            if timesteps > env_steps >= self.next_eval and self.num_timesteps > 0:
                while self.next_eval <= env_steps:
                    self.next_eval += eval_every
                self.evaluate_now()

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs * repeat)
            # none at the end (the last rollout's update is still to come): the final
            # evaluation after ``learn`` scores the policy that is saved, once
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return EvalCallback()
