"""Saved agents: load one, and score it beside the LQGs on any episodes.

``spacecraft evaluate AGENT.zip [--episodes 10] [--first-seed 2000] [--json OUT]``
calls :func:`evaluate_agent`: it loads a model saved by ``spacecraft train``
(``<name>.zip``, its ``<name>_vecnormalize.pkl`` observation statistics and
the run's ``metrics.json`` beside them, which say how the agent was trained:
algorithm, features, scenario, reward, action repeat), flies it through the
controllers' harness on the episodes asked for, and scores the same
episodes with the oracle, adaptive, scheduled and fixed LQG: the common
quadratic cost from 100 s (median, mean, worst episode and each episode),
attitude RMS, vibration, share of stable episodes, and the agent's paired
ratios to each comparator. The default episodes (seeds 2000-2009) are
held out from training (seeds 0, 1, ...) and from the evaluation episodes
training selects its best checkpoint on (1000-1009).

The repository ships trained agents in ``agents/`` at its top level
(:data:`SHIPPED_AGENTS`; a source checkout installed with ``make`` or ``pip
install -e`` has them, a built wheel does not); ``docs/results/rl.md`` says
how each was trained and what it scores.
"""

from __future__ import annotations

import importlib.util
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from controllers.lqg import INTEGRAL_SETTLE_S
from spacecraft_lab.reporting import COMPARATOR_NAMES, improvement_references
from spacecraft_lab.rl_protocol import (
    improvement_probabilities,
    interval_estimates,
    protocol_table,
)
from spacecraft_lab.score_cache import default_cache
from spacecraft_lab.training import (
    ALGORITHMS,
    COMPARATORS,
    FEATURES,
    NormalizedPolicy,
    _evaluate,
    _make_env,
    _one_torch_thread,
    _score_comparators,
    _training_env_kwargs,
    algorithm_class,
    base_comparator,
    residual_scale,
)

__all__ = ["AGENT_DIRECTORY", "HELD_OUT_SEEDS", "SHIPPED_AGENTS", "SHIPPED_SEEDS", "evaluate_agent",
           "evaluation_table", "load_agent", "paired_ratio"]

#: Episodes :func:`evaluate_agent` scores by default: disjoint from the training seeds
#: and from the evaluation episodes training picks its best checkpoint on.
HELD_OUT_SEEDS = tuple(range(2000, 2010))
#: Where the repository keeps its trained agents.
AGENT_DIRECTORY = Path(__file__).resolve().parent.parent / "agents"
#: The shipped agents: name -> path of the model (``spacecraft evaluate NAME`` finds it).
SHIPPED_AGENTS = {
    "residual-scheduled-family":
        AGENT_DIRECTORY / "residual-scheduled-family" / "ppo-residual-scheduled-seed0.zip",
    "ars-averaged-family":
        AGENT_DIRECTORY / "ars-averaged-family" / "seed1" / "ars-attitude-error-averaged-seed1.zip",
    "ars-residual-scheduled-family":
        AGENT_DIRECTORY / "ars-residual-scheduled-family"
        / "ars-residual-scheduled-averaged-seed1.zip",
}
#: The shipped agents trained on several seeds: name -> every seed's model (``spacecraft
#: evaluate NAME`` scores them together; :func:`load_agent` loads the one of
#: :data:`SHIPPED_AGENTS`).
SHIPPED_SEEDS = {
    "ars-averaged-family": tuple(
        AGENT_DIRECTORY / "ars-averaged-family" / f"seed{k}"
        / f"ars-attitude-error-averaged-seed{k}.zip" for k in range(3)),
}
#: Training settings an agent's ``metrics.json`` must hold.
_SETTINGS = ("algo", "features", "scenario", "randomize", "reward", "repeat")


def _resolve(agent: str | Path) -> Path:
    """A shipped agent's name, or the path of a saved model (``.zip``)."""
    if str(agent) in SHIPPED_AGENTS:
        return SHIPPED_AGENTS[str(agent)]
    path = Path(agent)
    if path.suffix != ".zip":
        raise ValueError(f"agent must be a saved model (.zip) or one of "
                         f"{sorted(SHIPPED_AGENTS)}, got {str(agent)!r}")
    return path


