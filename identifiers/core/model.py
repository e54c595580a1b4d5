"""Identified discrete-time state-space models in innovation form.

    x_{k+1} = A x_k + B u_k + K e_k,      y_k = C x_k + D u_k + e_k

:class:`StateSpaceModel` holds one model
(:class:`identifiers.core.model_sequence.ModelSequence` the time-varying sequence an
online identifier produces).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # python-control is imported only by to_control()
    import control

__all__ = ["Modes", "StateSpaceModel", "observability_basis"]


def observability_basis(a: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``T`` = the first n rows of ``[C; CA; CA^2; ...]``.

    ``x' = T x`` expresses a model in "predicted-output" coordinates: the
    state is the first n entries of the stacked free-response output
    predictions. For an observable model whose first n such rows are
    independent these coordinates depend on the input-output behaviour
    only, so models identified in different bases can be compared and
    chained (:meth:`ModelSequence.chained` uses it for sequences whose
    models do not share a basis).

    Parameters
    ----------
    a : (n, n) ndarray
        State matrix ``A``.
    c : (m, n) ndarray
        Output matrix ``C``.

    Returns
    -------
    (n, n) ndarray
        ``T``; singular if the model is unobservable or its first n stacked
        rows are dependent.

    Raises
    ------
    ValueError
        ``a`` not square, or ``c`` without rows or of another width.
    """
    n = a.shape[0]
    if c.ndim != 2 or c.shape[0] < 1 or c.shape[1] != n or a.shape != (n, n):
        raise ValueError(f"a must be (n, n) and c (m, n) with m >= 1, got {a.shape} and "
                         f"{c.shape}")
    rows, block = [], c
    total = 0
    while total < n:
        rows.append(block)
        total += block.shape[0]
        block = block @ a
    return np.vstack(rows)[:n]


# the functional form keeps real types in the annotations (this module postpones its own,
# which the API reference cannot resolve inside a named tuple's generated __new__)
Modes = NamedTuple("Modes", [("frequency_hz", np.ndarray), ("damping", np.ndarray)])  # noqa: UP014
Modes.__doc__ = """Oscillatory modes of a model (:meth:`StateSpaceModel.modal`).

    Attributes
    ----------
    frequency_hz : (k,) ndarray
        Natural frequencies, Hz, ascending.
    damping : (k,) ndarray
        Damping ratios.
    """


