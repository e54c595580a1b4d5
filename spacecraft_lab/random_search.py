"""Augmented random search with each antithetic pair flown on the same episode.

Augmented random search (ARS; Mania, Guy and Recht, "Simple random search of
static linear policies is competitive for reinforcement learning", NeurIPS 2018;
sb3-contrib's ``ARS``) learns a policy's weights ``theta`` from episode returns
alone: each iteration draws ``n_delta`` directions ``delta_i``, flies
``theta + sigma delta_i`` and ``theta - sigma delta_i`` for one episode each, and
steps along ``sum_i (R_i+ - R_i-) delta_i`` over the ``n_top`` directions whose
better return is highest, scaled by the learning rate over ``n_top`` times the
returns' standard deviation.

On the task family each episode draws a new plant, a new slew and new sensor
noise, whose differences in return are far larger than those a small change of
the weights makes. :func:`paired_ars` returns ARS with common random numbers:

* the ``+`` and ``-`` candidates of a direction fly the same episode (the env is
  seeded with the same seed before each; the seeds come from a generator seeded
  by the model's seed), so ``R_i+ - R_i-`` is the direction's effect alone;
* each pair's mean return is removed before the update: the update itself only
  uses the differences, and the returns' standard deviation that scales the step
  is then that of the differences, not that of the episodes.

Measured on the family with the attitude error and rate observed in nominal units,
one decision a second (``python benchmarks/bench_ars.py``, ``docs/results/rl.md``): the
paired search was at 3.8x the oracle LQG's median cost after 1.6M env steps where
sb3-contrib's ARS with the same settings was at 12.6x.

sb3-contrib is an optional dependency (the ``rl`` extra): it is imported when
:func:`paired_ars` is called.
"""

from __future__ import annotations

from functools import cache, partial
from typing import Any

import numpy as np

__all__ = ["paired_ars"]


@cache
def paired_ars() -> type:
    """The paired ARS class (a subclass of ``sb3_contrib.ARS``).

    Returns
    -------
    type
        ``PairedARS``: constructed, trained, saved and loaded as sb3-contrib's
        ``ARS`` (the same keywords), single-process (``learn`` refuses
        ``async_eval``).
    """
    import copy

    import torch as th
    from sb3_contrib import ARS
    from stable_baselines3.common.evaluation import evaluate_policy

    class PairedARS(ARS):
        """sb3-contrib's ARS whose antithetic candidates fly the same episode, with
        each pair's mean return removed (:mod:`spacecraft_lab.random_search`)."""

        def _setup_model(self) -> None:
            super()._setup_model()
            self.episode_rng = np.random.default_rng(self.seed)

        def learn(self, *args: Any, **kwargs: Any) -> Any:
            if kwargs.get("async_eval") is not None:
                raise ValueError("PairedARS evaluates its candidates in one process "
                                 "(async_eval must be None)")
            return super().learn(*args, **kwargs)

        def evaluate_candidates(self, candidate_weights: th.Tensor, callback: Any,
                                async_eval: Any) -> th.Tensor:
            """Episode returns of the ``2 n_delta`` candidates, ``theta + delta_i`` and
            ``theta - delta_i`` on the same episode, each pair's mean removed."""
            seeds = self.episode_rng.integers(2**31 - 1, size=self.n_delta)
            returns = th.zeros(self.pop_size, device=self.device)
            policy = copy.deepcopy(self.policy)
            self.ep_info_buffer = []
            callback.on_rollout_start()
            for index in range(self.pop_size):
                policy.load_from_vector(candidate_weights[index].cpu())
                self.env.seed(int(seeds[index % self.n_delta]))
                rewards, lengths = evaluate_policy(
                    policy, self.env, n_eval_episodes=self.n_eval_episodes,
                    return_episode_rewards=True, warn=False,
                    callback=partial(self._trigger_callback, callback=callback,
                                     n_envs=self.env.num_envs))
                returns[index] = sum(rewards) + self.alive_bonus_offset * sum(lengths)
                self._mimic_monitor_wrapper(rewards, lengths)
            callback.on_rollout_end()
            mean = 0.5 * (returns[:self.n_delta] + returns[self.n_delta:])
            return returns - th.cat([mean, mean])

    return PairedARS
