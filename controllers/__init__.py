"""Attitude controllers for the flexible spacecraft and the closed-loop harness.

* :class:`AdaptiveLQR`: LQR re-designed every step from an online identifier.
* :class:`LQR` (fixed LQG, t = 0 design), :class:`OracleLQR` (true
  time-varying model and state), :class:`PD`.
* :class:`PolicyController`: any SB3 policy behind the same interface.
* :func:`run_episode`, :func:`episode_metrics`, :func:`compare`: the
  closed-loop harness.
* :class:`IdentifiedModelFeatures`: the identifier as a model-learning
  component for RL agents.
"""

from controllers.adaptive import AdaptiveLQR
from controllers.base import Controller, PolicyController
from controllers.baselines import LQR, PD, LQRWeights, OracleLQR, equilibrium_state
from controllers.features import IdentifiedModelFeatures
from controllers.harness import Trajectory, compare, episode_metrics, run_episode
from controllers.riccati import RiccatiTracker, check_weights, dlqr, spectral_radius
from spacecraft_conventions import __version__

__all__ = [
    "LQR",
    "PD",
    "AdaptiveLQR",
    "Controller",
    "IdentifiedModelFeatures",
    "LQRWeights",
    "OracleLQR",
    "PolicyController",
    "RiccatiTracker",
    "Trajectory",
    "__version__",
    "check_weights",
    "compare",
    "dlqr",
    "episode_metrics",
    "equilibrium_state",
    "run_episode",
    "spectral_radius",
]
