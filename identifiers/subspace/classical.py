"""Classical recursive PBSID (Houtzager, van Wingerden, Verhaegen).

Per step: recursive VARX update, then the product of observability and
controllability matrices LK (f m x p (r + m)) is rebuilt from the current
Markov parameters and the state is ``x_k = W LK phi_k``; RLS then gives
``[C D]`` and ``[A B K]`` (docs/design/identification.md). The "weighted"
LK (default) replaces each future output by its own prediction, which keeps
the estimate consistent on closed-loop data; the unweighted one is the
plain shift.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from identifiers.subspace.recursive import PredictionStateIdentifier
from identifiers.subspace.varx import predictor_product

__all__ = ["ClassicalRPBSID"]


class ClassicalRPBSID(PredictionStateIdentifier):
    """Classical recursive predictor-based subspace identification.

    Parameters
    ----------
    n, p, forgetting
        Order, past window, forgetting factor (paper: 15 and 0.98).
    weighted : bool
        Weighted (closed-loop consistent) LK; default True.
    **kwargs
        ``f`` (default ``p``, as the PBSID toolbox's ``rpbsid``), ``basis``,
        ``dt``, ``warmup`` and the constants of
        :class:`identifiers.subspace.recursive.PredictionStateIdentifier`.

    Notes
    -----
    Building LK costs O(f^2 m^2 p (r + m)) per step; this is what
    :class:`identifiers.subspace.predictor.PredictorRPBSID` avoids.

    Examples
    --------
    A lightly damped 0.5 Hz resonance sampled at 10 Hz, identified from 200 s of
    a white input:

    >>> import numpy as np
    >>> from identifiers import ClassicalRPBSID
    >>> r, theta = np.exp(-0.05 * np.pi * 0.1), np.pi * np.sqrt(1 - 0.05**2) * 0.1
    >>> A = np.array([[2 * r * np.cos(theta), -r**2], [1.0, 0.0]])
    >>> B, C = np.array([[1.0], [0.0]]), np.array([[0.1, 0.05]])
    >>> ident = ClassicalRPBSID(n=2, p=10)
    >>> rng, x = np.random.default_rng(0), np.zeros(2)
    >>> for _ in range(2000):
    ...     u = rng.standard_normal(1)
    ...     ident.update(u, C @ x)
    ...     x = A @ x + B @ u
    >>> modes = ident.model.modal()
    >>> modes.frequency_hz.round(3), modes.damping.round(3)   # truth: 0.5 Hz, 0.05
    (array([0.5]), array([0.05]))
    """

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.9995, *,
                 weighted: bool = True, **kwargs: Any) -> None:
        self.weighted = bool(weighted)
        kwargs.setdefault("f", p)
        super().__init__(n, p, forgetting, **kwargs)

    def _predictions(self, phi: np.ndarray) -> np.ndarray:
        return self._state_map() @ phi

    def _predictions_many(self, phis: np.ndarray) -> np.ndarray:
        return phis @ self._state_map().T          # one LK for the warm-up's samples

    def _state_map(self) -> np.ndarray:
        """LK of the current VARX, (f m, p (r + m))."""
        return predictor_product(self._varx.theta, self.n_inputs, self._horizon, self.weighted)
