"""Online subspace identification of time-varying systems.

Streaming identifiers share one API: ``update(u, y)`` per sample,
``.model`` (a :class:`StateSpaceModel`, or None while warming up),
``.state``, ``fit(U, Y)`` and ``reset()``.

* :class:`ImprovedRPBSID`: recursive PBSID without Hankel matrix or SVD per
  step; ``variant="predictor"`` (default) or the paper's ``"apsa"``.
* :class:`ClassicalRPBSID`: Houtzager et al.'s recursive PBSID.
* :class:`WindowedPBSID`: batch PBSID refitted on a sliding window.
* :func:`pbsid`: offline batch PBSID.
"""

from identifiers.base import OnlineIdentifier, RecursivePBSIDBase
from identifiers.batch import PBSIDResult, pbsid
from identifiers.classical import ClassicalRPBSID
from identifiers.evaluation import (
    add_measurement_noise,
    identification_inputs,
    normalized_error,
    one_step_predictions,
    paper_test_inputs,
    vaf,
)
from identifiers.improved import VARIANTS, ImprovedRPBSID
from identifiers.model import ModelSequence, StateSpaceModel, observability_basis
from identifiers.rls import RecursiveLeastSquares
from identifiers.windowed import WindowedPBSID

__all__ = [
    "VARIANTS",
    "ClassicalRPBSID",
    "ImprovedRPBSID",
    "ModelSequence",
    "OnlineIdentifier",
    "PBSIDResult",
    "RecursiveLeastSquares",
    "RecursivePBSIDBase",
    "StateSpaceModel",
    "WindowedPBSID",
    "add_measurement_noise",
    "identification_inputs",
    "normalized_error",
    "observability_basis",
    "one_step_predictions",
    "paper_test_inputs",
    "pbsid",
    "vaf",
]
