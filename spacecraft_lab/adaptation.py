"""What the identifier is worth to an agent, measured RMA-style.

``spacecraft adapt AGENT.zip [AGENT.zip ...] [--episodes 20] [--out DIR]``
calls :func:`run_adaptation` on policies that ``spacecraft train`` trained
with the true plant's parameters observed (``--features privileged``,
``residual-scheduled-privileged``, ``residual-fixed-privileged`` or
``residual-scheduled-averaged-privileged``: :class:`controllers.PrivilegedFeatures`,
the rigid-body gain with the actuator efficiency, the dominant modes and the paddle
angle). Each source's vector is put where the setting reads the truth's (the
``parameters`` of :func:`spacecraft_lab.training._make_env`), so the policy flies its
training env with only the vector changed. For each policy it

1. flies the policy (the truth observed) on ``episodes`` episodes of the
   family (seeds from :data:`COLLECTION_SEED`, disjoint from training, from
   checkpoint selection and from the scored episodes), recording the
   identifier's :class:`controllers.PhysicalFeatures` beside the privileged
   vector at every refresh;
2. fits an :class:`controllers.AdaptationModule` on those pairs (the
   policy's own rollouts, as rapid motor adaptation learns its module);
3. scores the same policy on the held-out episodes
   (:data:`spacecraft_lab.agents.HELD_OUT_SEEDS`) three times, the vector
   from the truth, from the adaptation module
   (:class:`controllers.EstimatedFeatures`) and from the nominal plant
   (``PrivilegedFeatures(source="nominal")``), beside the oracle, scheduled
   and fixed LQG on the same episodes: the common quadratic cost from
   100 s, with paired ratios;
4. measures the estimate against the truth on those episodes (RMS error per
   channel group from 60 s), beside the identifier's raw vector and the
   nominal one.

``spacecraft adapt`` writes ``adaptation.json``, ``table.md`` and
``adaptation.png`` (:func:`spacecraft_lab.plots.plot_adaptation`).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from controllers import (
    AdaptationModule,
    EstimatedFeatures,
    PhysicalFeatures,
    PrivilegedFeatures,
    run_episode,
)
from spacecraft_env import env_id
from spacecraft_lab.agents import HELD_OUT_SEEDS, load_agent, paired_ratio
from spacecraft_lab.score_cache import default_cache
from spacecraft_lab.training import _evaluate, _make_env, _one_torch_thread, _score_comparators

__all__ = ["COLLECTION_SEED", "SOURCES", "adaptation_table", "run_adaptation"]

#: First episode seed of the adaptation module's training rollouts (training uses
#: 0, 1, ...; checkpoint selection 1000-1009; the scored episodes 2000-2009).
COLLECTION_SEED = 3000
#: The three parameter vectors the same policy flies with.
SOURCES = ("true", "estimated", "nominal")
#: Channel groups of the error report (two modes): name -> channels.
_GROUPS = {"gain": slice(0, 6), "frequency": slice(7, 9), "damping": slice(9, 11)}
#: Errors are measured from this time on (the identifier's 50 s warm-up is over).
_ERROR_FROM_S = 60.0


def _unprivileged(features: str) -> str:
    """The training setting without its privileged vector (``privileged`` -> ``none``)."""
    if features == "privileged":
        return "none"
    if features.endswith("-privileged"):
        return features[:-len("-privileged")]
    raise ValueError(f"the agent was trained with features {features!r}; an RMA comparison "
                     "needs a policy trained on the truth's parameters (features 'privileged' "
                     "or 'residual-*-privileged')")


class _PairedVectors(gym.ObservationWrapper):
    """The identifier's physical vector and the truth's side by side: appends the
    privileged vector alone (what the policy was trained on) and records both at every
    refresh with its time (s)."""

    def __init__(self, env: gym.Env, every: int = 10) -> None:
        inner = PrivilegedFeatures(PhysicalFeatures(env, every=every), every=every)
        super().__init__(inner)
        self.d, self.every = inner.n_features, int(every)
        size = inner.observation_space.shape[0] - self.d
        self.observation_space = gym.spaces.Box(
            np.delete(inner.observation_space.low, np.s_[size - self.d:size]),
            np.delete(inner.observation_space.high, np.s_[size - self.d:size]),
            dtype=inner.observation_space.dtype)
        self.records: list[tuple[np.ndarray, np.ndarray, float]] = []
        self._steps = 0

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        self._steps = 0
        return super().reset(**kwargs)

    def step(self, action: Any) -> tuple[np.ndarray, Any, bool, bool, dict[str, Any]]:
        kept = len(self.records)
        obs, reward, terminated, truncated, info = super().step(action)
        if terminated or truncated:
            del self.records[kept:]            # no decision follows the last observation
        return obs, reward, terminated, truncated, info

    def observation(self, observation: np.ndarray) -> np.ndarray:
        d = self.d
        if self._steps % self.every == 0:
            self.records.append((observation[-2 * d:-d].astype(float),
                                 observation[-d:].astype(float), self.env.unwrapped.time))
        self._steps += 1
        return np.concatenate([observation[:-2 * d], observation[-d:]])


def _paired_rollouts(policy: Any, make: Any, seeds: Sequence[int],
                     every: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fly ``policy`` with the truth observed; return the physical and privileged vectors
    at every refresh and the refresh times (s). ``make(parameters)``: the setting's env
    with ``parameters`` appending its parameter vector."""
    records: list[tuple[np.ndarray, np.ndarray, float]] = []
    for seed in seeds:
        paired: list[_PairedVectors] = []

        def parameters(env: gym.Env, into: list = paired) -> gym.Env:
            into.append(_PairedVectors(env, every))
            return into[-1]

        env = make(parameters)
        run_episode(env, policy, seed=int(seed))
        records.extend(paired[0].records)
        env.close()
    physical, privileged, times = zip(*records, strict=True)
    return (np.asarray(physical, dtype=float), np.asarray(privileged, dtype=float),
            np.asarray(times, dtype=float))


