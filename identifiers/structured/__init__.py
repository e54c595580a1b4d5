"""The structure-aware identifier and its parts.

:class:`RigidFlexibleIdentifier` (:mod:`identifiers.structured.rigid_flexible`)
uses what physics fixes (the rigid body's kinematics, modes as resonators,
which sensor sees what) and estimates the rest. Its parts, each in its own
module:

* :mod:`identifiers.structured.modal_basis` (and its compiled kernels
  :mod:`identifiers.structured.modal_kernels`): the modal filter bank
  that makes every output linear in the unknown gains;
* :mod:`identifiers.structured.modal_discovery`: the batch search for the
  modes; :mod:`identifiers.structured.modal_tracker`: their tracking;
* :mod:`identifiers.structured.rigid_gain`: the rigid-body gain
  ``J^-1`` with its calibrated uncertainty;
* :mod:`identifiers.structured.change_detection`: the change tests.

:class:`PhysicalFitIdentifier` (:mod:`identifiers.structured.physical_identifier`)
is the other structure-aware identifier: a :class:`PhysicalModel`
(:mod:`identifiers.structured.physical_model`: symmetric positive definite
``J^-1``, passive collocated modes) fitted once to the warm-up by output
error (:mod:`identifiers.structured.physical_fit`) and then held;
:class:`ScheduledPhysicalIdentifier` (:mod:`identifiers.structured.scheduled_identifier`)
fits the hub-plus-appendage :class:`ScheduledPhysicalModel`
(:mod:`identifiers.structured.scheduled_model`, fitted by
:mod:`identifiers.structured.scheduled_fit` from the starts of
:mod:`identifiers.structured.scheduled_start`) whose turning appendages follow
a drive angle; its refits are judged before they run by
:mod:`identifiers.structured.scheduled_information`.

:class:`StructuredRPBSID` (:mod:`identifiers.structured.structured_rpbsid`) is
the paper's improved RPBSID on the flexible part beside an exact
:class:`RigidBlock` (ZOH double integrators with the recursively estimated
gain): the source paper's algorithm with the rigid body known.

Imports :mod:`identifiers.core` and :mod:`identifiers.subspace` (the mode
search runs a batch PBSID), never the reverse.
"""

from identifiers.structured.change_detection import ChangeEvent, InnovationCUSUM, RegressionGLR
from identifiers.structured.modal_basis import ModalFilterBank, Resonator
from identifiers.structured.modal_discovery import discover_resonators, merge_resonators
from identifiers.structured.physical_fit import PhysicalFit, fit_physical_model
from identifiers.structured.physical_identifier import PhysicalFitIdentifier
from identifiers.structured.physical_model import PhysicalModel
from identifiers.structured.rigid_block import RigidBlock
from identifiers.structured.rigid_flexible import RigidFlexibleIdentifier
from identifiers.structured.rigid_gain import RigidGainEstimate
from identifiers.structured.scheduled_fit import ScheduledFit, fit_scheduled_model
from identifiers.structured.scheduled_identifier import ScheduledPhysicalIdentifier
from identifiers.structured.scheduled_model import ScheduledPhysicalModel
from identifiers.structured.structured_rpbsid import StructuredRPBSID

__all__ = [
    "ChangeEvent",
    "InnovationCUSUM",
    "ModalFilterBank",
    "PhysicalFit",
    "PhysicalFitIdentifier",
    "PhysicalModel",
    "RegressionGLR",
    "Resonator",
    "RigidBlock",
    "RigidFlexibleIdentifier",
    "RigidGainEstimate",
    "ScheduledFit",
    "ScheduledPhysicalIdentifier",
    "ScheduledPhysicalModel",
    "StructuredRPBSID",
    "discover_resonators",
    "fit_physical_model",
    "fit_scheduled_model",
    "merge_resonators",
]
