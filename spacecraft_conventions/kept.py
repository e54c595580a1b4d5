"""A value kept while the arrays it was computed from stay equal.

The adaptive LQG reads the identifier's model every step, but an identifier
holds the same matrices over several steps (the scheduled fit re-discretizes
only when the drive has turned by its resolution; a docking plant's model
holds between refits). Everything that depends on the model alone (the
exported model object itself, the law's weight and augmented model, its
equilibrium map, the acceptance test's unit states, the filter's process
noise, a converged Riccati design) is therefore kept, keyed on the bits of
its inputs, and computed again only when one of them changes.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from typing import Any, Generic, TypeVar

import numpy as np

__all__ = ["KeptWhileEqual"]

T = TypeVar("T")

_DOUBLE = struct.Struct("<d")


class KeptWhileEqual(Generic[T]):
    """One value and the inputs it was computed from, compared bit for bit.

    The inputs are kept as snapshots of their bits (shape, dtype and bytes),
    so a caller that changes its arrays in place never finds a stale value.
    Bits, not values, are the key: the kept value is a deterministic function
    of the inputs, so inputs with the same bits give the same value exactly
    (an input holding NaN keeps its value too), while ``0.0`` and ``-0.0``,
    equal as values, are different inputs. Comparing bytes also costs a
    fraction of ``numpy.array_equal``'s call on the small matrices of the
    adaptive loop, which makes several such comparisons every step.
    """

    def __init__(self) -> None:
        self._inputs: tuple[tuple[Any, ...], ...] | None = None
        self._value: T | None = None

    @staticmethod
    def _bits(value: Any) -> tuple[Any, ...]:
        kind = type(value)
        if kind is float:
            return kind, _DOUBLE.pack(value)
        if kind is int or kind is bool:
            return kind, value
        array = value if kind is np.ndarray else np.asarray(value)
        if array.dtype.hasobject:
            # an object array's bytes are addresses, not values
            raise TypeError(f"inputs must be numeric arrays or scalars, got {kind.__name__} "
                            f"of dtype object")
        return array.shape, array.dtype, array.tobytes()

    def holds(self, inputs: Sequence[Any]) -> bool:
        """Whether a value is kept and every input has the bits (shape, dtype and
        bytes) of the one it was kept for.

        Returns
        -------
        bool
            True when the kept value may be handed out for ``inputs``.
        """
        kept = self._inputs
        if kept is None or len(kept) != len(inputs):
            return False
        bits = self._bits
        return all(old == bits(new) for old, new in zip(kept, inputs, strict=True))

    @property
    def value(self) -> T | None:
        """The kept value (None when nothing is kept)."""
        return self._value

    def keep(self, inputs: Sequence[Any], value: T) -> T:
        """Keep ``value`` for ``inputs``; returns ``value``.

        Returns
        -------
        object
            ``value``, unchanged.
        """
        self._inputs = tuple(self._bits(m) for m in inputs)
        self._value = value
        return value

    def get(self, inputs: Sequence[Any], compute: Callable[[], T]) -> T:
        """The kept value for ``inputs``, or ``compute()`` kept for them.

        Returns
        -------
        object
            The kept or newly computed value.
        """
        return self._value if self.holds(inputs) else self.keep(inputs, compute())

    def clear(self) -> None:
        """Forget the kept value."""
        self._inputs = self._value = None
