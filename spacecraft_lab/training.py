"""Training stable-baselines3 agents on the spacecraft environments.

``spacecraft train --algo ppo|sac --features F --timesteps N --seeds S
[--randomize] --out DIR`` calls :func:`run_training`: for each seed it
trains an agent on a registered environment (slew task; ``--randomize``
draws a new scenario every episode, e.g. docking masses, times and
offsets), Monitor-wrapped, with observations and rewards normalized by
``VecNormalize``. ``F`` (:data:`FEATURES`) appends nothing (``none``),
:class:`controllers.IdentifiedModelFeatures` (``identified``: the
identifier restarts every episode; ``identified-kept``: it is carried over
episode resets; ``identified-kept-no-state``: carried over, and without
the identifier's state estimate among the features) or (the ceiling)
:class:`controllers.OracleModelFeatures` (``oracle``). Two more settings
use a model through a controller instead (residual RL,
:class:`controllers.ResidualControl`): the agent's action is added to that
of the self-tuning LQG on the identified model (``residual-adaptive``) or of
the fixed LQG on the nominal model (``residual-fixed``, the comparator: what
a model the identifier did not learn gives). Every ``eval_every``
steps the current policy is evaluated through the same harness as the
controllers (:func:`controllers.run_episode`), and the evaluation (attitude
RMS, vibration, return, share of stable episodes) goes to SB3's logger
under ``eval/`` beside Monitor's ``rollout/ep_rew_mean`` and
``ep_len_mean``, so TensorBoard shows them. It writes the saved models,
``learning_curves.png``, ``metrics.json`` (final attitude RMS, vibration,
return, and the env steps needed to come within 2x of the adaptive LQG's
attitude RMS on the same evaluation seeds, with the fixed LQG beside it)
and, with ``--tensorboard``, TensorBoard logs.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from controllers import (
    AdaptiveLQG,
    Controller,
    FixedLQG,
    IdentifiedModelFeatures,
    OracleModelFeatures,
    ResidualControl,
    episode_metrics,
    run_episode,
)
from spacecraft_env import ActionRepeat, env_id
from spacecraft_lab.control import SCENARIO_NAMES
from spacecraft_lab.plots import plot_learning_curves

__all__ = ["ACTION_REPEAT", "ALGORITHMS", "EVAL_SEEDS", "EVAL_WARMUP_SEED", "FEATURES",
           "HYPERPARAMETERS", "NormalizedPolicy", "ZeroTorque", "run_training"]

#: stable-baselines3 algorithms the job trains.
ALGORITHMS = ("ppo", "sac")
#: What the agent gets on top of the env: observation features, or (residual-*) a
#: controller whose action it corrects.
FEATURES = ("none", "identified", "identified-kept", "identified-kept-no-state", "oracle",
            "residual-adaptive", "residual-fixed")
#: ``IdentifiedModelFeatures`` keywords of each identified-features setting.
_IDENTIFIED = {
    "identified": {"keep_identifier": False, "include_state": True},
    "identified-kept": {"keep_identifier": True, "include_state": True},
    "identified-kept-no-state": {"keep_identifier": True, "include_state": False},
}
#: Base controller of each residual setting (``ResidualControl``).
_RESIDUAL = {"residual-adaptive": AdaptiveLQG, "residual-fixed": FixedLQG}
#: Evaluation episode seeds (disjoint from training seeds).
EVAL_SEEDS = (1000, 1001, 1002)
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
}


class ZeroTorque(Controller):
    """The trivial baseline: no torque at all."""

    name = "zero torque"

    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        return np.zeros(3, dtype=np.float32)


class NormalizedPolicy(Controller):
    """An SB3 model trained under ``VecNormalize``, as a harness controller.

    ``repeat``: the model was trained under
    :class:`~spacecraft_env.ActionRepeat`, so it decides every ``repeat``
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


def _make_env(scenario: str, features: str, env_kwargs: dict[str, Any]) -> gym.Env:
    env = gym.make(env_id(scenario), **env_kwargs)
    if features in _IDENTIFIED:
        env = IdentifiedModelFeatures(env, **_IDENTIFIED[features])
    elif features == "oracle":
        env = OracleModelFeatures(env)
    elif features in _RESIDUAL:
        env = ResidualControl(env, _RESIDUAL[features](env.unwrapped))
    return env


def _evaluate(controller: Controller, scenario: str, features: str,
              env_kwargs: dict[str, Any], seeds=EVAL_SEEDS) -> dict[str, float]:
    per_seed = []
    kept = _IDENTIFIED.get(features, {}).get("keep_identifier", False)
    shared = _make_env(scenario, features, env_kwargs) if kept else None
    if shared is not None:
        # one env: its identifier learns through a first, discarded episode and
        # is carried into every evaluated one
        run_episode(shared, controller, seed=EVAL_WARMUP_SEED)
    for seed in seeds:
        env = shared or _make_env(scenario, features, env_kwargs)
        traj = run_episode(env, controller, seed=seed)
        per_seed.append(episode_metrics(traj, env.unwrapped.model))
        if shared is None:
            env.close()
    if shared is not None:
        shared.close()
    return {"attitude_rms_deg": float(np.mean([m["attitude_rms_deg"] for m in per_seed])),
            "vibration_rms_mm": float(np.mean([m["vibration_rms_mm"] for m in per_seed])),
            "return": float(np.mean([m["return"] for m in per_seed])),
            "stable_share": float(np.mean([m["stable"] for m in per_seed]))}


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


