"""Outputs found wrong after they were recorded, corrected in a held fit's record.

A sensor fault is often declared seconds after it struck: a gyro bias is found when the
star tracker has integrated enough of it. Until then the identifier recorded the biased
readings, its state's filter ran on them, and its change test may have fired on them as
if the plant had changed. :class:`OutputCorrection` (a :class:`WarmupFit` host) takes a
correction of the outputs since a sample: the record (:meth:`WarmupFit.update`'s
``_history`` and a refit's ``_record``) takes the corrected samples, the state's filter
is run again over them from its prior at the first, the change test starts afresh, and
an alarm raised since then whose refit record is still being taken is dismissed
(``confirmed`` False: it was the sensor's, not the plant's). A fit running in the
background forked before the correction: the correction is applied again when that
fit's state takes over.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from identifiers.physical.warmup_fit import WarmupFit

__all__ = ["OutputCorrection"]


class OutputCorrection(WarmupFit):
    """A :class:`identifiers.physical.warmup_fit.WarmupFit` that takes late corrections of
    its outputs (:meth:`correct_outputs`)."""

    def reset(self) -> None:
        super().reset()
        #: corrections made while a background fit ran, applied again when it lands
        self._corrections: list[tuple[np.ndarray, int, int]] = []

    def restart(self) -> None:
        super().restart()
        self._corrections = []

    def correct_outputs(self, offset: ArrayLike, since: int, stop: int | None = None) -> None:
        """The outputs of samples ``since`` to ``stop`` read ``offset`` too much.

        Parameters
        ----------
        offset : (m,) array_like
            What the outputs read too much, in their physical units (the order of the
            identifier's layout).
        since : int
            The first sample corrected, counted from the first update (>= 0).
        stop : int, optional
            The sample after the last corrected (default: every sample since).

        Returns
        -------
        None

        Raises
        ------
        ValueError
            For an offset that is not one finite value per output, or a negative
            ``since``.
        """
        offset = np.asarray(offset, dtype=float)
        if self._sy is not None and (offset.shape != self._sy.shape
                                     or not np.isfinite(offset).all()):
            raise ValueError(f"offset must be {self._sy.shape[0]} finite values, one per "
                             f"output, got shape {offset.shape}")
        if since < 0:
            raise ValueError(f"since must be a sample index >= 0, got {since}")
        if self._sy is None:                  # nothing recorded yet
            return
        stop = self.n_samples if stop is None else int(stop)
        if self.fit_pending:
            self._corrections.append((offset, since, stop))
        first, last = (self._count - (self.n_samples - k) for k in (since, stop))
        shift = offset / self._sy
        fixed: dict[int, tuple] = {}
        for items in (self._history, self._record):
            origin = self._count - len(items)
            for i in range(max(first - origin, 0), min(last - origin, len(items))):
                item = items[i]
                # the two records share their items: each corrected once, in new tuples
                # (a running fit holds the old ones)
                if id(item) not in fixed:
                    fixed[id(item)] = (item[0], item[1] - shift, *item[2:])
                items[i] = fixed[id(item)]
        back = self._count - first
        if self._kf is not None and self.accumulate and 0 < back <= len(self._priors) \
                and np.isfinite(self._priors[-back]).all():
            a, b, c, _, _ = self._mats
            self._kf.x = self._priors[-back].copy()
            for i in range(-back, 0):
                self._priors[i] = self._kf.x.copy()
                u, y = self._history[i][:2]
                self._kf.update(a, b, c, self._q, self._r, self._filter_input(u), y)
        if self._events and self._events[-1].sample >= since and self.refit_start is not None:
            self._record, self.refit_start = [], None
            self._events[-1] = replace(self._events[-1], confirmed=False)
            self.n_alarms_unconfirmed += 1
        if self._kf is not None:
            self._watch()

    def _adopt(self) -> None:
        corrections, self._corrections = self._corrections, []
        super()._adopt()
        if self.fit_log[-1]["outcome"] == "adopted":
            for args in corrections:      # made after the fit's fork: its state lacks them
                self.correct_outputs(*args)
