"""Designed persistent excitation for an adaptive loop: a multi-axis random binary torque.

An identifier learns the torque-to-motion gain only in the directions the
torques explore; a regulator that holds the spacecraft still explores
none. :class:`BinaryExcitation` adds a pseudo-random binary sequence (PRBS)
per torque axis: each axis holds ``+a`` or ``-a`` and flips with
probability ``1 / hold`` per sample, a flat spectrum up to about
``1 / (2 hold dt)`` Hz (0.5 Hz for the defaults, above the first flexible
modes). Its amplitude is a stated torque budget, larger during the warm-up
than afterwards, and it can be shaped toward the directions the identifier
knows least (:meth:`shape`). The cost is measured: :attr:`rms` is the RMS
excitation torque applied so far.

:class:`MotionNeed` decides whether identification is needed at all: a
spacecraft whose sensors show nothing beyond their noise has nothing for a
better model to improve, and shaking it to learn one costs more than the
model can return (held at rest, the 0.5 N m warm-up excitation cost about
1000 times what the robust fixed design costs there).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["NEED_SIGMAS", "BinaryExcitation", "MotionNeed", "warmup_excitation"]

#: A sample shows motion to control when its attitude error or rate on some axis is
#: beyond this many standard deviations of that sensor's noise (:class:`MotionNeed`):
#: held at rest, Gaussian noise on the six channels crosses it about once in 30 000
#: episodes of 2500 samples.
NEED_SIGMAS = 6.0


class BinaryExcitation:
    """Random binary torque on three axes with a warm-up and a steady budget.

    Parameters
    ----------
    warmup_amplitude : float
        Amplitude per axis (N m) for the first ``warmup_steps`` samples.
    amplitude : float
        Amplitude per axis (N m) afterwards (0 switches it off).
    warmup_steps : int
        Samples of the warm-up budget.
    hold : float
        Mean samples between sign flips (>= 1).
    """

    def __init__(self, warmup_amplitude: float = 1.0, amplitude: float = 0.1,
                 warmup_steps: int = 300, hold: float = 10.0) -> None:
        for name, value in (("warmup_amplitude", warmup_amplitude), ("amplitude", amplitude)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite torque >= 0 N m, got {value}")
        if warmup_steps < 0:
            raise ValueError(f"warmup_steps must be >= 0, got {warmup_steps}")
        if not (np.isfinite(hold) and hold >= 1):
            raise ValueError(f"hold must be >= 1 sample, got {hold}")
        self.warmup_amplitude = float(warmup_amplitude)
        self.amplitude = float(amplitude)
        self.warmup_steps = int(warmup_steps)
        self.hold = float(hold)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        """New episode; the sequence is drawn from ``np.random.default_rng(seed)``."""
        self._rng = np.random.default_rng(seed)
        self._sign = self._rng.choice([-1.0, 1.0], size=3)
        self._k = 0
        self._energy = 0.0
        self._shape = np.eye(3)

    def shape(self, covariance: np.ndarray | None) -> None:
        """Steer the budget toward poorly known input directions.

        ``covariance`` (3, 3) is the identifier's uncertainty of the torque
        directions (larger = less known); the binary signal is multiplied
        by its symmetric square root scaled to unit largest gain, so a
        direction known ten times better gets about a third of the
        amplitude. None restores the isotropic sequence.
        """
        if covariance is None:
            self._shape = np.eye(3)
            return
        cov = 0.5 * (np.asarray(covariance, dtype=float) + np.asarray(covariance).T)
        vals, vecs = np.linalg.eigh(cov)
        if not (np.isfinite(vals).all() and vals.max() > 0):
            self._shape = np.eye(3)
            return
        root = np.sqrt(np.clip(vals, 0.0, None) / vals.max())
        self._shape = (vecs * root) @ vecs.T

    def __call__(self, on: bool = True) -> np.ndarray:
        """The excitation torque of this sample, N m, (3,).

        Parameters
        ----------
        on : bool
            False: the sequence advances as it would (so the samples after are the
            same) and this sample applies none (zeros, no energy counted).

        Returns
        -------
        (3,) ndarray
        """
        flip = self._rng.random(3) < 1.0 / self.hold
        self._sign = np.where(flip, -self._sign, self._sign)
        amp = self.warmup_amplitude if self._k < self.warmup_steps else self.amplitude
        self._k += 1
        torque = amp * (self._shape @ self._sign) if on else np.zeros(3)
        self._energy += float(torque @ torque)
        return torque

    @property
    def rms(self) -> float:
        """RMS excitation torque applied so far (all axes), N m."""
        return float(np.sqrt(self._energy / max(3 * self._k, 1)))


def warmup_excitation(identifier: object) -> BinaryExcitation:
    """The excitation an adaptive loop gives ``identifier``: its ``warmup_amplitude``
    (N m per axis; :class:`BinaryExcitation`'s default where it states none) for its
    ``warmup`` samples (500 where it states none), then none until the loop asks.

    Parameters
    ----------
    identifier : object
        An online identifier (``identifiers.OnlineIdentifier``).

    Returns
    -------
    BinaryExcitation
    """
    asked = ({"warmup_amplitude": float(identifier.warmup_amplitude)}
             if hasattr(identifier, "warmup_amplitude") else {})
    return BinaryExcitation(warmup_steps=int(getattr(identifier, "warmup", 500)),
                            amplitude=0.0, **asked)


class MotionNeed:
    """Whether the spacecraft moves beyond its sensors' noise: the need to identify.

    Latched per episode: False until a sample's attitude error (measured attitude
    minus reference) or rate exceeds :data:`NEED_SIGMAS` standard deviations of
    that sensor's specified noise on some axis (exactly zero without noise), True
    from then on. While it is False there is nothing for a better model to improve:
    :class:`controllers.AdaptiveLQG` flies its robust fallback and adds no
    excitation. A slew, an attitude to correct, a docking's momentum or a
    disturbance sets it at once; a spacecraft held at rest never does.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft env (its observation layout and ``noise_std`` are read).
    sigmas : float
        The threshold in noise standard deviations (> 0).

    Examples
    --------
    >>> import gymnasium as gym
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraft-v2", task="regulation",
    ...                initial_attitude_deg=0.0)
    >>> need = MotionNeed(env)
    >>> obs, info = env.reset(seed=0)
    >>> need(obs, info["reference"])
    False
    """

    def __init__(self, env: Any, sigmas: float = NEED_SIGMAS) -> None:
        if not (np.isfinite(sigmas) and sigmas > 0):
            raise ValueError(f"sigmas must be a finite number > 0, got {sigmas!r}")
        env = getattr(env, "unwrapped", env)
        layout, outputs = env.observation_layout, env.model.output_layout
        self._att = layout.indices("attitude")
        self._rate = layout.indices("rate")
        noise = np.asarray(env.noise_std, dtype=float)
        self._bound = sigmas * np.concatenate([noise[outputs.indices("attitude")],
                                               noise[outputs.indices("rate")]])
        self.sigmas = float(sigmas)
        self.reset()

    def reset(self) -> None:
        """A new episode: no motion seen yet."""
        self.needed = False

    def __call__(self, obs: np.ndarray, reference: np.ndarray) -> bool:
        """Whether motion has been seen up to this sample (``obs``: the env's
        observation; ``reference``: the reference attitude, rad, (3,)).

        Returns
        -------
        bool
        """
        if not self.needed:
            obs = np.asarray(obs, dtype=float)
            level = np.abs(np.concatenate([obs[self._att] - reference, obs[self._rate]]))
            # a missing sample (NaN) shows nothing
            self.needed = bool(np.any(np.where(np.isfinite(level), level, 0.0) > self._bound))
        return self.needed
