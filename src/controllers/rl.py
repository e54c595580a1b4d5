"""Training stable-baselines3 agents on the spacecraft environments.

``spacecraft train --algo ppo|sac --features none|identified --timesteps N
--seeds S --out DIR`` calls :func:`run_training`: for each seed it trains an
agent on a registered environment (slew task), with observations and rewards
normalized by ``VecNormalize``, optionally with
:class:`~controllers.features.IdentifiedModelFeatures` appended; every
``eval_every`` steps the current policy is evaluated through the same
harness as the controllers (:func:`~controllers.harness.run_episode` with a
:class:`~controllers.base.PolicyController`). It writes the saved models,
``learning_curves.png``, ``metrics.json`` (final attitude RMS, return, and
the env steps needed to come within 2x of the adaptive LQR's attitude RMS on
the same evaluation seeds) and, with ``--tensorboard``, TensorBoard logs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from controllers.adaptive import AdaptiveLQR
from controllers.base import Controller
from controllers.experiment import ENV_IDS
from controllers.features import IdentifiedModelFeatures
from controllers.harness import episode_metrics, run_episode

__all__ = ["NormalizedPolicy", "comparison_table", "run_training"]

EVAL_SEEDS = (1000, 1001, 1002)


class NormalizedPolicy(Controller):
    """An SB3 model trained under ``VecNormalize``, as a harness controller."""

    def __init__(self, model, vec_normalize, name: str) -> None:
        self.model = model
        self.vec_normalize = vec_normalize
        self.name = name

    def act(self, obs, info: dict[str, Any] | None = None) -> np.ndarray:
        norm = self.vec_normalize.normalize_obs(np.asarray(obs, dtype=np.float32)[None])
        action, _ = self.model.predict(norm, deterministic=True)
        return np.asarray(action[0], dtype=np.float32)


def _make_env(scenario: str, features: str, env_kwargs: dict[str, Any]):
    env = gym.make(ENV_IDS[scenario], **env_kwargs)
    if features == "identified":
        env = IdentifiedModelFeatures(env)
    return env


def _evaluate(controller: Controller, scenario: str, features: str,
              env_kwargs: dict[str, Any], seeds=EVAL_SEEDS) -> dict[str, float]:
    rms, ret = [], []
    for seed in seeds:
        env = _make_env(scenario, features, env_kwargs)
        traj = run_episode(env, controller, seed=seed)
        m = episode_metrics(traj, env.unwrapped.model)
        rms.append(m["attitude_rms_deg"])
        ret.append(m["return"])
        env.close()
    return {"attitude_rms_deg": float(np.mean(rms)), "return": float(np.mean(ret))}


def run_training(algo: str = "ppo", features: str = "none", timesteps: int = 100_000,
                 seeds: int = 1, out: str | Path = "results/train", *,
                 scenario: str = "docking", eval_every: int = 20_000,
                 tensorboard: str | None = None, progress: bool = True) -> dict:
    """Train, evaluate and save SB3 agents; see the module docstring."""
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    algos = {"ppo": PPO, "sac": SAC}
    if algo not in algos:
        raise ValueError(f"algo must be one of {sorted(algos)}, got {algo!r}")
    if features not in ("none", "identified"):
        raise ValueError(f"features must be 'none' or 'identified', got {features!r}")
    if scenario not in ENV_IDS:
        raise ValueError(f"scenario must be one of {sorted(ENV_IDS)}, got {scenario!r}")
    if timesteps < 1 or seeds < 1:
        raise ValueError("timesteps and seeds must be >= 1")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    env_kwargs = {"task": "slew"}

    baseline_env = gym.make(ENV_IDS[scenario], **env_kwargs)
    baseline = _evaluate(AdaptiveLQR(baseline_env.unwrapped), scenario, "none", env_kwargs)
    target = 2.0 * baseline["attitude_rms_deg"]

    runs = []
    for seed in range(seeds):
        venv = VecNormalize(DummyVecEnv([lambda: _make_env(scenario, features, env_kwargs)]),
                            norm_obs=True, norm_reward=True, clip_obs=10.0)
        venv.seed(seed)
        model = algos[algo]("MlpPolicy", venv, seed=seed, verbose=0,
                            tensorboard_log=tensorboard)
        curve: list[dict[str, float]] = []
        name = f"{algo}-{features}-seed{seed}"

        callback = _eval_callback(BaseCallback, model, venv, name, curve, timesteps,
                                 eval_every, scenario, features, env_kwargs, progress)
        model.learn(total_timesteps=timesteps, callback=callback,
                    tb_log_name=name if tensorboard else "run")
        venv.training = False
        final = _evaluate(NormalizedPolicy(model, venv, name), scenario, features, env_kwargs)
        model.save(out / f"{name}.zip")
        venv.save(str(out / f"{name}_vecnormalize.pkl"))
        reached = next((c["timesteps"] for c in curve if c["attitude_rms_deg"] <= target), None)
        runs.append({"seed": seed, "final": final, "curve": curve,
                     "steps_to_2x_adaptive": reached})

    metrics = {
        "algo": algo, "features": features, "scenario": scenario, "timesteps": timesteps,
        "seeds": seeds, "eval_seeds": list(EVAL_SEEDS), "adaptive_lqr": baseline,
        "target_attitude_rms_deg": target, "runs": runs,
        "final_attitude_rms_deg": float(np.mean([r["final"]["attitude_rms_deg"] for r in runs])),
        "final_return": float(np.mean([r["final"]["return"] for r in runs])),
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    _plot_curves(out / "learning_curves.png", metrics)
    return metrics


def _eval_callback(base, model, venv, name, curve, timesteps, eval_every, scenario,
                  features, env_kwargs, progress):
    """SB3 callback: tqdm progress and a harness evaluation every ``eval_every`` steps."""

    class EvalCallback(base):
        def __init__(self) -> None:
            super().__init__()
            self.bar = tqdm(total=timesteps, desc=name, disable=not progress)
            self.next_eval = eval_every

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            if self.num_timesteps >= self.next_eval:
                self.next_eval += eval_every
                venv.training = False
                score = _evaluate(NormalizedPolicy(model, venv, name), scenario, features,
                                  env_kwargs)
                venv.training = True
                curve.append({"timesteps": int(self.num_timesteps), **score})
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return EvalCallback()


def comparison_table(directories) -> str:
    """Markdown table of several ``spacecraft train`` output directories."""
    rows, baseline = [], None
    for directory in directories:
        m = json.loads((Path(directory) / "metrics.json").read_text())
        baseline = m["adaptive_lqr"]
        reached = [r["steps_to_2x_adaptive"] for r in m["runs"]]
        rows.append(f"| {m['algo'].upper()} | {m['features']} | {m['timesteps']:,} "
                    f"| {m['final_attitude_rms_deg']:.3f} | {m['final_return']:.4g} "
                    f"| {', '.join('not reached' if x is None else f'{x:,}' for x in reached)} |")
    head = ["| agent | features | env steps | final attitude RMS (deg) | final return "
            "| env steps to <= 2x adaptive LQR RMS |", "|---|---|---|---|---|---|"]
    if baseline is not None:
        rows.append(f"| adaptive LQR | - | - | {baseline['attitude_rms_deg']:.3f} "
                    f"| {baseline['return']:.4g} | - |")
    return "\n".join(head + rows) + "\n"


def _plot_curves(path: Path, metrics: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for run in metrics["runs"]:
        if not run["curve"]:
            continue
        steps = [c["timesteps"] for c in run["curve"]]
        axes[0].plot(steps, [c["attitude_rms_deg"] for c in run["curve"]], "o-",
                     label=f"seed {run['seed']}")
        axes[1].plot(steps, [c["return"] for c in run["curve"]], "o-")
    axes[0].axhline(metrics["adaptive_lqr"]["attitude_rms_deg"], color="k", ls="--",
                    label="adaptive LQR")
    axes[0].axhline(metrics["target_attitude_rms_deg"], color="gray", ls=":",
                    label="2x adaptive LQR")
    axes[1].axhline(metrics["adaptive_lqr"]["return"], color="k", ls="--")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("attitude RMS (deg), eval seeds")
    axes[1].set_ylabel("return, eval seeds")
    for ax in axes:
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{metrics['algo'].upper()}, features: {metrics['features']}, "
                 f"{metrics['scenario']}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
