"""Predictor-based subspace identification: recursive, sliding-window and batch PBSID.

Black-box methods: the state is in coordinates of their own. The recursive
ones share the stages of :mod:`identifiers.subspace.recursive` (the
recursive VARX predictor, RLS on a state sequence) and the VARX helpers of
:mod:`identifiers.subspace.varx`:

* :class:`ImprovedRPBSID` (:mod:`identifiers.subspace.improved`): the
  source paper's improved recursive PBSID;
* :class:`ClassicalRPBSID` (:mod:`identifiers.subspace.classical`):
  Houtzager et al.'s recursive PBSID;
* :class:`PredictorRPBSID` (:mod:`identifiers.subspace.predictor`) and
  :class:`MomentRefitRPBSID` (:mod:`identifiers.subspace.moment_refit`):
  two variants measured beside them;
* :class:`WindowedPBSID` (:mod:`identifiers.subspace.windowed`) and
  :func:`pbsid` (:mod:`identifiers.subspace.batch`): batch PBSID on a
  sliding window, and offline.

Imports only :mod:`identifiers.core`.
"""

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

__all__ = [
    "ClassicalRPBSID",
    "ImprovedRPBSID",
    "MomentRefitRPBSID",
    "PBSIDResult",
    "PredictionStateIdentifier",
    "PredictorRPBSID",
    "RecursiveVARXIdentifier",
    "SystemRLSIdentifier",
    "WindowedPBSID",
    "pbsid",
]
