"""Online subspace identification of time-varying systems.

Streaming identifiers share one API: ``update(u, y)`` per sample,
``.model`` (a :class:`StateSpaceModel`, or None while warming up),
``.state``, ``.health``, ``fit(U, Y)`` and ``reset()``.

* :func:`default_identifier`: the recommended identifier for the
  spacecraft's outputs, with its settings.
* :class:`RigidFlexibleIdentifier`: known rigid-body kinematics, estimated
  inverse inertia and flexible modes, change detection; the default.
* :class:`PhysicalFitIdentifier`: a physical model (symmetric positive
  definite inverse inertia, passive collocated modes) fitted once to the
  warm-up by output error and held; for a plant that does not change much
  after its warm-up.
* :class:`ScheduledPhysicalIdentifier`: hub plus one mode per appendage,
  the turning appendages' couplings and inertia following a drive angle
  (``set_schedule``), fitted once to the warm-up by output error; for a
  spacecraft whose paddles turn.
* :class:`StructuredRPBSID`: the paper's improved recursive PBSID on the
  flexible part, beside an exact rigid block with the recursively estimated
  inverse inertia (the paper's algorithm with the rigid body known).
* :class:`ImprovedRPBSID`: the paper's improved recursive PBSID (affine
  projection sign state update), for reproduction.
* :class:`MomentRefitRPBSID`: recursive VARX plus batch-equivalent refits of
  the system matrices from exponentially weighted data moments.
* :class:`PredictorRPBSID`: the classical state computed as a forward run
  of the VARX predictor (no LK), RLS system matrices.
* :class:`ClassicalRPBSID`: Houtzager et al.'s recursive PBSID.
* :class:`WindowedPBSID`: batch PBSID refitted on a sliding window.
* :func:`pbsid`: offline batch PBSID.

The package has four families over a small core, and imports run one way
(``core`` <- ``subspace`` <- ``modal``, ``physical``, ``structured`` <- the
modules at the top; the three structure-aware families never import each other):

* :mod:`identifiers.core`: what every method uses: the streaming base class
  (:class:`OnlineIdentifier`) composed of its sample guard
  (:mod:`identifiers.core.screening`) and its health guard
  (:mod:`identifiers.core.rollback`), the one RLS primitive, the models,
  the Kalman predictor, the health report and the data monitor; and what the
  structure-aware families share: the modal filter bank, the rigid-body gain,
  the change tests and the filter on an identified model;
* :mod:`identifiers.subspace` (black-box): the predictor-based subspace methods
  (recursive, sliding-window and batch PBSID) and their shared stages;
* :mod:`identifiers.modal`: the rigid-flexible identifier
  (:class:`RigidFlexibleIdentifier`) and its parts: the modal regression, the
  mode search and tracker, the exported model;
* :mod:`identifiers.physical`: physical models fitted by output error and held
  (:class:`PhysicalFitIdentifier`, the drive-scheduled
  :class:`ScheduledPhysicalIdentifier`);
* :mod:`identifiers.structured`: the structure-aware RPBSID
  (:class:`StructuredRPBSID`): the paper's RPBSID with the rigid body known;
* :mod:`identifiers.defaults` (the recommended settings) and
  :mod:`identifiers.signals` (test inputs and noise) and
  :mod:`identifiers.evaluation` (predictions and scores).

Everything public is importable from ``identifiers`` itself.
"""

from identifiers.core.background import FIT_OUTCOMES, FitTiming
from identifiers.core.change_detection import ChangeEvent, InnovationCUSUM, RegressionGLR
from identifiers.core.fit_jobs import FitCancelled, cancel_fits, cancellation_point
from identifiers.core.health import IdentifierHealth, IdentifierHealthWarning
from identifiers.core.kalman import KalmanPredictor, steady_state_gain
from identifiers.core.modal_basis import ModalFilterBank, Resonator
from identifiers.core.model import Modes, StateSpaceModel, observability_basis
from identifiers.core.model_sequence import ModelSequence
from identifiers.core.online import OnlineIdentifier
from identifiers.core.rigid_gain import RigidGainEstimate
from identifiers.core.rls import RecursiveLeastSquares
from identifiers.defaults import (
    CLOSED_LOOP_SETTINGS,
    DEFAULT_SETTINGS,
    STRUCTURED_CLOSED_LOOP_SETTINGS,
    default_identifier,
)
from identifiers.evaluation import (
    HORIZONS,
    h_step_predictions,
    modal_errors,
    normalized_error,
    one_step_predictions,
    persistence_predictions,
    prediction_vaf,
    relative_gain_error,
    rigid_body_gain,
    unstable_share,
    vaf,
)
from identifiers.modal.modal_discovery import discover_resonators, merge_resonators
from identifiers.modal.rigid_flexible import RigidFlexibleIdentifier
from identifiers.physical.physical_fit import PhysicalFit, fit_physical_model
from identifiers.physical.physical_identifier import PhysicalFitIdentifier
from identifiers.physical.physical_model import PhysicalModel
from identifiers.physical.scheduled_fit import ScheduledFit, fit_scheduled_model
from identifiers.physical.scheduled_identifier import ScheduledPhysicalIdentifier
from identifiers.physical.scheduled_model import ScheduledPhysicalModel
from identifiers.signals import add_measurement_noise, identification_inputs, paper_test_inputs
from identifiers.structured.rigid_block import RigidBlock
from identifiers.structured.structured_rpbsid import StructuredRPBSID
from identifiers.subspace.batch import PBSIDResult, pbsid
from identifiers.subspace.classical import ClassicalRPBSID
from identifiers.subspace.improved import ImprovedRPBSID
from identifiers.subspace.moment_refit import MomentRefitRPBSID
from identifiers.subspace.predictor import PredictorRPBSID
from identifiers.subspace.recursive import (
    PredictionStateIdentifier,
    RecursiveVARXIdentifier,
    SystemRLSIdentifier,
)
from identifiers.subspace.windowed import WindowedPBSID
from spacecraft_conventions import __version__

__all__ = [
    "CLOSED_LOOP_SETTINGS",
    "DEFAULT_SETTINGS",
    "FIT_OUTCOMES",
    "HORIZONS",
    "STRUCTURED_CLOSED_LOOP_SETTINGS",
    "ChangeEvent",
    "ClassicalRPBSID",
    "FitCancelled",
    "FitTiming",
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
    "PhysicalFit",
    "PhysicalFitIdentifier",
    "PhysicalModel",
    "PredictionStateIdentifier",
    "PredictorRPBSID",
    "RecursiveLeastSquares",
    "RecursiveVARXIdentifier",
    "RegressionGLR",
    "Resonator",
    "RigidBlock",
    "RigidFlexibleIdentifier",
    "RigidGainEstimate",
    "ScheduledFit",
    "ScheduledPhysicalIdentifier",
    "ScheduledPhysicalModel",
    "StateSpaceModel",
    "StructuredRPBSID",
    "SystemRLSIdentifier",
    "WindowedPBSID",
    "__version__",
    "add_measurement_noise",
    "cancel_fits",
    "cancellation_point",
    "default_identifier",
    "discover_resonators",
    "fit_physical_model",
    "fit_scheduled_model",
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
