"""The time-varying model sequence ``{A_k, B_k, C_k, D_k, K_k}`` an online identifier
produces, one innovation-form model (:class:`identifiers.core.model.StateSpaceModel`)
per sample (paper Sec. 4.3 judges identification on it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.model import StateSpaceModel, observability_basis

__all__ = ["ModelSequence"]


class ModelSequence(Sequence):
    """Time-varying model sequence from an online identifier.

    Entry k is the model after sample k was processed, or ``None`` while the
    identifier was warming up.

    Attributes
    ----------
    A, B, C, D, K : ndarray
        Stacked matrices, shape ``(N, ...)``; NaN where not warmed up.
    valid : (N,) bool ndarray
    states : (N, n) ndarray or None
        The identifier's state estimate after sample k, ``x_{k+1|k}``, in
        model k's coordinates (NaN where not warmed up); what h-step-ahead
        predictions start from.
    consistent_basis : bool
        True when every model uses the same state coordinates (every
        identifier of this package: the recursive ones by construction, the
        sliding-window method by aligning each refit to the previous one);
        False for a sequence of independently chosen bases, whose models are
        re-based into the :func:`observability_basis` before being chained.
    """

    def __init__(self, A: ArrayLike, B: ArrayLike, C: ArrayLike, D: ArrayLike, K: ArrayLike,
                 valid: ArrayLike, dt: float, consistent_basis: bool = True,
                 states: ArrayLike | None = None) -> None:
        self.A, self.B, self.C, self.D, self.K = (np.asarray(v) for v in (A, B, C, D, K))
        self.valid = np.asarray(valid, dtype=bool)
        self.dt = float(dt)
        self.consistent_basis = bool(consistent_basis)
        self.states = None if states is None else np.asarray(states, dtype=float)
        if self.states is not None and self.states.shape != (len(self.valid), self.A.shape[1]):
            raise ValueError(f"states must have shape ({len(self.valid)}, {self.A.shape[1]}), "
                             f"got {self.states.shape}")

    @classmethod
    def from_models(cls, models: Sequence[StateSpaceModel | None],
                    dt: float | None = None) -> ModelSequence:
        """Stack a list of models (``None`` entries allowed).

        Returns
        -------
        ModelSequence
            The stacked sequence (NaN matrices and ``valid`` False where a model is
            None).
        """
        first = next((m for m in models if m is not None), None)
        if first is None:
            raise ValueError("no model in the sequence")
        n, r, m = first.n, first.n_inputs, first.n_outputs
        N = len(models)
        arrays = [np.full((N, *s), np.nan) for s in ((n, n), (n, r), (m, n), (m, r), (n, m))]
        valid = np.zeros(N, dtype=bool)
        for k, mod in enumerate(models):
            if mod is None:
                continue
            valid[k] = True
            for arr, mat in zip(arrays, (mod.A, mod.B, mod.C, mod.D, mod.K), strict=True):
                arr[k] = mat
        return cls(*arrays, valid, dt if dt is not None else first.dt)

    def __len__(self) -> int:
        return self.valid.shape[0]

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        if not self.valid[k]:
            return None
        return StateSpaceModel(self.A[k], self.B[k], self.C[k], self.D[k], self.K[k], self.dt)

    def first_valid(self) -> int:
        """Index of the first warmed-up model.

        Returns
        -------
        int
            The index.
        """
        idx = np.flatnonzero(self.valid)
        if idx.size == 0:
            raise ValueError("no valid model in the sequence")
        return int(idx[0])

    def chained(self, k: int) -> StateSpaceModel:
        """Model k in coordinates that chain across steps (see ``consistent_basis``).

        Returns
        -------
        StateSpaceModel
            Model k, in the chaining coordinates.
        """
        mod = self[k]
        if self.consistent_basis:
            return mod
        try:
            return mod.transform(observability_basis(mod.A, mod.C))
        except np.linalg.LinAlgError:
            return mod

    def _index(self, k: int, k0: int) -> int:
        return k if k >= k0 and self.valid[k] else k0

    def simulate(self, inputs: np.ndarray, start: int | None = None) -> np.ndarray:
        """Response of the time-varying sequence from zero state (paper Sec. 4.3).

        ``x_{k+1} = A_k x_k + B_k u_k``, ``y_k = C_k x_k + D_k u_k``; steps
        before ``start`` (default: the first valid model) and invalid steps
        use the model at ``start``.

        Parameters
        ----------
        inputs : (N, r) ndarray
            Input sequence aligned with the models.

        Returns
        -------
        (N, m) ndarray
            The outputs, one row per sample.
        """
        return self._run(inputs, None, start)

    def predict(self, inputs: np.ndarray, outputs: np.ndarray,
                start: int | None = None) -> np.ndarray:
        """One-step-ahead predictions with the time-varying innovation predictor.

        ``x_{k+1} = A_k x_k + B_k u_k + K_k (y_k - C_k x_k - D_k u_k)``.

        Returns
        -------
        (N, m) ndarray
            ``yhat_{k|k-1}``, one row per sample.
        """
        return self._run(inputs, outputs, start)

    def _run(self, inputs: np.ndarray, outputs: np.ndarray | None,
             start: int | None) -> np.ndarray:
        """Chain the models over a record: simulation, or prediction if ``outputs``."""
        u = np.asarray(inputs, dtype=float)
        y = None if outputs is None else np.asarray(outputs, dtype=float)
        n_steps = min(len(self), u.shape[0]) if y is None else y.shape[0]
        k0 = self.first_valid() if start is None else int(start)
        x = np.zeros(self.A.shape[1])
        out = np.empty((n_steps, self.C.shape[1]))
        cache: dict[int, StateSpaceModel] = {}
        for k in range(n_steps):
            j = self._index(k, k0)
            mod = cache.get(j)
            if mod is None:
                cache = {j: self.chained(j)}
                mod = cache[j]
            out[k] = mod.C @ x + mod.D @ u[k]
            x = mod.A @ x + mod.B @ u[k]
            if y is not None:
                x += mod.K @ (y[k] - out[k])
        return out

    def modal(self, n_freq: int | None = None) -> np.ndarray:
        """Identified natural frequencies (Hz) per step, NaN-padded, (N, n_freq).

        Returns
        -------
        (N, n_freq) ndarray
            The frequencies, Hz, ascending per step; NaN where a step has fewer modes or
            no model.
        """
        n_half = self.A.shape[1] // 2 if n_freq is None else n_freq
        out = np.full((len(self), n_half), np.nan)
        for k in np.flatnonzero(self.valid):
            f, _ = self[k].modal(unique=False)
            f = f[:n_half]
            out[k, :f.size] = f
        return out