def run_training(algo: str = "ppo", features: str = "none", timesteps: int = 100_000,
                 seeds: int = 1, out: str | Path = "results/train", *,
                 scenario: str = "docking", eval_every: int = 20_000,
                 tensorboard: str | None = None, progress: bool = True,
                 randomize: bool = False, repeat: int = ACTION_REPEAT,
                 reward: str = "bounded", first_seed: int = 0) -> dict:
    """Train, evaluate and save SB3 agents; see the module docstring.

    Seeds ``first_seed .. first_seed + seeds - 1`` are trained (so seeds can be
    split over processes; ``spacecraft rl-table`` pools directories of equal
    settings).

    ``timesteps`` and ``eval_every`` count env steps (0.1 s samples), also
    under ``repeat`` (agent decisions are ``timesteps / repeat``), so runs
    with different ``repeat`` compare at equal simulated time.
    """
    # optional dependency (the "rl" extra): imported where it is needed
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    algos = dict(zip(ALGORITHMS, (PPO, SAC), strict=True))
    if algo not in algos:
        raise ValueError(f"algo must be one of {ALGORITHMS}, got {algo!r}")
    if features not in FEATURES:
        raise ValueError(f"features must be one of {FEATURES}, got {features!r}")
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"scenario must be one of {sorted(SCENARIO_NAMES)}, got {scenario!r}")
    if timesteps < 1 or seeds < 1 or first_seed < 0:
        raise ValueError("timesteps and seeds must be >= 1, first_seed >= 0")
    env_kwargs = {"task": "slew", "randomize": bool(randomize), "reward": reward}
    # the env checks the reward form and the wrapper the repeat, before anything is written
    baseline_env = ActionRepeat(gym.make(env_id(scenario), **env_kwargs), repeat)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    baseline = _evaluate(AdaptiveLQG(baseline_env.unwrapped), scenario, "none", env_kwargs)
    fixed = _evaluate(FixedLQG(baseline_env.unwrapped), scenario, "none", env_kwargs)
    zero = _evaluate(ZeroTorque(), scenario, "none", env_kwargs)
    target = 2.0 * baseline["attitude_rms_deg"]

    runs = []
    with _one_torch_thread(torch):
        torch_threads = torch.get_num_threads()
        for seed in range(first_seed, first_seed + seeds):
            venv = VecNormalize(
                DummyVecEnv([lambda: Monitor(ActionRepeat(_make_env(scenario, features, env_kwargs),
                                                          repeat))]),
                norm_obs=True, norm_reward=True, clip_obs=10.0)
            venv.seed(seed)
            model = algos[algo]("MlpPolicy", venv, seed=seed, verbose=0,
                                tensorboard_log=tensorboard, **HYPERPARAMETERS[algo])
            curve: list[dict[str, float]] = []
            name = f"{algo}-{features}-seed{seed}"

            callback = _eval_callback(BaseCallback, model, venv, name, curve, timesteps,
                                     eval_every, scenario, features, env_kwargs, progress, repeat)
            model.learn(total_timesteps=-(-timesteps // repeat), callback=callback,
                        tb_log_name=name if tensorboard else "run")
            venv.training = False
            final = _evaluate(NormalizedPolicy(model, venv, name, repeat), scenario, features,
                              env_kwargs)
            model.save(out / f"{name}.zip")
            venv.save(str(out / f"{name}_vecnormalize.pkl"))
            reached = next((c["timesteps"] for c in curve if c["attitude_rms_deg"] <= target), None)
            runs.append({"seed": seed, "final": final, "curve": curve,
                         "steps_to_2x_adaptive": reached})

    metrics = {
        "algo": algo, "features": features, "scenario": scenario, "randomize": bool(randomize),
        "repeat": repeat, "reward": reward, "hyperparameters": HYPERPARAMETERS[algo],
        "timesteps": timesteps, "seeds": seeds, "eval_seeds": list(EVAL_SEEDS),
        "torch_threads": torch_threads,
        "adaptive_lqg": baseline, "fixed_lqg": fixed, "zero_torque": zero,
        "target_attitude_rms_deg": target, "runs": runs,
        "final_attitude_rms_deg": float(np.mean([r["final"]["attitude_rms_deg"] for r in runs])),
        "final_vibration_rms_mm": float(np.mean([r["final"]["vibration_rms_mm"] for r in runs])),
        "final_return": float(np.mean([r["final"]["return"] for r in runs])),
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    plot_learning_curves(out / "learning_curves.png", metrics)
    return metrics


def _eval_callback(base, model, venv, name, curve, timesteps, eval_every, scenario,
                  features, env_kwargs, progress, repeat):
    """SB3 callback: tqdm progress and a harness evaluation every ``eval_every`` env
    steps (``num_timesteps`` counts agent decisions, ``repeat`` env steps each)."""

    class EvalCallback(base):
        def __init__(self) -> None:
            super().__init__()
            self.bar = tqdm(total=timesteps, desc=name, disable=not progress)
            self.next_eval = eval_every

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs * repeat)
            if self.num_timesteps * repeat >= self.next_eval:
                self.next_eval += eval_every
                venv.training = False
                score = _evaluate(NormalizedPolicy(model, venv, name, repeat), scenario,
                                  features, env_kwargs)
                venv.training = True
                curve.append({"timesteps": int(self.num_timesteps * repeat), **score})
                for key, value in score.items():
                    self.logger.record(f"eval/{key}", value)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return EvalCallback()
