"""How well do the physical features estimate the plant in a quiet loop, per identifier setting?

On ``FlexibleSpacecraftFamily-v2`` (slew task, 40 dB), the gain-scheduled LQG flies
each held-out episode (seeds 2000-2009 by default) while several
:class:`controllers.PhysicalFeatures` wrappers, each on its own identifier (the
default's settings, overridden as listed in :data:`VARIANTS`), observe the same
loop, with :class:`controllers.PrivilegedFeatures` (the truth's vector) beside them.
At every refresh (1 s) each vector is compared with the truth's; printed, from
60 s: the RMS error of the three log-diagonal rigid-gain channels and of the two
log-frequency channels, median [worst] over the episodes, beside the nominal
plant's vector (the guess without an identifier), and each identifier's update
cost (CPU time in the same run, and its ratio to the default's).

Usage: ``python benchmarks/bench_feature_estimates.py [--episodes 10] [--first-seed 2000]
[--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import PhysicalFeatures, PrivilegedFeatures, ScheduledLQG, run_episode
from controllers.features import PHYSICAL_FEATURE_NAMES
from identifiers import CLOSED_LOOP_SETTINGS, default_identifier
from spacecraft_conventions import single_threaded_blas

#: Identifier settings compared: label -> overrides of the default's.
VARIANTS: Mapping[str, Mapping[str, Any]] = {
    "default (open-loop settings)": {},
    "closed-loop settings": dict(CLOSED_LOOP_SETTINGS),
    "closed-loop settings, couplings' walk 1e-4": {**CLOSED_LOOP_SETTINGS,
                                                   "coupling_drift": 1e-4},
    "default without re-searches": {"rediscover": None},
}
#: The channels scored: the rigid gain's log diagonal and the modes' log frequencies.
GAIN = [PHYSICAL_FEATURE_NAMES.index(f"log_gain_{a}") for a in ("xx", "yy", "zz")]
FREQUENCY = [PHYSICAL_FEATURE_NAMES.index(f"log_freq_{i}") for i in (1, 2)]
#: Errors are scored from this time on, s (after the identifiers' warm-ups).
FROM_S = 60.0


class _TimedIdentifier:
    """An identifier whose ``update`` adds its CPU time to ``seconds`` and counts itself
    in ``updates``; everything else is the identifier's."""

    def __init__(self, identifier: Any) -> None:
        self.__dict__["_inner"] = identifier
        self.__dict__["seconds"] = 0.0
        self.__dict__["updates"] = 0

    def update(self, u: np.ndarray, y: np.ndarray) -> Any:
        start = time.process_time()
        try:
            return self._inner.update(u, y)
        finally:
            self.__dict__["seconds"] += time.process_time() - start
            self.__dict__["updates"] += 1

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name == "_inner":    # a copy's, before its state is set
            raise AttributeError(name)
        return getattr(self._inner, name)


class _Recorder(gym.Wrapper):
    """Hands the controller the env's own observation and records the appended vectors
    (each wrapper's, then the truth's) with the time at every refresh."""

    def __init__(self, env: gym.Env, width: int, every: int = 10) -> None:
        super().__init__(env)
        self.width, self.every, self.rows, self._steps = width, every, [], 0
        self._own = env.unwrapped.observation_space.shape[0]
        self.observation_space = env.unwrapped.observation_space

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict]:
        obs, info = self.env.reset(**kwargs)
        self._steps = 0
        return obs[:self._own], info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._steps % self.every == 0:
            self.rows.append((self.env.unwrapped.time, obs[-self.width:].astype(float)))
        self._steps += 1
        return obs[:self._own], reward, terminated, truncated, info


def episode(seed: int) -> tuple[dict[str, tuple[float, float]], dict[str, tuple[float, int]]]:
    """One episode: each variant's (gain, frequency) RMS errors and the nominal guess's,
    and each identifier's update time (s) and number of updates."""
    env = gym.make("FlexibleSpacecraftFamily-v2", task="slew")
    base = env.unwrapped
    wrapped, timed = env, {}
    for label, overrides in VARIANTS.items():
        timed[label] = _TimedIdentifier(default_identifier(
            base.observation_layout.sensors(), n=base.model.n, dt=base.model.dt, **overrides))
        wrapped = PhysicalFeatures(wrapped, identifier=timed[label])
    wrapped = PrivilegedFeatures(wrapped)
    d = wrapped.n_features
    recorder = _Recorder(wrapped, d * (len(VARIANTS) + 1))
    run_episode(recorder, ScheduledLQG(env), seed=seed)
    times = np.array([t for t, _ in recorder.rows])
    vectors = np.array([v for _, v in recorder.rows])[times >= FROM_S]
    truth = vectors[:, -d:]

    def rms(estimate: np.ndarray, cols: list[int]) -> float:
        return float(np.sqrt(np.mean((estimate[:, cols] - truth[:, cols]) ** 2)))

    errors = {label: (rms(vectors[:, i * d:(i + 1) * d], GAIN),
                      rms(vectors[:, i * d:(i + 1) * d], FREQUENCY))
              for i, label in enumerate(VARIANTS)}
    nominal = np.zeros_like(truth)          # every channel is 0 at the nominal plant
    errors["nominal plant's vector"] = (rms(nominal, GAIN), rms(nominal, FREQUENCY))
    env.close()
    return errors, {label: (t.seconds, t.updates) for label, t in timed.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=2000)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    seeds = range(args.first_seed, args.first_seed + args.episodes)
    errors: dict[str, list] = {}
    seconds: dict[str, float] = dict.fromkeys(VARIANTS, 0.0)
    updates: dict[str, int] = dict.fromkeys(VARIANTS, 0)
    with single_threaded_blas:
        for seed in seeds:
            per_episode, spent = episode(seed)
            for label, value in per_episode.items():
                errors.setdefault(label, []).append(value)
            for label, (spent_s, count) in spent.items():
                seconds[label] += spent_s
                updates[label] += count
            print(f"episode {seed}: " + "; ".join(
                f"{label} {g:.3f} / {f:.3f}" for label, (g, f) in per_episode.items()),
                flush=True)
    print(f"\nRMS error from {FROM_S:g} s, median [worst] over episodes {seeds.start}-"
          f"{seeds.stop - 1}; update cost (CPU time per update, this run)")
    width = max(map(len, errors))
    per_update = {label: seconds[label] / updates[label] for label in VARIANTS}
    default = per_update[next(iter(VARIANTS))]
    print(f"{'identifier':<{width}}  {'log-gain':>15}  {'log-frequency':>15}  {'us':>6}  "
          f"{'/ default':>9}")
    for label, values in errors.items():
        a = np.array(values)
        cost = (f"{1e6 * per_update[label]:6.0f}  {per_update[label] / default:9.2f}"
                if label in per_update else "")
        print(f"{label:<{width}}  {np.median(a[:, 0]):7.3f} [{a[:, 0].max():5.2f}]  "
              f"{np.median(a[:, 1]):7.3f} [{a[:, 1].max():5.2f}]  {cost}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"errors": errors,
                       "update_us": {k: 1e6 * v for k, v in per_update.items()}}, fh, indent=1)


if __name__ == "__main__":
    main()
