"""What the adaptive LQG's distance to the oracle is made of: ablations side by side.

Each row flies the adaptive loop with one piece of the truth handed to it
(or one setting changed), on the same seeds, and prints the common cost
from 100 s as a paired-seed ratio to the oracle LQG (median and worst seed),
its split (attitude / rate / deflection / torque, medians) and the share of
the steps from 60 s flown by the fallback:

* ``adaptive LQG``: the default loop;
* ``true rigid gain``: the same identifier, but the exported model's
  rigid-body gain ``G = J(t)^-1`` replaced by the truth at every export (the
  modal part stays identified);
* ``true modal frequencies``: the identifier given the true plant's modal
  frequencies and damping at t = 0 as its modes (``prior``), not tracked;
  only the couplings and the rigid gain are identified;
* ``same-law oracle + warm-up``: the adaptive law on the true model with
  the adaptive loop's 30 s, 1 N m warm-up excitation (does the energy the
  warm-up pumps into the modes cost anything, with a right model?);
* ``same-law oracle``, ``oracle LQG``, ``robust LQG``: the references.

It then freezes the loop of the adaptive LQG's worst seed at ``--at`` seconds and prints the damping
ratios of the true closed loop's modes between 0.07 and 0.1 Hz (the paddle
and antenna cluster) for the adaptive LQG's flying design and the oracle
LQG's, beside the plant's own (about 0.01): a design that removes damping
there feeds the modes it is meant to quiet.

Usage: ``python benchmarks/bench_adaptive_ablation.py [--scenario paddle_rotation]
[--seeds 6] [--paddle-angle DEG] [--at 200] [--workers 2]`` (about 2 minutes on 2 cores).

The ``true rigid gain`` row reaches into the identifier's regression
(``RigidFlexibleIdentifier._theta``): an ablation, not an API.
"""

from __future__ import annotations

import argparse
from functools import partial

import gymnasium as gym
import numpy as np

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import (
    AdaptiveLQG,
    BinaryExcitation,
    LQRWeights,
    OracleLQG,
    RobustLQG,
    TrueModelIdentifier,
    compare,
)
from controllers.baselines import process_noise
from identifiers import CLOSED_LOOP_SETTINGS, Resonator, steady_state_gain
from identifiers.rigid_flexible import RigidFlexibleIdentifier
from spacecraft_env import ENV_IDS
from spacecraft_lab.control import env_kwargs_for

#: The band of the paddle and antenna modes whose closed-loop damping is printed, Hz.
CLUSTER_HZ = (0.07, 0.10)


class TrueRigidGain(RigidFlexibleIdentifier):
    """The default closed-loop identifier with the truth's ``J(t)^-1`` in its exports."""

    def __init__(self, env: gym.Env, **options) -> None:
        super().__init__(**options)
        self._truth = env.unwrapped.model

    def _theta(self) -> np.ndarray:
        theta = super()._theta()
        if self._fits:
            gain = np.linalg.inv(self._truth.inertia(self._k * self.dt))
            cols = np.arange(self._bank.size)[self._bank.slices["rate"]]
            rows = self._rate_rows
            # the regression's units: rows by the rate scale, columns by their RMS
            theta[rows, cols[0]:cols[-1] + 1] = (
                gain * (self._scale[cols] * self._su)[None, :] / self._sy[rows][:, None])
        return theta


def true_resonators(env: gym.Env, t: float = 0.0) -> list[Resonator]:
    """The true plant's flexible modes at ``t`` as resonators."""
    eig = np.linalg.eigvals(env.unwrapped.model.continuous(t).A)
    eig = eig[eig.imag > 1e-6]
    return [Resonator(float(abs(e) / (2 * np.pi)), float(-e.real / abs(e)))
            for e in sorted(eig, key=abs)]


def _adaptive(env: gym.Env) -> AdaptiveLQG:
    return AdaptiveLQG(env, weights=LQRWeights())


def _true_gain(env: gym.Env) -> AdaptiveLQG:
    return AdaptiveLQG(env, weights=LQRWeights(),
                       identifier=TrueRigidGain(env, **CLOSED_LOOP_SETTINGS))


def _true_frequencies(env: gym.Env) -> AdaptiveLQG:
    env.reset(seed=0)               # the plant at t = 0 (the scenario's, not the seed's)
    options = {**CLOSED_LOOP_SETTINGS, "prior": true_resonators(env), "track_modes": False}
    return AdaptiveLQG(env, weights=LQRWeights(), identifier=RigidFlexibleIdentifier(**options))


def _same_law(env: gym.Env, warmup: bool) -> AdaptiveLQG:
    identifier = TrueModelIdentifier(env)
    if warmup:
        identifier.warmup = CLOSED_LOOP_SETTINGS["warmup"]
        return AdaptiveLQG(env, weights=LQRWeights(), identifier=identifier)
    return AdaptiveLQG(env, weights=LQRWeights(), identifier=identifier,
                       excitation=BinaryExcitation(0.0, 0.0))


def _oracle(env: gym.Env) -> OracleLQG:
    return OracleLQG(env, LQRWeights())


def _robust(env: gym.Env) -> RobustLQG:
    return RobustLQG(env, LQRWeights())


ROWS = {"adaptive LQG": _adaptive, "true rigid gain": _true_gain,
        "true modal frequencies": _true_frequencies,
        "same-law oracle + warm-up": partial(_same_law, warmup=True),
        "same-law oracle": partial(_same_law, warmup=False),
        "oracle LQG": _oracle, "robust LQG": _robust}


