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
* ``model frozen at 60 s``: the default identifier, whose exported model
  the loop stops seeing change at 60 s (what closed-loop learning after
  that adds or costs);
* ``true model after warm-up``: the adaptive law given the true model only
  after its 30 s warm-up (the fallback and the 1 N m excitation fly until
  then, as in the adaptive loop): what the warm-up itself costs;
* ``same-law oracle + warm-up``: the adaptive law on the true model with
  the adaptive loop's 30 s, 1 N m warm-up excitation (does the energy the
  warm-up pumps into the modes cost anything, with a right model?);
* ``same-law oracle + warm-up, integral from 100 s``: the same, with the
  law's attitude integral held until 100 s (how much of that cost is the
  integral charged by the transient after the warm-up, how much the modes);
* ``same-law oracle``, ``oracle LQG``, ``robust LQG``: the references.

Then the tolerance table (skip with ``--no-tolerance``): the same law on
the true model with its flexible modes or rigid-body gain perturbed
(:class:`PerturbedTruth`, :data:`TOLERANCE`): how wrong may an identified
model be before the law pays for it?

It then freezes the loop of the adaptive LQG's worst seed at ``--at`` seconds and prints the damping
ratios of the true closed loop's modes between 0.07 and 0.1 Hz (the paddle
and antenna cluster) for the adaptive LQG's flying design and the oracle
LQG's, beside the plant's own (about 0.01): a design that removes damping
there feeds the modes it is meant to quiet.

Usage: ``python benchmarks/bench_adaptive_ablation.py [--scenario paddle_rotation]
[--seeds 6] [--task slew] [--snr-db 40] [--paddle-angle DEG] [--at 200] [--workers 2]
[--no-tolerance]``
(about 3 minutes on 2 cores).

The ``true rigid gain`` row reaches into the identifier's regression
(``RigidFlexibleIdentifier._theta``): an ablation, not an API.
"""

from __future__ import annotations

import argparse
from functools import partial
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import scipy.linalg

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import (
    AdaptiveLQG,
    BinaryExcitation,
    LQRWeights,
    OracleLQG,
    RobustLQG,
    TrueModelIdentifier,
    compare,
    fast_identifier,
)
from controllers.baselines import process_noise
from controllers.harness import SCORED_FROM_S
from identifiers import CLOSED_LOOP_SETTINGS, Resonator
from identifiers.modal.rigid_flexible import RigidFlexibleIdentifier
from spacecraft_env import DEFAULT_SNR_DB, env_id
from spacecraft_lab.control import SCENARIO_NAMES, env_kwargs_for

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


class FrozenAfter(RigidFlexibleIdentifier):
    """The default closed-loop identifier whose exported model stops changing at
    sample ``freeze`` (it keeps learning; the loop no longer sees it)."""

    def __init__(self, freeze: int, **options) -> None:
        super().__init__(**options)
        self.freeze = freeze
        self._frozen = None

    @property
    def model(self):
        if self._frozen is not None:
            return self._frozen
        model = super().model
        if self._k >= self.freeze:
            self._frozen = model
        return model


class LateTruth(TrueModelIdentifier):
    """The true model, given only after the adaptive loop's warm-up (the fallback and
    the warm-up excitation fly until then, as in the adaptive loop)."""

    @property
    def ready(self) -> bool:
        return self._k >= self.warmup

    @property
    def model(self):
        return super().model if self.ready else None


class PerturbedTruth(TrueModelIdentifier):
    """The true model with its flexible modes or rigid-body gain perturbed: how
    wrong may a model be before the same law pays for it?

    Every flexible mode's pole is moved along its own eigen-direction (rank-one
    spectral projectors, so the rigid-body Jordan blocks are untouched): its
    frequency by the factor ``1 + frequency * e_f`` and its damping ratio by
    ``exp(damping * e_d)``; its input coupling is scaled by ``1 + coupling * e_c``
    (``e_*`` standard normal per mode, from ``seed``); modes in ``drop`` (Hz band)
    lose their input coupling (the model does not have them); the rigid-body
    part of ``B`` is scaled by ``gain``. The continuous model is re-sampled
    (ZOH) every second.
    """

    def __init__(self, env: gym.Env, frequency: float = 0.0, coupling: float = 0.0,
                 damping: float = 0.0, gain: float = 1.0,
                 drop: tuple[float, float] | None = None, seed: int = 7) -> None:
        self.frequency, self.coupling, self.damping, self.gain = frequency, coupling, damping, gain
        self.drop = drop
        draws = np.random.default_rng(seed).standard_normal((3, 32))
        self._e_f, self._e_c, self._e_d = draws
        self._cached: tuple[float, object] | None = None
        super().__init__(env)

    def _system(self):
        t = float(np.floor(self._k * self.dt))
        if self._cached is not None and self._cached[0] == t:
            return self._cached[1]
        continuous = self.env.model.continuous(t)
        a, b = continuous.A, continuous.B
        vals, left, right = scipy.linalg.eig(a, left=True, right=True)
        flexible = np.flatnonzero(np.abs(vals.imag) > 1e-9)
        flexible = flexible[np.argsort(np.abs(vals[flexible]))]
        a_new, b_new = a.astype(complex), b.astype(complex)
        rigid = np.eye(a.shape[0], dtype=complex)
        for rank, j in enumerate(flexible):
            mode = rank // 2                        # a conjugate pair shares its draws
            projector = np.outer(right[:, j], left[:, j].conj()) / (left[:, j].conj() @ right[:, j])
            rigid -= projector
            wn = abs(vals[j]) * (1.0 + self.frequency * self._e_f[mode])
            zeta = min(0.9, -vals[j].real / abs(vals[j]) * np.exp(self.damping * self._e_d[mode]))
            pole = complex(-zeta * wn, np.sign(vals[j].imag) * wn * np.sqrt(1.0 - zeta**2))
            a_new += (pole - vals[j]) * projector
            scale = self.coupling * self._e_c[mode]
            if self.drop is not None and self.drop[0] < abs(vals[j]) / (2 * np.pi) < self.drop[1]:
                scale = -1.0
            b_new += scale * projector @ b
        b_new += (self.gain - 1.0) * rigid @ b
        n = a.shape[0]
        block = np.zeros((n + 3, n + 3))
        block[:n, :n], block[:n, n:] = a_new.real * self.dt, b_new.real * self.dt
        zoh = scipy.linalg.expm(block)
        system = SimpleNamespace(A=zoh[:n, :n], B=zoh[:n, n:])
        self._cached = (t, system)
        return system


def true_resonators(env: gym.Env, t: float = 0.0) -> list[Resonator]:
    """The true plant's flexible modes at ``t`` as resonators."""
    freq, zeta = env.unwrapped.model.modal(t)
    return [Resonator(float(f), float(z)) for f, z in zip(freq, zeta, strict=True)]


