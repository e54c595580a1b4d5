"""Writing a controller: subclass ``controllers.Controller`` and score it in the harness.

A PD law whose gains follow the identifier's rigid-body gain (so its bandwidth
stays put when the inertia changes), flown on the docking scenario beside the
fixed and oracle LQG, judged on the common quadratic cost from 100 s.

    python examples/custom_controller.py [--seeds 3] [--steps 2500]
"""

import argparse

import gymnasium as gym
import numpy as np

from controllers import Controller, FixedLQG, OracleLQG, episode_metrics, run_episode
from identifiers import CLOSED_LOOP_SETTINGS, default_identifier


class IdentifiedPD(Controller):
    """PD on the attitude error, gains scaled by the identified inverse inertia."""

    name = "identified PD"

    def __init__(self, env: gym.Env, bandwidth_rad_s: float = 0.1, damping: float = 0.9):
        self.env = env
        self.bandwidth, self.damping = bandwidth_rad_s, damping
        self.max_torque = env.max_torque
        self.nominal_gain = np.linalg.inv(env.model.nominal().inertia(0.0))
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.identifier = default_identifier(**CLOSED_LOOP_SETTINGS)
        self.last = None

    def act(self, obs: np.ndarray, info: dict | None = None) -> np.ndarray:
        y = np.asarray(obs[:10], dtype=float)             # attitude, rate, deflections
        if self.last is not None:
            self.identifier.update(*self.last)
        estimate = self.identifier.rigid_gain
        gain = self.nominal_gain if estimate is None else estimate.gain
        inertia = np.linalg.inv(0.5 * (gain + gain.T))      # kg m^2
        error = y[:3] - info["reference"]
        w = self.bandwidth
        torque = -inertia @ (w * w * error + 2 * self.damping * w * y[3:6])
        action = np.clip(torque / self.max_torque, -1.0, 1.0)
        self.last = (action * self.max_torque, y)
        return action.astype(np.float32)


parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--seeds", type=int, default=3)
parser.add_argument("--steps", type=int, default=2500)
args = parser.parse_args()

results: dict[str, list[float]] = {}
for seed in range(args.seeds):
    for make in (IdentifiedPD, FixedLQG, OracleLQG):
        env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2", task="slew",
                       max_episode_steps=args.steps)
        ctrl = make(env.unwrapped)
        m = episode_metrics(run_episode(env, ctrl, seed=seed), env.unwrapped.model)
        results.setdefault(ctrl.name, []).append(m["cost_after_100s"])
for name, costs in results.items():
    print(f"{name:>15}: cost from 100 s, median over {args.seeds} seeds {np.median(costs):.4g}")