def _group_errors(estimate: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """RMS error of each channel group (:data:`_GROUPS`)."""
    return {group: float(np.sqrt(np.mean((estimate[:, cols] - truth[:, cols]) ** 2)))
            for group, cols in _GROUPS.items()}


def run_adaptation(agents: Sequence[str | Path], episodes: int = 20,
                   seeds: Sequence[int] = HELD_OUT_SEEDS, workers: int | None = None,
                   progress: bool = True, cache: bool = True) -> dict[str, Any]:
    """The RMA comparison of one or more policies trained on the truth's parameters.

    Parameters
    ----------
    agents : sequence of str or Path
        Saved models of ``spacecraft train`` with ``--features privileged`` or
        ``residual-*-privileged``, all of the same setting.
    episodes : int
        Rollouts per policy that train its adaptation module (seeds
        :data:`COLLECTION_SEED` on).
    seeds : sequence of int
        The scored episodes (default :data:`spacecraft_lab.agents.HELD_OUT_SEEDS`).
    workers : int, optional
        Processes scoring the LQG comparators (default: the cores).
    progress : bool
        Show a progress bar.
    cache : bool
        Read the comparators' scores from :func:`spacecraft_lab.score_cache.default_cache`
        and store new ones there (default); False scores them again.

    Returns
    -------
    dict
        ``agents`` (each policy's path, its scores per source, the paired
        ratios estimated/true and nominal/estimated and to the comparators,
        and the parameter errors per channel group of the estimate, the
        identifier's raw vector and the nominal one), ``comparators`` (the
        LQGs' scores), ``eval_seeds``, ``collection_seeds``.

    Raises
    ------
    ValueError
        For no agent, ``episodes < 1``, agents of different settings or a
        setting without the privileged vector.
    """
    if not agents:
        raise ValueError("give at least one agent")
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    seeds = tuple(int(s) for s in seeds)
    loaded = [load_agent(agent) for agent in agents]
    settings = loaded[0][1]
    for _, other in loaded[1:]:
        if any(other[key] != settings[key] for key in ("features", "scenario", "reward")):
            raise ValueError("the agents must share their training setting; "
                             f"{other['path']} differs from {settings['path']}")
    features = settings["features"]
    base = _unprivileged(features)
    scenario, env_kwargs = settings["scenario"], settings["env_kwargs"]

    def make(parameters: Any) -> gym.Env:
        return _make_env(scenario, features, env_kwargs, settings["base_integral_settle_s"],
                         parameters=parameters)

    collection = tuple(range(COLLECTION_SEED, COLLECTION_SEED + int(episodes)))
    comparators = _score_comparators(scenario, env_kwargs, seeds, workers, progress,
                                     when="First", cache=default_cache() if cache else None)
    import torch

    results = []
    bar = tqdm(total=len(loaded) * 4, desc="policies x (rollouts, 3 sources)",
               disable=not progress, leave=False)
    with _one_torch_thread(torch):
        for policy, agent in loaded:
            physical, privileged, _ = _paired_rollouts(policy, make, collection)
            module = AdaptationModule().fit(physical, privileged)
            bar.update()
            makers = {"true": lambda: make(PrivilegedFeatures),
                      "estimated": lambda m=module: make(lambda env: EstimatedFeatures(env, m)),
                      "nominal": lambda: make(partial(PrivilegedFeatures, source="nominal"))}
            scores = {}
            for source in SOURCES:
                scores[source] = _evaluate(policy, scenario, base, env_kwargs, seeds,
                                           make_env=makers[source])
                bar.update()
            # the parameters themselves on the scored episodes, the truth flown
            phys, priv, times = _paired_rollouts(policy, make, seeds)
            late = times >= _ERROR_FROM_S
            # the nominal vector depends on the scenario's nominal plant alone
            nominal_env = PrivilegedFeatures(gym.make(env_id(scenario), **env_kwargs),
                                             source="nominal")
            nominal = np.broadcast_to(nominal_env.nominal_vector, priv[late].shape)
            nominal_env.close()
            errors = {"estimated": _group_errors(module.predict(phys[late]), priv[late]),
                      "identifier": _group_errors(phys[late], priv[late]),
                      "nominal": _group_errors(nominal, priv[late])}
            per = {source: scores[source]["cost_after_100s_per_seed"] for source in SOURCES}
            results.append({
                "path": agent["path"], "scores": scores, "errors": errors,
                "estimated_over_true": paired_ratio(per["estimated"], per["true"]),
                "nominal_over_estimated": paired_ratio(per["nominal"], per["estimated"]),
                "over": {f"{source}/{key}": paired_ratio(per[source],
                                                    comp["cost_after_100s_per_seed"])
                         for source in SOURCES
                         for key, comp in comparators.items() if key != "zero_torque"}})
    bar.close()
    return {"features": settings["features"], "scenario": scenario,
            "eval_seeds": list(seeds), "collection_seeds": list(collection),
            "comparators": comparators, "agents": results}


def adaptation_table(result: dict[str, Any]) -> str:
    """Markdown tables of :func:`run_adaptation`'s result.

    Returns
    -------
    str
        Markdown: one table per setting.
    """
    seeds = result["eval_seeds"]
    lines = [f"RMA comparison: {result['features']} on {result['scenario']}, "
             f"{len(result['agents'])} policies, episodes {seeds[0]}-{seeds[-1]}, adaptation "
             f"module fitted on {len(result['collection_seeds'])} rollouts each; common cost "
             "from 100 s, median / mean [worst episode]",
             "",
             "| policy | true parameters | estimated | nominal | estimated / true, paired "
             "median [worst] | nominal / estimated | estimated / scheduled LQG |",
             "|---|---|---|---|---|---|---|"]
    for agent in result["agents"]:
        cells = [f"{s['cost_after_100s']:.4g} / {s['cost_after_100s_mean']:.4g} "
                 f"[{s['cost_after_100s_worst']:.3g}]"
                 for s in (agent["scores"][source] for source in SOURCES)]
        est, nom = agent["estimated_over_true"], agent["nominal_over_estimated"]
        sched = agent["over"]["estimated/scheduled_lqg"]
        lines.append(f"| {Path(agent['path']).stem} | {' | '.join(cells)} | "
                     f"{est['median']:.3g} [{est['worst']:.3g}] | "
                     f"{nom['median']:.3g} [{nom['worst']:.3g}] | "
                     f"{sched['median']:.3g} [{sched['worst']:.3g}] |")
    lines += ["", "| comparator | median | mean [worst] |", "|---|---|---|"]
    for key, score in result["comparators"].items():
        lines.append(f"| {key.replace('_', ' ')} | {score['cost_after_100s']:.4g} | "
                     f"{score['cost_after_100s_mean']:.4g} "
                     f"[{score['cost_after_100s_worst']:.3g}] |")
    lines += ["", f"Parameter error from {_ERROR_FROM_S:g} s on the same episodes (RMS, frame "
              "units: log gain, log frequency, 10 x damping):", "",
              "| policy | vector | gain | frequency | damping |", "|---|---|---|---|---|"]
    for agent in result["agents"]:
        for vector, errors in agent["errors"].items():
            lines.append(f"| {Path(agent['path']).stem} | {vector} | {errors['gain']:.3g} | "
                         f"{errors['frequency']:.3g} | {errors['damping']:.3g} |")
    return "\n".join(lines)