def cluster_damping(controller, a, b, c, gain, truth, t: float) -> np.ndarray:
    """Damping ratios of the true closed loop's modes in :data:`CLUSTER_HZ` (the loop
    of the design ``(a, b, c, gain)`` with its steady-state Kalman filter, the true
    plant frozen at ``t``, the integral of the attitude error)."""
    filt = steady_state_gain(a, c, process_noise(b), np.diag(controller._noise_var))[0]
    true = truth.discrete(t)
    c_t = truth.C[controller._meas_rows]
    c_att = truth.C[truth.output_layout.slice("attitude")]
    nt, n = true.A.shape[0], a.shape[0]
    gx, gz = gain[:, :n], gain[:, n:]
    to_u = np.hstack([-gx @ filt @ c_t, -gx @ (np.eye(n) - filt @ c), -gz])
    top = np.hstack([true.A, np.zeros((nt, n + 3))]) + true.B @ to_u
    mid = np.hstack([a @ filt @ c_t, a @ (np.eye(n) - filt @ c), np.zeros((n, 3))]) + b @ to_u
    bottom = np.hstack([truth.dt * c_att, np.zeros((3, n)), np.eye(3)])
    eig = np.linalg.eigvals(np.vstack([top, mid, bottom]))
    eig = eig[(eig.imag > 0) & (np.abs(eig) > 0)]
    s = np.log(eig) / truth.dt
    freq = np.abs(s) / (2 * np.pi)
    inside = (freq > CLUSTER_HZ[0]) & (freq < CLUSTER_HZ[1])
    return np.sort(-s.real[inside] / np.abs(s[inside]))


def frozen_loops(env_id: str, kwargs: dict, at_s: float, seed: int) -> None:
    env = gym.make(env_id, **kwargs)
    truth = env.unwrapped.model
    adaptive, oracle = AdaptiveLQG(env, weights=LQRWeights()), OracleLQG(env, LQRWeights())
    obs, info = env.reset(seed=seed)
    adaptive.reset(seed)
    for _ in range(round(at_s / truth.dt)):
        obs, _, _, _, info = env.step(adaptive.act(obs, info))
    model = adaptive.identifier.model
    t = at_s
    open_loop = np.linalg.eigvals(truth.continuous(t).A)
    open_loop = open_loop[open_loop.imag > 0]
    band = (np.abs(open_loop) / (2 * np.pi) > CLUSTER_HZ[0]) & \
        (np.abs(open_loop) / (2 * np.pi) < CLUSTER_HZ[1])
    print(f"\nclosed-loop damping ratios of the modes in {CLUSTER_HZ[0]}-{CLUSTER_HZ[1]} Hz, "
          f"seed {seed} (the adaptive LQG's worst), loop frozen at t = {t:g} s")
    plant = np.sort(-open_loop[band].real / np.abs(open_loop[band]))
    print(f"  plant (open loop)     {np.round(plant, 4)}")
    if adaptive._flying_gain is not None and model is not None:
        damping = cluster_damping(adaptive, model.A, model.B, model.C, adaptive._flying_gain,
                                  truth, t)
        print(f"  adaptive LQG design   {np.round(damping, 4)}  (flying: {adaptive._flying})")
    true = truth.discrete(t)
    gain = oracle.law.design(true.A, true.B, oracle._c, oracle._c_att)
    damping = cluster_damping(oracle, true.A, true.B, oracle._c, gain, truth, t)
    print(f"  oracle LQG design     {np.round(damping, 4)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paddle_rotation",
                        choices=sorted(set(ENV_IDS.values()) - {"family"}))
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--paddle-angle", type=float, default=None,
                        help="paddle angle at t = 0, deg (constant and rotation scenarios)")
    parser.add_argument("--at", type=float, default=200.0,
                        help="time of the frozen-loop damping analysis, s")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    env_id = {v: k for k, v in ENV_IDS.items()}[args.scenario]
    kwargs = env_kwargs_for(args.scenario, paddle_angle=args.paddle_angle)
    table, _ = compare(ROWS, partial(gym.make, env_id, **kwargs), list(range(args.seeds)),
                       progress=True, workers=args.workers)
    oracle = np.array([m["cost_after_100s"] for m in table["oracle LQG"]["per_seed"]])
    print(f"\n{args.scenario}, {args.seeds} seeds, common cost from 100 s")
    print(f"{'row':28s} {'/ oracle':>9s} {'worst':>7s}   split att / rate / defl / torque"
          f"   fallback t >= 60 s")
    worst = 0
    for name, result in table.items():
        seeds = result["per_seed"]
        ratio = np.array([m["cost_after_100s"] for m in seeds]) / oracle
        split = " / ".join(f"{np.median([m[f'cost_{p}_after_100s'] for m in seeds]):.2g}"
                           for p in ("attitude", "rate", "deflection", "torque"))
        if name == "adaptive LQG":
            worst = int(np.argmax(ratio))
        fallback = np.median([m.get("fallback_share_after_60s") or 0.0 for m in seeds])
        print(f"{name:28s} {np.median(ratio):9.2f} {np.max(ratio):7.2f}   {split:34s}"
              f" {100 * fallback:5.0f} %")
    frozen_loops(env_id, kwargs, args.at, worst)


if __name__ == "__main__":
    main()
