"""The identifiers' core: the streaming base class and what every method uses.

:class:`OnlineIdentifier` (:mod:`identifiers.core.online`) composed of
:class:`SampleScreening` (:mod:`identifiers.core.screening`: what may be
learned from) and :class:`HealthGuard` (:mod:`identifiers.core.rollback`:
the estimator's own state); the one RLS primitive
(:mod:`identifiers.core.rls`, its compiled kernel
:mod:`identifiers.core.rls_kernel`); state-space models
(:mod:`identifiers.core.model`); the Kalman predictor
(:mod:`identifiers.core.kalman`); the health report
(:mod:`identifiers.core.health`) and the data monitor
(:mod:`identifiers.core.data_monitor`); running residual statistics
(:mod:`identifiers.core.residual_statistics`); argument checks
(:mod:`identifiers.core.checks`). And what the structure-aware families
(:mod:`identifiers.modal`, :mod:`identifiers.physical`,
:mod:`identifiers.structured`) share: the modal filter bank
(:mod:`identifiers.core.modal_basis`, its compiled kernels
:mod:`identifiers.core.modal_kernels`), the rigid-body gain with its calibrated
uncertainty (:mod:`identifiers.core.rigid_gain`), the change tests
(:mod:`identifiers.core.change_detection`) and the Kalman filter on an
identified model (:mod:`identifiers.core.state_filter`). Nothing here imports
the method families.
"""

from identifiers.core.change_detection import ChangeEvent, InnovationCUSUM, RegressionGLR
from identifiers.core.data_monitor import DataMonitor
from identifiers.core.health import IdentifierHealth, IdentifierHealthWarning
from identifiers.core.kalman import KalmanPredictor, steady_state_gain
from identifiers.core.modal_basis import ModalFilterBank, Resonator
from identifiers.core.model import Modes, StateSpaceModel, observability_basis
from identifiers.core.model_sequence import ModelSequence
from identifiers.core.online import OnlineIdentifier
from identifiers.core.residual_statistics import correlation_time
from identifiers.core.rigid_gain import RigidGainEstimate
from identifiers.core.rls import RecursiveLeastSquares
from identifiers.core.rollback import HealthGuard
from identifiers.core.screening import OUTLIER_RUN, SampleScreening

__all__ = [
    "OUTLIER_RUN",
    "ChangeEvent",
    "DataMonitor",
    "HealthGuard",
    "IdentifierHealth",
    "IdentifierHealthWarning",
    "InnovationCUSUM",
    "KalmanPredictor",
    "ModalFilterBank",
    "ModelSequence",
    "Modes",
    "OnlineIdentifier",
    "RecursiveLeastSquares",
    "RegressionGLR",
    "Resonator",
    "RigidGainEstimate",
    "SampleScreening",
    "StateSpaceModel",
    "correlation_time",
    "observability_basis",
    "steady_state_gain",
]