def _settings(path: Path) -> dict[str, Any]:
    """The training settings of the model at ``path``, from its run's ``metrics.json``."""
    metrics_path = path.parent / "metrics.json"
    if not metrics_path.is_file():
        raise FileNotFoundError(f"{path} has no metrics.json beside it (the 'spacecraft train' "
                                "run's record, which says how the agent was trained)")
    try:
        metrics = json.loads(metrics_path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{metrics_path} is not JSON: {exc}") from None
    missing = [key for key in _SETTINGS if key not in metrics]
    if missing:
        raise ValueError(f"{metrics_path} lacks the training settings {missing}")
    settings = {key: metrics[key] for key in _SETTINGS}
    # a run saved before the key existed trained its residual base with the integral at once
    settle = metrics.get("base_integral_settle_s", 0.0)
    settings["base_integral_settle_s"] = INTEGRAL_SETTLE_S if settle is None else float(settle)
    if settings["algo"] not in ALGORITHMS or settings["features"] not in FEATURES:
        raise ValueError(f"{metrics_path}: algo {settings['algo']!r} / features "
                         f"{settings['features']!r} are not ones this version trains")
    trained, present = metrics.get("residual_scale"), residual_scale(settings["features"])
    if trained is not None and trained != present:
        raise ValueError(f"{metrics_path}: the agent was trained with a residual authority of "
                         f"{trained} of full torque; this version's {settings['features']!r} "
                         f"setting flies {present}")
    if not (isinstance(settings["repeat"], int) and settings["repeat"] >= 1):
        raise ValueError(f"{metrics_path}: repeat must be an integer >= 1, "
                         f"got {settings['repeat']!r}")
    return settings


def load_agent(agent: str | Path) -> tuple[NormalizedPolicy, dict[str, Any]]:
    """Load a saved agent as a harness controller.

    Parameters
    ----------
    agent : str or Path
        A model saved by ``spacecraft train`` (``<name>.zip``, with
        ``<name>_vecnormalize.pkl`` and the run's ``metrics.json`` in the
        same directory), or a name of :data:`SHIPPED_AGENTS`.

    Returns
    -------
    policy : NormalizedPolicy
        The deterministic policy behind its fixed observation statistics,
        deciding every ``repeat`` env steps as in training.
    settings : dict
        ``algo``, ``features``, ``scenario``, ``randomize``, ``reward``,
        ``repeat``, ``env_kwargs`` (the environment's keywords), ``path`` and
        ``base_integral_settle_s`` (the residual base's integral settle time it
        was trained with, s: 0 for runs saved before it was recorded).

    Raises
    ------
    ImportError
        Without the ``rl`` extra.
    FileNotFoundError, ValueError
        For a missing or inconsistent file, naming it.
    """
    path = _resolve(agent)
    if not path.is_file():
        raise FileNotFoundError(f"no saved model at {path}")
    statistics = path.with_name(f"{path.stem}_vecnormalize.pkl")
    if not statistics.is_file():
        raise FileNotFoundError(f"{path} has no observation statistics beside it "
                                f"({statistics.name})")
    settings = _settings(path)
    if importlib.util.find_spec("stable_baselines3") is None:
        raise ImportError("loading an agent needs the 'rl' extra (stable-baselines3): run "
                          "`make test`, or `pip install -c constraints.txt -e \".[rl]\"`")
    # optional dependency (the "rl" extra): imported where it is needed
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    env_kwargs = _training_env_kwargs(settings["randomize"], settings["reward"])
    venv = DummyVecEnv([lambda: _make_env(settings["scenario"], settings["features"],
                                          env_kwargs, settings["base_integral_settle_s"])])
    normalization = VecNormalize.load(str(statistics), venv)
    normalization.training = False
    model = algorithm_class(settings["algo"]).load(str(path), device="cpu")
    if model.observation_space.shape != venv.observation_space.shape:
        raise ValueError(f"{path} expects observations of shape "
                         f"{model.observation_space.shape}, its environment gives "
                         f"{venv.observation_space.shape}")
    policy = NormalizedPolicy(model, normalization, path.stem, settings["repeat"])
    return policy, {**settings, "env_kwargs": env_kwargs, "path": str(path)}


def paired_ratio(mine: Sequence[float], theirs: Sequence[float]) -> dict[str, float]:
    """Median and worst of the per-episode cost ratios ``mine / theirs``.

    Parameters
    ----------
    mine, theirs : sequence of float
        Costs of the same episodes, in the same order (``inf`` for a failure).

    Returns
    -------
    dict
        ``median`` and ``worst`` (largest) ratio; an undefined ratio (0 / 0, or a
        failure on both sides) counts as infinite.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.asarray(mine, dtype=float) / np.asarray(theirs, dtype=float)
    ratio = np.where(np.isnan(ratio), np.inf, ratio)
    return {"median": float(np.median(ratio)), "worst": float(np.max(ratio))}


#: Settings every training seed of one evaluation must share.
_SHARED = ("algo", "features", "scenario", "randomize", "reward", "repeat", "env_kwargs",
           "base_integral_settle_s")


def evaluate_agent(agent: str | Path | Sequence[str | Path],
                   seeds: tuple[int, ...] = HELD_OUT_SEEDS,
                   workers: int | None = None, progress: bool = True,
                   cache: bool = True) -> dict[str, Any]:
    """Score a saved agent (one or several training seeds of one setting) and the LQG
    comparators on the same episodes.

    Parameters
    ----------
    agent : str, Path or sequence of them
        See :func:`load_agent`; several: the training seeds of one setting (the same
        algorithm, observations, scenario, reward and environment), scored together by
        the protocol (a ``(training seeds, draws)`` matrix). A name of
        :data:`SHIPPED_SEEDS` stands for every seed it ships.
    seeds : tuple of int
        Episode seeds (default :data:`HELD_OUT_SEEDS`), all >= 0.
    workers : int, optional
        Processes scoring the comparators side by side (default: the cores);
        the scores do not depend on it.
    progress : bool
        Show progress bars.
    cache : bool
        Read the comparators' scores from :func:`spacecraft_lab.score_cache.default_cache`
        and store new ones there (default); False scores them again.

    Returns
    -------
    dict
        ``agent`` (the first seed's :func:`load_agent` settings), ``agents`` (every seed's
        model path), ``eval_seeds``, ``scores`` (name -> the harness's scores:
        ``cost_after_100s`` median, ``_mean``, ``_worst``, ``_per_seed``,
        ``worst_episode_seed``, attitude RMS, vibration, return, ``stable_share``; the
        agent's under ``"agent"``, each draw's cost the mean over its training seeds, and
        per training seed under ``agent_runs``) and ``agent_over`` (comparator -> median
        and worst of the agent's paired per-episode cost ratios) and ``protocol``
        (:mod:`spacecraft_lab.rl_protocol`: ``estimates``, name -> IQM, median and mean
        with 95 % intervals over training seeds and draws; ``improvement``, the
        probability that the agent costs less than its base, where it has one, and the
        adaptive LQG on a draw; ``draws``; ``training_seeds``).

    Raises
    ------
    ValueError
        For no episode seed, a negative one, or training seeds of different settings.
    """
    seeds = tuple(int(s) for s in seeds)
    if not seeds or min(seeds) < 0:
        raise ValueError(f"seeds must be one or more integers >= 0, got {seeds}")
    agents = [agent] if isinstance(agent, str | Path) else list(agent)
    # a shipped agent trained on several seeds stands for all of them
    agents = [path for a in agents for path in SHIPPED_SEEDS.get(str(a), (a,))]
    if not agents:
        raise ValueError("agent must name at least one saved model")
    loaded = [load_agent(a) for a in agents]
    settings = loaded[0][1]
    for _, other in loaded[1:]:
        differ = [key for key in _SHARED if other[key] != settings[key]]
        if differ:
            raise ValueError(f"{other['path']} was trained otherwise than {settings['path']} "
                             f"({', '.join(differ)}): the seeds of one evaluation must share "
                             "their setting")
    import torch

    with _one_torch_thread(torch):      # as in training: results independent of the cores
        runs = [_evaluate(policy, settings["scenario"], settings["features"],
                          settings["env_kwargs"], seeds,
                          base_settle_s=settings["base_integral_settle_s"])
                for policy, _ in loaded]
    matrix = np.array([run["cost_after_100s_per_seed"] for run in runs], dtype=float)
    scores = {"agent": runs[0] if len(runs) == 1 else _pooled(runs, seeds),
              **_score_comparators(settings["scenario"], settings["env_kwargs"],
                                   seeds, workers, progress, when="Then",
                                   cache=default_cache() if cache else None)}
    mine = scores["agent"]["cost_after_100s_per_seed"]
    agent_over = {key: paired_ratio(mine, scores[key]["cost_after_100s_per_seed"])
                  for key, _ in COMPARATORS}
    costs = {key: score["cost_after_100s_per_seed"] for key, score in scores.items()}
    costs["agent"] = matrix
    over = improvement_references(base_comparator(settings["features"]))
    protocol = {"estimates": interval_estimates(costs),
                "improvement": improvement_probabilities(costs, "agent", over),
                "draws": len(seeds), "training_seeds": len(runs)}
    result = {"agent": settings, "agents": [s["path"] for _, s in loaded],
              "eval_seeds": list(seeds), "scores": scores, "agent_over": agent_over,
              "protocol": protocol}
    if len(runs) > 1:
        result["agent_runs"] = runs
    return result


def _pooled(runs: list[dict[str, Any]], seeds: tuple[int, ...]) -> dict[str, Any]:
    """The harness's scores of several training seeds as one controller's: each draw's
    cost the mean over the seeds (infinite if any crashed), the other figures averaged."""
    with np.errstate(invalid="ignore"):
        costs = np.mean([run["cost_after_100s_per_seed"] for run in runs], axis=0)
    return {"cost_after_100s": float(np.median(costs)),
            "cost_after_100s_mean": float(np.mean(costs)),
            "cost_after_100s_worst": float(np.max(costs)),
            "worst_episode_seed": int(seeds[int(np.argmax(costs))]),
            "cost_after_100s_per_seed": costs.tolist(),
            **{key: float(np.mean([run[key] for run in runs]))
               for key in ("attitude_rms_deg", "vibration_rms_mm", "return", "stable_share")}}


def evaluation_table(result: dict[str, Any]) -> str:
    """Markdown table of :func:`evaluate_agent`'s result.

    Returns
    -------
    str
        Markdown: one row per controller or agent.
    """
    settings = result["agent"]
    models = [Path(p).name for p in result.get("agents", [settings["path"]])]
    pooled = (f"; the agent's row: each episode's cost the mean over its {len(models)} "
              "training seeds" if len(models) > 1 else "")
    lines = [f"{settings['algo'].upper()} {settings['features']} on {settings['scenario']} "
             f"({', '.join(models)}){pooled}, {len(result['eval_seeds'])} episodes "
             f"(seeds {result['eval_seeds'][0]}-{result['eval_seeds'][-1]}); common cost "
             "from 100 s",
             "",
             "| controller | median | mean | worst (seed) | agent / it, median [worst] "
             "| stable |",
             "|---|---|---|---|---|---|"]
    for key, score in result["scores"].items():
        over = result["agent_over"].get(key)
        ratio = "-" if over is None else f"{over['median']:.3g} [{over['worst']:.3g}]"
        lines.append(f"| {COMPARATOR_NAMES.get(key, key)} | {score['cost_after_100s']:.4g} | "
                     f"{score['cost_after_100s_mean']:.4g} | "
                     f"{score['cost_after_100s_worst']:.4g} ({score['worst_episode_seed']}) | "
                     f"{ratio} | {100 * score['stable_share']:.0f} % |")
    protocol = result.get("protocol")
    if protocol is None:
        return "\n".join(lines)
    names = {COMPARATOR_NAMES.get(k, k): v for k, v in protocol["estimates"].items()}
    better = {COMPARATOR_NAMES.get(k, k): v for k, v in protocol["improvement"].items()}
    lines += ["", "The evaluation protocol (docs/design/evaluation.md, \"RL agents\"): the "
              "cost from 100 s over the draws, 95 % stratified-bootstrap intervals over "
              "seeds and draws:", "",
              protocol_table(names, better, "agent",
                             {"agent": protocol.get("training_seeds", 1)}, protocol["draws"])]
    return "\n".join(lines).rstrip("\n")