def _adaptive(env: gym.Env) -> AdaptiveLQG:
    # the structured recursive identifier's loop, which this ablation takes apart
    return AdaptiveLQG(env, weights=LQRWeights(), identifier=fast_identifier(env))


def _true_gain(env: gym.Env) -> AdaptiveLQG:
    return AdaptiveLQG(env, weights=LQRWeights(),
                       identifier=TrueRigidGain(env, **CLOSED_LOOP_SETTINGS))


def _true_frequencies(env: gym.Env) -> AdaptiveLQG:
    env.reset(seed=0)               # the plant at t = 0 (the scenario's, not the seed's)
    options = {**CLOSED_LOOP_SETTINGS, "prior": true_resonators(env), "track_modes": False}
    return AdaptiveLQG(env, weights=LQRWeights(), identifier=RigidFlexibleIdentifier(**options))


def _frozen(env: gym.Env) -> AdaptiveLQG:
    return AdaptiveLQG(env, weights=LQRWeights(),
                       identifier=FrozenAfter(FREEZE_AT, **CLOSED_LOOP_SETTINGS))


def _late_truth(env: gym.Env) -> AdaptiveLQG:
    identifier = LateTruth(env)
    identifier.warmup = CLOSED_LOOP_SETTINGS["warmup"]
    return AdaptiveLQG(env, weights=LQRWeights(), identifier=identifier)


def _perturbed(env: gym.Env, **perturbation) -> AdaptiveLQG:
    return AdaptiveLQG(env, weights=LQRWeights(), identifier=PerturbedTruth(env, **perturbation),
                       excitation=BinaryExcitation(0.0, 0.0))


def _same_law(env: gym.Env, warmup: bool) -> AdaptiveLQG:
    identifier = TrueModelIdentifier(env)
    if warmup:
        identifier.warmup = CLOSED_LOOP_SETTINGS["warmup"]
        return AdaptiveLQG(env, weights=LQRWeights(), identifier=identifier)
    return AdaptiveLQG(env, weights=LQRWeights(), identifier=identifier,
                       excitation=BinaryExcitation(0.0, 0.0))


