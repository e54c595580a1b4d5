"""Physical models fitted by output error, then held: the physical and drive-scheduled fits.

:class:`PhysicalFitIdentifier` (:mod:`identifiers.physical.physical_identifier`)
holds a :class:`PhysicalModel` (:mod:`identifiers.physical.physical_model`:
symmetric positive definite ``J^-1``, passive collocated modes) fitted once to
the warm-up by output error (:mod:`identifiers.physical.physical_fit`).
:class:`ScheduledPhysicalIdentifier`
(:mod:`identifiers.physical.scheduled_identifier`) fits the hub-plus-appendage
:class:`ScheduledPhysicalModel` (:mod:`identifiers.physical.scheduled_model`,
simulated by :mod:`identifiers.physical.scheduled_simulation`, fitted by
:mod:`identifiers.physical.scheduled_fit` from the starts of
:mod:`identifiers.physical.scheduled_start`, its uncertainty in
:mod:`identifiers.physical.scheduled_uncertainty`) whose turning appendages
follow a drive angle; its refits are judged before they run by
:mod:`identifiers.physical.scheduled_information`. Both fit through
:mod:`identifiers.physical.warmup_fit` (the record, a failed fit retried, the
filter on the held model).

Imports :mod:`identifiers.core` only.
"""

from identifiers.physical.physical_fit import PhysicalFit, fit_physical_model
from identifiers.physical.physical_identifier import PhysicalFitIdentifier
from identifiers.physical.physical_model import PhysicalModel
from identifiers.physical.scheduled_fit import ScheduledFit, fit_scheduled_model
from identifiers.physical.scheduled_identifier import ScheduledPhysicalIdentifier
from identifiers.physical.scheduled_model import ScheduledPhysicalModel

__all__ = [
    "PhysicalFit",
    "PhysicalFitIdentifier",
    "PhysicalModel",
    "ScheduledFit",
    "ScheduledPhysicalIdentifier",
    "ScheduledPhysicalModel",
    "fit_physical_model",
    "fit_scheduled_model",
]
