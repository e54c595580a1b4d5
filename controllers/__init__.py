"""Attitude controllers for the flexible spacecraft and the closed-loop harness.

* :class:`AdaptiveLQG`: certainty-equivalence LQG re-designed every step on
  the model of an online identifier, with integral action, a designed
  excitation and a physical acceptance test for every gain.
* Baselines (:mod:`controllers.baselines`): :class:`PD`, :class:`FixedLQG`
  (nominal design), :class:`RobustLQG` (rigid-body design behind notches),
  :class:`ScheduledLQG` (on the measured paddle angle), :class:`OracleLQG`
  (true model, Kalman filter, the adaptive law's reference) and :class:`OracleLQR`
  (true model and state).
* :class:`ClairvoyantLQG` (:mod:`controllers.ceiling`): the ceiling of the common
  cost, the finite-horizon LQG on the true time-varying plant with the true noise
  statistics; with ``start`` (:func:`adaptive_start`) the same-start ceiling; planned
  for the cost from 100 s only, the window ceiling (:func:`window_ceiling`).
* :class:`PolicyController`: any SB3 policy behind the same interface.
* :func:`run_episode`, :func:`episode_metrics`, :func:`compare`: the
  closed-loop harness.
* :class:`IdentifiedModelFeatures`: the identifier as a model-learning
  component for RL agents; :class:`OracleModelFeatures`: the same features
  from the true plant (the ceiling, privileged); :class:`PhysicalFeatures`:
  the identifier's physical estimates (rigid-body gain, slowest modes, their
  uncertainties, a change flag) in a fixed normalized frame, and
  :class:`PrivilegedFeatures` the same vector from the truth (or the nominal
  plant); :class:`AdaptationModule` and :class:`EstimatedFeatures`: that vector
  estimated from the identifier's (RMA's adaptation module);
  :class:`ResidualControl`: an
  agent's action added to a controller's (residual RL on the adaptive LQG);
  :class:`ScoredWindowReward`: an agent's reward on the window the harness
  scores (from 100 s, a crash whenever it comes).
"""

from controllers.acceptance import (
    GainAcceptance,
    effective_gains,
    input_disk_margin,
    stable_under_input_gains,
)
from controllers.actuator_monitor import ActuatorMonitor
from controllers.adaptation import AdaptationModule, EstimatedFeatures
from controllers.adaptive import AdaptiveLQG, FallbackWarning, ScheduleWarning
from controllers.base import Controller, PolicyController
from controllers.baselines import (
    PD,
    FixedLQG,
    OracleLQG,
    OracleLQR,
    RobustLQG,
    ScheduledLQG,
    TrueModelIdentifier,
    nominal_model,
)
from controllers.ceiling import (
    ClairvoyantLQG,
    ExcitedStart,
    adaptive_start,
    finite_horizon_lqr,
    same_start_ceiling,
    window_ceiling,
)
from controllers.excitation import BinaryExcitation, MotionNeed
from controllers.features import (
    IdentifiedModelFeatures,
    OracleModelFeatures,
    PhysicalFeatures,
    PrivilegedFeatures,
)
from controllers.gyro_bias import FaultWarning, GyroBiasMonitor
from controllers.harness import (
    ComparisonInterrupted,
    Trajectory,
    compare,
    controller_shares,
    episode_metrics,
    fallback_causes,
    run_episode,
    stage_costs,
)
from controllers.loop_identifiers import (
    LOOP_FIT_TIMING,
    closed_loop_identifier,
    fast_identifier,
    scheduled_identifier,
    structured_identifier,
)
from controllers.lqg import (
    LQGLaw,
    LQRWeights,
    equilibrium_map,
    equilibrium_state,
    output_weight,
    set_integral_settle,
)
from controllers.noise_intensity import ProcessNoiseBank
from controllers.residual import BaseRelativeReward, ResidualControl, ResidualObservations
from controllers.rewards import ScoredWindowReward
from controllers.riccati import RiccatiTracker, check_weights, dlqr, doubling_dare, spectral_radius
from spacecraft_conventions import __version__

__all__ = [
    "LOOP_FIT_TIMING",
    "PD",
    "ActuatorMonitor",
    "AdaptationModule",
    "AdaptiveLQG",
    "BaseRelativeReward",
    "BinaryExcitation",
    "ClairvoyantLQG",
    "ComparisonInterrupted",
    "Controller",
    "EstimatedFeatures",
    "ExcitedStart",
    "FallbackWarning",
    "FaultWarning",
    "FixedLQG",
    "GainAcceptance",
    "GyroBiasMonitor",
    "IdentifiedModelFeatures",
    "LQGLaw",
    "LQRWeights",
    "MotionNeed",
    "OracleLQG",
    "OracleLQR",
    "OracleModelFeatures",
    "PhysicalFeatures",
    "PolicyController",
    "PrivilegedFeatures",
    "ProcessNoiseBank",
    "ResidualControl",
    "ResidualObservations",
    "RiccatiTracker",
    "RobustLQG",
    "ScheduleWarning",
    "ScheduledLQG",
    "ScoredWindowReward",
    "Trajectory",
    "TrueModelIdentifier",
    "__version__",
    "adaptive_start",
    "check_weights",
    "closed_loop_identifier",
    "compare",
    "controller_shares",
    "dlqr",
    "doubling_dare",
    "effective_gains",
    "episode_metrics",
    "equilibrium_map",
    "equilibrium_state",
    "fallback_causes",
    "fast_identifier",
    "finite_horizon_lqr",
    "input_disk_margin",
    "nominal_model",
    "output_weight",
    "run_episode",
    "same_start_ceiling",
    "scheduled_identifier",
    "set_integral_settle",
    "spectral_radius",
    "stable_under_input_gains",
    "stage_costs",
    "structured_identifier",
    "window_ceiling",
]
