"""The structure-aware RPBSID: the source paper's algorithm with the rigid body known.

:class:`StructuredRPBSID` (:mod:`identifiers.structured.structured_rpbsid`) runs
the paper's improved RPBSID on the flexible part
(:mod:`identifiers.structured.flexible_part`, its resonant part in
:mod:`identifiers.structured.resonant`) beside an exact :class:`RigidBlock`
(:mod:`identifiers.structured.rigid_block`: ZOH double integrators with the
recursively estimated gain).

Imports :mod:`identifiers.core` and :mod:`identifiers.subspace` (the recursive
PBSID it runs), never :mod:`identifiers.modal` or :mod:`identifiers.physical`.
"""

from identifiers.structured.rigid_block import RigidBlock
from identifiers.structured.structured_rpbsid import StructuredRPBSID

__all__ = ["RigidBlock", "StructuredRPBSID"]