class IntegralHeld(AdaptiveLQG):
    """The adaptive law whose attitude integral does not run before ``from_s``."""

    def __init__(self, env: gym.Env, from_s: float, **options) -> None:
        super().__init__(env, **options)
        self.from_s = from_s
        integrate = self.law.integrate

        def held(attitude_error: np.ndarray, saturated: bool) -> None:
            if self._k * self.dt >= self.from_s:
                integrate(attitude_error, saturated)

        self.law.integrate = held


def _same_law_integral_held(env: gym.Env) -> AdaptiveLQG:
    identifier = TrueModelIdentifier(env)
    identifier.warmup = CLOSED_LOOP_SETTINGS["warmup"]
    return IntegralHeld(env, SCORED_FROM_S, weights=LQRWeights(), identifier=identifier)


def _oracle(env: gym.Env) -> OracleLQG:
    return OracleLQG(env, LQRWeights())


def _robust(env: gym.Env) -> RobustLQG:
    return RobustLQG(env, LQRWeights())


#: Sample at which the ``model frozen at 60 s`` row stops showing the loop new models.
FREEZE_AT = 600

ROWS = {"adaptive LQG": _adaptive, "true rigid gain": _true_gain,
        "true modal frequencies": _true_frequencies,
        "model frozen at 60 s": _frozen,
        "true model after warm-up": _late_truth,
        "same-law oracle + warm-up": partial(_same_law, warmup=True),
        "same-law oracle + warm-up, integral from 100 s": _same_law_integral_held,
        "same-law oracle": partial(_same_law, warmup=False),
        "oracle LQG": _oracle, "robust LQG": _robust}


#: The tolerance table: the same-law oracle on a perturbed true model (PerturbedTruth).
TOLERANCE = {
    "frequencies +-10 %": dict(frequency=0.1),
    "damping x exp(+-0.7)": dict(damping=0.7),
    "modal couplings +-30 %": dict(coupling=0.3),
    "modal couplings +-60 %": dict(coupling=0.6),
    "modes above 0.15 Hz missing": dict(drop=(0.15, 10.0)),
    "strongest cluster mode missing": dict(drop=(0.095, 0.1)),
    "rigid-body gain x 0.8": dict(gain=0.8),
    "rigid-body gain x 1.2": dict(gain=1.2),
}


def cluster_damping(controller, a, b, c, gain, truth, t: float) -> np.ndarray:
    """Damping ratios of the true closed loop's modes in :data:`CLUSTER_HZ`: the loop of
    the design ``(a, b, c, gain)`` with its steady-state Kalman filter and the true plant
    frozen at ``t``, as the harness's verdict builds it (the controller's
    ``_closed_loop``)."""
    loop = controller._closed_loop(a, b, c, gain, process_noise(b), controller._noise_var,
                                   truth, t)
    eig = np.linalg.eigvals(loop)
    eig = eig[(eig.imag > 0) & (np.abs(eig) > 0)]
    s = np.log(eig) / truth.dt
    freq = np.abs(s) / (2 * np.pi)
    inside = (freq > CLUSTER_HZ[0]) & (freq < CLUSTER_HZ[1])
    return np.sort(-s.real[inside] / np.abs(s[inside]))


def hub_passivity(a: np.ndarray, b: np.ndarray, c: np.ndarray, rate_rows: np.ndarray,
                  scale: float, dt: float) -> float:
    """Smallest eigenvalue of the Hermitian part of the torque-to-body-rate response
    over :data:`CLUSTER_HZ`, relative to ``scale``: the hub's rate gyro and torque are
    collocated, so the plant's is >= 0 up to the sample-and-hold's half-sample lag;
    a model with a clearly negative one injects energy where the plant dissipates it."""
    smallest = np.inf
    for f in np.linspace(*CLUSTER_HZ, 121):
        z = np.exp(2j * np.pi * f * dt)
        h = c[rate_rows] @ np.linalg.solve(z * np.eye(a.shape[0]) - a, b)
        smallest = min(smallest, float(np.linalg.eigvalsh(0.5 * (h + h.conj().T)).min()))
    return smallest / scale


