"""Online subspace identification of time-varying systems.

Streaming identifiers share one API: ``update(u, y)`` per sample,
``.model`` (a :class:`StateSpaceModel`, or None while warming up),
``.state``, ``.health``, ``fit(U, Y)`` and ``reset()``.

* :func:`default_identifier`: the recommended identifier for the
  spacecraft's outputs, with its settings.
* :class:`RigidFlexibleIdentifier`: known rigid-body kinematics, estimated
  inverse inertia and flexible modes, change detection; the default.
* :class:`ImprovedRPBSID`: the paper's improved recursive PBSID (affine
  projection sign state update), for reproduction.
* :class:`MomentRefitRPBSID`: recursive VARX plus batch-equivalent refits of
  the system matrices from exponentially weighted data moments.
* :class:`PredictorRPBSID`: the classical state computed as a forward run
  of the VARX predictor (no LK), RLS system matrices.
* :class:`ClassicalRPBSID`: Houtzager et al.'s recursive PBSID.
* :class:`WindowedPBSID`: batch PBSID refitted on a sliding window.
* :func:`pbsid`: offline batch PBSID.
"""

from identifiers.base import (
    OnlineIdentifier,
    PredictionStateIdentifier,
    RecursiveVARXIdentifier,
    SystemRLSIdentifier,
)
from identifiers.batch import PBSIDResult, pbsid
from identifiers.change_detection import ChangeEvent, InnovationCUSUM, RegressionGLR
from identifiers.classical import ClassicalRPBSID
from identifiers.defaults import CLOSED_LOOP_SETTINGS, DEFAULT_SETTINGS, default_identifier
from identifiers.evaluation import (
    HORIZONS,
    add_measurement_noise,
    h_step_predictions,
    identification_inputs,
    modal_errors,
    normalized_error,
    one_step_predictions,
    paper_test_inputs,
    persistence_predictions,
    prediction_vaf,
    relative_gain_error,
    rigid_body_gain,
    unstable_share,
    vaf,
)
from identifiers.health import IdentifierHealth, IdentifierHealthWarning
from identifiers.improved import ImprovedRPBSID
from identifiers.kalman import KalmanPredictor, steady_state_gain
from identifiers.modal_basis import ModalFilterBank, Resonator
from identifiers.modal_discovery import discover_resonators, merge_resonators
from identifiers.model import ModelSequence, Modes, StateSpaceModel, observability_basis
from identifiers.moment_refit import MomentRefitRPBSID
from identifiers.predictor import PredictorRPBSID
from identifiers.rigid_flexible import RigidFlexibleIdentifier
from identifiers.rigid_gain import RigidGainEstimate
from identifiers.rls import RecursiveLeastSquares
from identifiers.windowed import WindowedPBSID
from spacecraft_conventions import __version__

__all__ = [
    "CLOSED_LOOP_SETTINGS",
    "DEFAULT_SETTINGS",
    "HORIZONS",
    "ChangeEvent",
    "ClassicalRPBSID",
    "IdentifierHealth",
    "IdentifierHealthWarning",
    "ImprovedRPBSID",
    "InnovationCUSUM",
    "KalmanPredictor",
    "ModalFilterBank",
    "ModelSequence",
    "Modes",
    "MomentRefitRPBSID",
    "OnlineIdentifier",
    "PBSIDResult",
    "PredictionStateIdentifier",
    "PredictorRPBSID",
    "RecursiveLeastSquares",
    "RecursiveVARXIdentifier",
    "RegressionGLR",
    "Resonator",
    "RigidFlexibleIdentifier",
    "RigidGainEstimate",
    "StateSpaceModel",
    "SystemRLSIdentifier",
    "WindowedPBSID",
    "__version__",
    "add_measurement_noise",
    "default_identifier",
    "discover_resonators",
    "h_step_predictions",
    "identification_inputs",
    "merge_resonators",
    "modal_errors",
    "normalized_error",
    "observability_basis",
    "one_step_predictions",
    "paper_test_inputs",
    "pbsid",
    "persistence_predictions",
    "prediction_vaf",
    "relative_gain_error",
    "rigid_body_gain",
    "steady_state_gain",
    "unstable_share",
    "vaf",
]
