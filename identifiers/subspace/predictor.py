"""Recursive PBSID with the classical state computed without LK.

The state is the first n entries (or an SVD basis) of the VARX predictor
run forward ``f`` steps from the past window, with future inputs set to
zero and each future output replaced by its own prediction. This equals the
classical RPBSID state ``x = W LK phi`` exactly (the weighted LK applied to
the past window is that forward run) without ever forming LK:
O(f m p (r + m)) per step instead of O(f^2 m^2 p (r + m)). ``C`` and
``[A B K]`` then follow by RLS (paper Eq. 47-55) as in the classical
method, whose accuracy it shares for the same ``f`` and ``W``.
"""

from __future__ import annotations

import numpy as np

from identifiers.subspace.recursive import PredictionStateIdentifier
from identifiers.subspace.varx import free_response

__all__ = ["PredictorRPBSID"]


class PredictorRPBSID(PredictionStateIdentifier):
    """Recursive PBSID whose state is a forward run of the VARX predictor.

    Parameters
    ----------
    n, p, forgetting
        Order, past window, forgetting factor.
    **kwargs
        ``f``, ``basis``, ``dt``, ``warmup`` and the constants of
        :class:`identifiers.subspace.recursive.PredictionStateIdentifier`.
    """

    def _predictions(self, phi: np.ndarray) -> np.ndarray:
        return free_response(self._varx.theta, phi, self.n_inputs, self._horizon)
