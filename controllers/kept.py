"""A value kept while the arrays it was computed from stay equal.

The adaptive LQG is handed a new model object every step, but an identifier
holds the same matrices over several steps (the scheduled fit re-discretizes
only when the drive has turned by its resolution; a docking plant's model
holds between refits). Everything that depends on the model alone (the
law's weight and augmented model, its equilibrium map, the acceptance test's
unit states, the filter's process noise, a converged Riccati design) is
therefore kept, keyed on the values of its inputs, and computed again only
when one of them changes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Generic, TypeVar

import numpy as np

__all__ = ["KeptWhileEqual"]

T = TypeVar("T")


class KeptWhileEqual(Generic[T]):
    """One value and the inputs it was computed from, compared by value.

    The inputs are kept as read-only arrays are (by reference: nobody can
    change them, e.g. a :class:`~identifiers.core.model.StateSpaceModel`'s
    matrices) or as copies (anything writeable), so a caller that changes
    its arrays in place never finds a stale value.
    """

    def __init__(self) -> None:
        self._inputs: tuple[np.ndarray, ...] | None = None
        self._value: T | None = None

    def holds(self, inputs: Sequence[Any]) -> bool:
        """Whether a value is kept and every input equals the one it was kept for
        (``numpy.array_equal``)."""
        kept = self._inputs
        return kept is not None and len(kept) == len(inputs) and all(
            np.array_equal(old, new) for old, new in zip(kept, inputs, strict=True))

    @property
    def value(self) -> T | None:
        """The kept value (None when nothing is kept)."""
        return self._value

    def keep(self, inputs: Sequence[Any], value: T) -> T:
        """Keep ``value`` for ``inputs``; returns ``value``."""
        arrays = (np.asarray(m) for m in inputs)
        self._inputs = tuple(m if not m.flags.writeable else m.copy() for m in arrays)
        self._value = value
        return value

    def get(self, inputs: Sequence[Any], compute: Callable[[], T]) -> T:
        """The kept value for ``inputs``, or ``compute()`` kept for them."""
        return self._value if self.holds(inputs) else self.keep(inputs, compute())

    def clear(self) -> None:
        """Forget the kept value."""
        self._inputs = self._value = None
