"""Streaming identification beside the env: what the identifier knows, against the truth.

The identifier gets one ``(torque, measurement)`` pair per step, as on board;
every 25 s this prints its rigid-body gain error and dominant-mode frequency
beside the true plant's, and the changes it detected (the modules dock at
100 s and 180 s).

    python examples/streaming_identification.py [--steps 2500]
"""

import argparse

import gymnasium as gym
import numpy as np

from identifiers import default_identifier

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=2500, help="env steps (0.1 s each)")
args = parser.parse_args()

env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2")      # 40 dB sensor noise
model = env.unwrapped.model
ident = default_identifier()                                      # the env's 10 outputs
rng = np.random.default_rng(0)
obs, info = env.reset(seed=0)
freqs = np.linspace(0.01, 0.5, 25)
phases = rng.uniform(0, 2 * np.pi, (3, freqs.size))
for k in range(args.steps):
    # a 1 N m RMS random-phase multisine per axis (action 1 = 10 N m)
    action = 0.1 * np.sin(2 * np.pi * freqs * 0.1 * k + phases).sum(axis=1) / np.sqrt(12.5)
    y = obs.astype(float)
    obs, _, terminated, truncated, info = env.step(action.astype(np.float32))
    ident.update(info["torque"], y)                 # the torque applied after y was measured
    t = info["time"]
    if round(t * 10) % 250 == 0 and ident.rigid_gain is not None:
        true_gain = np.linalg.inv(model.inertia(t))
        estimate = ident.rigid_gain
        err = np.linalg.norm(estimate.gain - true_gain) / np.linalg.norm(true_gain)
        f_id = ident.mode_estimates[0]
        f_true, _, weight = model.modal_residues(t)
        dominant = f_true[np.argmax(weight)]
        nearest = f_id[np.argmin(np.abs(f_id - dominant))] if f_id.size else np.nan
        print(f"t = {t:5.0f} s  gain error {100 * err:5.1f} % (2-sigma covers the truth: "
              f"{estimate.covers(true_gain)})  dominant mode {dominant:.4f} Hz, "
              f"identified {nearest:.4f} Hz")
    if terminated or truncated:
        break
print("changes detected at", [round(e.time, 1) for e in ident.events], "s")
