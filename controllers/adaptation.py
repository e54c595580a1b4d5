"""RMA-style adaptation: the privileged parameter vector estimated from the identifier.

A policy trained with :class:`controllers.PrivilegedFeatures` (the true
plant's rigid-body gain, dominant modes and paddle angle) needs that vector
when it flies. Rapid motor adaptation's answer is an *adaptation module*: a
regression, learnt on the policy's own rollouts, from what can be measured
to the privileged vector. Here what can be measured is the online
identifier's physical estimates and their uncertainty,
:class:`controllers.PhysicalFeatures`, in the same layout.

* :class:`AdaptationModule` is that regression (ridge, numpy only);
* :class:`EstimatedFeatures` runs the identifier and puts the module's
  estimate where the policy expects the privileged vector;
* ``PrivilegedFeatures(env, source="nominal")`` gives the nominal plant's.

The same policy flown with the true, the estimated and the nominal vector
on the same episodes measures what the identifier is worth to the agent
(``spacecraft adapt``, :mod:`spacecraft_lab.adaptation`).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike

from controllers.features import PhysicalFeatures, physical_feature_names
from identifiers import OnlineIdentifier

__all__ = ["AdaptationModule", "EstimatedFeatures"]


class AdaptationModule:
    """Ridge regression from the physical vector to the privileged one.

    The estimated channels are the ones the truth knows and the identifier
    estimates: the rigid-body gain (its log diagonal and normalized
    off-diagonal, 6 channels) and the k modes' log frequencies and damping
    (2k). Two affine maps share the work, selected by the input's ``ready``
    flag: before the identifier has warmed up its other channels are 0 and
    the estimate is an affine function of the paddle angle's sine and
    cosine (the best guess from the drive alone); after it, an affine
    function of every channel of the physical vector (the estimates, their
    uncertainty, the paddle angle and the change flag), standardized. The
    other output channels are what the privileged vector holds: uncertainty
    0, the paddle angle and the change flag as measured, ``ready`` 1.

    Parameters
    ----------
    n_modes : int
        k, modes in both vectors (:func:`controllers.features.physical_feature_names`).
    ridge : float
        Tikhonov weight per sample on the standardized inputs (>= 0).

    Examples
    --------
    >>> import numpy as np
    >>> from controllers import AdaptationModule
    >>> rng = np.random.default_rng(0)
    >>> physical = rng.normal(size=(400, 17))
    >>> physical[:, -1] = 1.0                                  # identifier ready
    >>> privileged = physical.copy()
    >>> privileged[:, :11] = 0.5 * physical[:, :11] + 0.1      # a known affine map
    >>> module = AdaptationModule(ridge=1e-9).fit(physical, privileged)
    >>> bool(np.allclose(module.predict(physical)[:, :6], privileged[:, :6], atol=1e-6))
    True
    >>> module.predict(physical[0]).shape                      # one vector
    (17,)
    """

    def __init__(self, n_modes: int = 2, ridge: float = 1e-3) -> None:
        names = physical_feature_names(int(n_modes))
        if not (np.isfinite(ridge) and ridge >= 0):
            raise ValueError(f"ridge must be >= 0, got {ridge}")
        self.n_modes = int(n_modes)
        self.ridge = float(ridge)
        self.size = len(names)
        k = self.n_modes
        self._targets = np.r_[0:6, 7:7 + 2 * k]
        self._zeroed = np.r_[6, 7 + 2 * k:7 + 3 * k]
        self._paddle = np.r_[7 + 3 * k:9 + 3 * k]
        self._before: np.ndarray | None = None      # (3, targets): sin, cos, 1
        self._after: np.ndarray | None = None       # (size + 1, targets)
        self._mean = np.zeros(self.size)
        self._std = np.ones(self.size)

    @property
    def fitted(self) -> bool:
        """Whether :meth:`fit` has run."""
        return self._after is not None

    def _check(self, name: str, value: ArrayLike) -> np.ndarray:
        x = np.asarray(value, dtype=float)
        if x.ndim != 2 or x.shape[1] != self.size:
            raise ValueError(f"{name} must have shape (N, {self.size}), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name} must be finite")
        return x

    @staticmethod
    def _solve(inputs: np.ndarray, targets: np.ndarray, ridge: float) -> np.ndarray:
        penalty = ridge * inputs.shape[0] * np.eye(inputs.shape[1])
        penalty[-1, -1] = 0.0                     # the constant is not shrunk
        return np.linalg.solve(inputs.T @ inputs + penalty, inputs.T @ targets)

    def _standardized(self, x: np.ndarray) -> np.ndarray:
        return np.column_stack([(x - self._mean) / self._std, np.ones(x.shape[0])])

    def fit(self, physical: ArrayLike, privileged: ArrayLike) -> AdaptationModule:
        """Fit both maps on paired samples (rows: the same instant of the same episode).

        Parameters
        ----------
        physical, privileged : (N, size) array_like
            :class:`controllers.PhysicalFeatures`' and
            :class:`controllers.PrivilegedFeatures`' vectors.

        Returns
        -------
        AdaptationModule
            ``self``.

        Raises
        ------
        ValueError
            For other shapes, non-finite values, or fewer than ``size + 1``
            ready samples.
        """
        x = self._check("physical", physical)
        y = self._check("privileged", privileged)
        if x.shape[0] != y.shape[0]:
            raise ValueError(f"physical and privileged must pair up: {x.shape[0]} and "
                             f"{y.shape[0]} rows")
        ready = x[:, -1] > 0.5
        if ready.sum() <= self.size:
            raise ValueError(f"need more than {self.size} samples with the identifier ready, "
                             f"got {int(ready.sum())}")
        targets = y[:, self._targets]
        self._mean = x[ready].mean(axis=0)
        std = x[ready].std(axis=0)
        self._std = np.where(std > 1e-9, std, 1.0)
        self._after = self._solve(self._standardized(x[ready]), targets[ready], self.ridge)
        early = x[~ready]
        if early.shape[0] > 3:
            inputs = np.column_stack([early[:, self._paddle], np.ones(early.shape[0])])
            self._before = self._solve(inputs, targets[~ready], self.ridge)
        else:                                     # never seen: the ready map's constant
            self._before = np.zeros((3, self._targets.size))
            self._before[-1] = self._after[-1]
        return self

    def predict(self, physical: ArrayLike) -> np.ndarray:
        """The privileged vector estimated from one ``(size,)`` or many ``(N, size)`` vectors.

        Returns
        -------
        (n_targets,) or (N, n_targets) ndarray
            The estimated privileged vector(s), in the order the module was fitted on.

        Raises
        ------
        RuntimeError
            Before :meth:`fit`.
        ValueError
            For another shape or non-finite values.
        """
        if not self.fitted:
            raise RuntimeError("fit the adaptation module before predicting")
        single = np.ndim(physical) == 1
        x = self._check("physical", np.atleast_2d(physical))
        ready = x[:, -1] > 0.5
        out = x.copy()
        estimate = np.column_stack([x[:, self._paddle], np.ones(x.shape[0])]) @ self._before
        if ready.any():
            estimate[ready] = self._standardized(x[ready]) @ self._after
        out[:, self._targets] = estimate
        out[:, self._zeroed] = 0.0
        out[:, -1] = 1.0
        return out[0] if single else out


class EstimatedFeatures(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """The privileged vector's layout, estimated: the identifier's
    :class:`controllers.PhysicalFeatures` passed through an :class:`AdaptationModule`.

    A policy trained with :class:`controllers.PrivilegedFeatures` flies
    this env unchanged: the observation ends with the same channels, the
    estimate in place of the truth.

    Parameters
    ----------
    env : gymnasium.Env
        A spacecraft environment observing attitude and rate.
    module : AdaptationModule
        Fitted, for the same number of modes.
    identifier : identifiers.OnlineIdentifier, optional
        Passed to :class:`controllers.PhysicalFeatures` (default: its default).
    every : int
        Env steps between refreshes (default 10, as both feature wrappers).

    Raises
    ------
    ValueError
        For a module that is not fitted.
    """

    def __init__(self, env: gym.Env, module: AdaptationModule,
                 identifier: OnlineIdentifier | None = None, every: int = 10) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, module=module, identifier=identifier,
                                                 every=every)
        if not isinstance(module, AdaptationModule) or not module.fitted:
            raise ValueError("module must be a fitted AdaptationModule")
        inner = PhysicalFeatures(env, identifier, n_modes=module.n_modes, every=every)
        gym.ObservationWrapper.__init__(self, inner)
        self.module = module
        self.n_features = inner.n_features
        self.identifier = inner.identifier

    def observation(self, observation: np.ndarray) -> Any:
        obs = np.asarray(observation, dtype=float).copy()
        obs[-self.n_features:] = np.clip(self.module.predict(obs[-self.n_features:]),
                                         -10.0, 10.0)
        return obs.astype(np.float32)