def frozen_loops(registered: str, kwargs: dict, at_s: float, seed: int) -> None:
    env = gym.make(registered, **kwargs)
    truth = env.unwrapped.model
    adaptive = AdaptiveLQG(env, weights=LQRWeights(), identifier=fast_identifier(env))
    oracle = OracleLQG(env, LQRWeights())
    obs, info = env.reset(seed=seed)
    adaptive.reset(seed)
    for _ in range(round(at_s / truth.dt)):
        obs, _, _, _, info = env.step(adaptive.act(obs, info))
    model = adaptive.identifier.model
    t = at_s
    freq, zeta = truth.modal(t)
    band = (freq > CLUSTER_HZ[0]) & (freq < CLUSTER_HZ[1])
    print(f"\nclosed-loop damping ratios of the modes in {CLUSTER_HZ[0]}-{CLUSTER_HZ[1]} Hz, "
          f"seed {seed} (the adaptive LQG's worst), loop frozen at t = {t:g} s")
    plant = np.sort(zeta[band])
    print(f"  plant (open loop)     {np.round(plant, 4)}")
    if adaptive._flying_gain is not None and model is not None:
        damping = cluster_damping(adaptive, model.A, model.B, model.C, adaptive._flying_gain,
                                  truth, t)
        print(f"  adaptive LQG design   {np.round(damping, 4)}  (flying: {adaptive._flying})")
    true = truth.discrete(t)
    gain = oracle.law.design(true.A, true.B, oracle._c, oracle._c_att)
    damping = cluster_damping(oracle, true.A, true.B, oracle._c, gain, truth, t)
    print(f"  oracle LQG design     {np.round(damping, 4)}")
    # how physical is the identified model? the rigid gain J^-1 is symmetric and the
    # collocated torque-to-rate response passive, in the plant
    rate = truth.output_layout.indices("rate")
    h_true = [np.linalg.norm(truth.C[rate] @ np.linalg.solve(
        np.exp(2j * np.pi * f * truth.dt) * np.eye(truth.n) - true.A, true.B))
        for f in np.linspace(*CLUSTER_HZ, 121)]
    scale = float(np.max(h_true))
    plant = hub_passivity(true.A, true.B, truth.C, rate, scale, truth.dt)
    estimate = adaptive.identifier.rigid_gain
    print("\nhow physical the identified model is (plant in brackets)")
    if estimate is not None:
        g = estimate.gain
        print(f"  rigid gain's antisymmetric part / its norm   "
              f"{np.linalg.norm(g - g.T) / (2 * np.linalg.norm(g)):.3f}  [0]")
    if model is not None:
        rows = adaptive.measured_layout.indices("rate")
        print(f"  min Hermitian part of the torque-to-rate response over the band, "
              f"/ the plant's peak   "
              f"{hub_passivity(model.A, model.B, model.C, rows, scale, truth.dt):.3f}  "
              f"[{plant:.3f}]")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paddle_rotation",
                        choices=sorted(set(SCENARIO_NAMES) - {"family"}))
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--paddle-angle", type=float, default=None,
                        help="paddle angle at t = 0, deg (constant and rotation scenarios)")
    parser.add_argument("--task", default="slew", choices=("slew", "regulation"))
    parser.add_argument("--snr-db", type=float, default=DEFAULT_SNR_DB,
                        help="measurement SNR per channel, dB")
    parser.add_argument("--at", type=float, default=200.0,
                        help="time of the frozen-loop damping analysis, s")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-tolerance", action="store_true",
                        help="skip the tolerance table (the same law on perturbed true models)")
    args = parser.parse_args()
    registered = env_id(args.scenario)
    kwargs = env_kwargs_for(args.scenario, task=args.task, paddle_angle=args.paddle_angle,
                            snr_db=args.snr_db)
    rows = dict(ROWS)
    if not args.no_tolerance:
        rows.update({f"same law, {name}": partial(_perturbed, **perturbation)
                     for name, perturbation in TOLERANCE.items()})
    table, _ = compare(rows, partial(gym.make, registered, **kwargs), list(range(args.seeds)),
                       progress=True, workers=args.workers)
    oracle = np.array([m["cost_after_100s"] for m in table["oracle LQG"]["per_seed"]])
    print(f"\n{args.scenario}, {args.task} task, {args.snr_db:g} dB, {args.seeds} seeds, "
          "common cost from 100 s")
    print(f"{'row':44s} {'/ oracle':>9s} {'worst':>7s}   split att / rate / defl / torque"
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
        print(f"{name:44s} {np.median(ratio):9.2f} {np.max(ratio):7.2f}   {split:34s}"
              f" {100 * fallback:5.0f} %")
    frozen_loops(registered, kwargs, args.at, worst)


if __name__ == "__main__":
    main()
