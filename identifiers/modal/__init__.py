"""The rigid-flexible identifier: a modal model that knows the rigid body.

:class:`RigidFlexibleIdentifier` (:mod:`identifiers.modal.rigid_flexible`) uses
what physics fixes (the rigid body's kinematics, modes as resonators, which
sensor sees what) and estimates the rest. Its parts, each in its own module:

* :mod:`identifiers.modal.modal_regression`: the modes found, rebuilt on and
  tracked, the sensor groups' regressions and the reaction to a change
  (:mod:`identifiers.modal.record_replay`: the kept record replayed after a
  rebuild);
* :mod:`identifiers.modal.modal_discovery`: the batch search for the modes;
  :mod:`identifiers.modal.modal_tracker`: their tracking;
* :mod:`identifiers.modal.minimal_model`: the exported model and the estimates
  it reports.

The filter bank (:mod:`identifiers.core.modal_basis`), the rigid-body gain
(:mod:`identifiers.core.rigid_gain`), the change tests
(:mod:`identifiers.core.change_detection`) and the model filter
(:mod:`identifiers.core.state_filter`) are shared with the other structure-aware
families and live in :mod:`identifiers.core`. Imports :mod:`identifiers.core`
and :mod:`identifiers.subspace` (the mode search runs a batch PBSID), never
:mod:`identifiers.physical` or :mod:`identifiers.structured`.
"""

from identifiers.modal.modal_discovery import discover_resonators, merge_resonators
from identifiers.modal.rigid_flexible import RigidFlexibleIdentifier

__all__ = ["RigidFlexibleIdentifier", "discover_resonators", "merge_resonators"]