@dataclass(frozen=True, eq=False, repr=False)
class StateSpaceModel:
    """Discrete-time innovation-form model ``(A, B, C, D, K)``.

    Attributes
    ----------
    A : (n, n) ndarray
    B : (n, r) ndarray
    C : (m, n) ndarray
    D : (m, r) ndarray
    K : (n, m) ndarray
        Kalman (predictor) gain.
    dt : float
        Sample time, s.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray
    dt: float = 0.1

    def __post_init__(self) -> None:
        mats = {}
        for name in ("A", "B", "C", "D", "K"):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.ndim != 2:
                raise ValueError(f"{name} must be 2-D, got shape {arr.shape}")
            arr.flags.writeable = False
            mats[name] = arr
            object.__setattr__(self, name, arr)
        n, r, m = self.n, self.B.shape[1], self.C.shape[0]
        expected = {"A": (n, n), "B": (n, r), "C": (m, n), "D": (m, r), "K": (n, m)}
        for name, shape in expected.items():
            if mats[name].shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {mats[name].shape}")
        dt = float(self.dt)
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive finite number of seconds, got {self.dt}")
        object.__setattr__(self, "dt", dt)

    @property
    def n(self) -> int:
        """State order."""
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    def to_control(self) -> control.StateSpace:
        """The deterministic part as a ``control.StateSpace`` with ``dt``.

        Returns
        -------
        control.StateSpace
            ``(A, B, C, D)`` at the model's sample time.
        """
        import control

        return control.StateSpace(self.A, self.B, self.C, self.D, self.dt)

    def poles(self) -> np.ndarray:
        """Eigenvalues of A (discrete).

        Returns
        -------
        (n,) complex ndarray
            The discrete-time poles.
        """
        return np.linalg.eigvals(self.A)

    def modal(self, unique: bool = True) -> Modes:
        """Natural frequencies (Hz) and damping ratios of the oscillatory poles.

        Continuous equivalents ``s = log(z) / dt`` of the eigenvalues with
        positive imaginary part, sorted by frequency.

        Parameters
        ----------
        unique : bool
            Report a repeated pole once (default). An identifier that gives a
            resonator more than one input-output direction (the rigid-flexible
            identifier's rank-2 couplings) repeats its pole exactly; ``False``
            lists every pole with its multiplicity.

        Returns
        -------
        Modes
            ``(frequency_hz, damping)``, two ``(k,)`` arrays; unpacks as a
            pair.

        Examples
        --------
        >>> import numpy as np
        >>> w, zeta, dt = 2 * np.pi * 0.5, 0.02, 0.1
        >>> s = complex(-zeta * w, w * np.sqrt(1 - zeta**2))
        >>> z = np.exp(s * dt)
        >>> a = np.array([[z.real, -z.imag], [z.imag, z.real]])
        >>> m = StateSpaceModel(a, np.ones((2, 1)), np.ones((1, 2)), np.zeros((1, 1)),
        ...                     np.zeros((2, 1)), dt)
        >>> f, d = m.modal()
        >>> print(f"{f[0]:.3f} Hz, damping {d[0]:.3f}")
        0.500 Hz, damping 0.020
        """
        z = self.poles()
        z = z[z.imag > 1e-12]
        if unique and z.size:
            z = np.sort_complex(z)
            keep = np.ones(z.size, dtype=bool)
            keep[1:] = np.abs(np.diff(z)) > 1e-9 * np.maximum(np.abs(z[1:]), 1.0)
            z = z[keep]
        s = np.log(z) / self.dt
        wn = np.abs(s)
        order = np.argsort(wn, kind="stable")
        return Modes(wn[order] / (2 * np.pi), -s.real[order] / wn[order])

    def __repr__(self) -> str:
        f, zeta = self.modal()
        radius = float(np.abs(self.poles()).max(initial=0.0))
        shown = ", ".join(f"{fi:.4g} Hz ({zi:.2g})" for fi, zi in zip(f[:4], zeta[:4],
                                                                        strict=True))
        more = f", ... {f.size - 4} more" if f.size > 4 else ""
        return (f"StateSpaceModel(n={self.n}, inputs={self.n_inputs}, "
                f"outputs={self.n_outputs}, dt={self.dt:g} s, spectral radius "
                f"{radius:.6f}, modes (damping): {shown or 'none'}{more})")

    def transform(self, t: np.ndarray) -> StateSpaceModel:
        """Same model in coordinates ``x' = T x``.

        Returns
        -------
        StateSpaceModel
            ``(T A T^-1, T B, C T^-1, D, T K)``.
        """
        t_inv = np.linalg.inv(t)
        return StateSpaceModel(t @ self.A @ t_inv, t @ self.B, self.C @ t_inv, self.D,
                               t @ self.K, self.dt)

    def in_observability_basis(self) -> StateSpaceModel:
        """The model in the :func:`observability_basis` coordinates.

        Returns
        -------
        StateSpaceModel
            The same input-output model in those coordinates.
        """
        return self.transform(observability_basis(self.A, self.C))

    def simulate(self, inputs: ArrayLike, x0: ArrayLike | None = None) -> np.ndarray:
        """Deterministic response ``y_k = C x_k + D u_k`` to ``inputs`` (N, r) from ``x0``.

        Returns
        -------
        (N, m) ndarray
            The outputs, one row per input sample.

        Raises
        ------
        ValueError
            If ``inputs`` is not (N, r) or ``x0`` not (n,).
        """
        return self._run(self._inputs(inputs), None, x0)

    def predict(self, inputs: ArrayLike, outputs: ArrayLike,
                x0: ArrayLike | None = None) -> np.ndarray:
        """One-step-ahead predictions ``yhat_{k|k-1}`` with the innovation gain K.

        Returns
        -------
        (N, m) ndarray
            ``yhat_{k|k-1}``, one row per sample.

        Raises
        ------
        ValueError
            If ``inputs`` is not (N, r), ``outputs`` not (N, m) or ``x0`` not (n,).
        """
        u = self._inputs(inputs)
        y = np.asarray(outputs, dtype=float)
        if y.shape != (u.shape[0], self.n_outputs):
            raise ValueError(f"outputs must have shape ({u.shape[0]}, {self.n_outputs}), "
                             f"got {y.shape}")
        return self._run(u, y, x0)

    def _inputs(self, inputs: ArrayLike) -> np.ndarray:
        u = np.asarray(inputs, dtype=float)
        if u.ndim != 2 or u.shape[1] != self.n_inputs:
            raise ValueError(f"inputs must have shape (N, {self.n_inputs}), got {u.shape}")
        return u

    def _run(self, u: np.ndarray, y: np.ndarray | None, x0: ArrayLike | None) -> np.ndarray:
        """Simulation, or one-step prediction when measured outputs ``y`` are given."""
        x = np.zeros(self.n) if x0 is None else np.asarray(x0, dtype=float)
        if x.shape != (self.n,):
            raise ValueError(f"x0 must have shape ({self.n},), got {x.shape}")
        out = np.empty((u.shape[0], self.n_outputs))
        for k in range(u.shape[0]):
            out[k] = self.C @ x + self.D @ u[k]
            x = self.A @ x + self.B @ u[k]
            if y is not None:
                x += self.K @ (y[k] - out[k])
        return out
