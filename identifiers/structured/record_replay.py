"""The replay of the kept record after a rebuild of
:class:`~identifiers.structured.rigid_flexible.RigidFlexibleIdentifier`.

When the modes change, the estimator is rebuilt on them and learns the
kept record again. :class:`RecordReplay` does that replay in batch where
the order of operations allows it: the record's head (the gains, the
error and signal levels, the modal tracker's moments) in one pass, and the
tail, over which the Kalman filter also runs, in stretches between the
model exports. The results are those of feeding every sample through
:meth:`~identifiers.structured.rigid_flexible.RigidFlexibleIdentifier._sample`
in turn, bit for bit (tests).
"""

from __future__ import annotations

import numpy as np

__all__ = ["RecordReplay"]


class RecordReplay:
    """Mixin of :class:`~identifiers.structured.modal_regression.ModalRegression`: the
    replay of the kept record, in batch.

    The host provides ``_fits`` (sensor rows, regressor columns and RLS per
    group), ``_tracker``, ``_track_levels``, ``_sample``, ``_filter_step``,
    ``_export``, ``_mats``, ``_last_innovation``, ``refresh`` and the noise
    levels ``_r``, ``_resvar`` and ``_noise_gain``.
    """

    def _replay_learning(self, phis: np.ndarray, y_fs: np.ndarray, use: np.ndarray,
                         sensitivities: tuple[np.ndarray, np.ndarray] | None) -> None:
        """What :meth:`_sample` does with replayed samples before the filter's tail (the
        gains' regressions, the error and signal levels, the modal tracker's moments),
        in batch: each group's RLS runs its rows in one compiled loop, a row reaching a
        group only if every group before it accepted it, as in :meth:`_learn`; the
        results are those of the sample-by-sample replay, bit for bit (test)."""
        ok = use.copy()
        errs = np.empty((len(use), self.n_outputs))
        for rows, cols, rls in self._fits:
            errs[:, rows], accepted = rls.update_many(phis[:, cols], y_fs[:, rows], use=ok)
            ok &= accepted
        for j in np.flatnonzero(ok):
            self._track_levels(errs[j], y_fs[j])
        if ok.any() and self._last_innovation is None:          # before the filter runs
            self._r = np.maximum(self._resvar / self._noise_gain, 1e-12)
        if self._tracker is not None and sensitivities is not None:
            for j in np.flatnonzero(use):
                self._tracker.update(phis[j], sensitivities[0][j], sensitivities[1][j],
                                     y_fs[j])

    def _replay_tail(self, samples: list[tuple], first: int, start_k: int, phis: np.ndarray,
                     y_fs: np.ndarray, use: np.ndarray,
                     sensitivities: tuple[np.ndarray, np.ndarray] | None) -> None:
        """The replay's tail, ``samples[first:]`` (sample ``j`` at time ``start_k + j``),
        where the Kalman filter runs and the model is exported every ``refresh`` samples.

        Until the filter has a model and a first innovation, the samples go through
        :meth:`_sample` one by one (the sensor noise the filter assumes comes from the
        regressions' errors until then). From there on the filter reads nothing the
        learning writes but the exported model, so each stretch up to the next export
        runs the filter sample by sample on the model it holds, then the learning in
        batch (:meth:`_replay_learning`), then the export: the same operations on the
        same numbers as :meth:`_sample` on each sample in turn.
        """
        j, end = first, len(samples)
        while j < end:
            if self._mats is None or self._last_innovation is None:
                u, y, learn, real = samples[j]
                sensitivity = None if sensitivities is None else (sensitivities[0][j],
                                                                  sensitivities[1][j])
                self._sample(u, y, learn, real, replay_k=start_k + j, filtering=True,
                             signals=(phis[j], y_fs[j], sensitivity))
                j += 1
                continue
            stop = min(end, j + ((-(start_k + j)) % self.refresh or self.refresh))
            for u, y, _, real in samples[j:stop]:
                self._filter_step(u, y, real, None)
            self._replay_learning(phis[j:stop], y_fs[j:stop], use[j:stop],
                                  None if sensitivities is None else
                                  (sensitivities[0][j:stop], sensitivities[1][j:stop]))
            if (start_k + stop) % self.refresh == 0:
                self._export()
            j = stop
