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

A search's modes are a candidate, not a verdict (:meth:`RecordReplay._try_modes`):
the rebuild on them is kept only if its model predicts the last
:data:`SEARCH_WINDOW` samples :data:`SEARCH_HORIZON` ahead better than the
model in use. A search over a record in which the modes moved (turning
paddles) can find fewer or averaged modes, which the tracker has already
left behind.
"""

from __future__ import annotations

import numpy as np

from identifiers.core.kalman import KalmanPredictor

__all__ = ["SEARCH_HORIZON", "SEARCH_WINDOW", "RecordReplay"]

#: Samples at the end of the record (50 s at dt = 0.1 s) on which a search's
#: modes and the modes in use are compared.
SEARCH_WINDOW = 500
#: Prediction horizon of that comparison, samples (10 s at dt = 0.1 s), and the
#: spacing of its starting points.
SEARCH_HORIZON = 100
_SEARCH_SPACING = 10
#: Samples the comparison's Kalman filter runs before the window, to settle.
_SEARCH_SETTLE = 300


def horizon_error(mats: tuple[np.ndarray, ...], process_noise: np.ndarray,
                  noise: np.ndarray, u: np.ndarray, y: np.ndarray, first: int,
                  horizon: int = SEARCH_HORIZON, spacing: int = _SEARCH_SPACING) -> float:
    """Mean squared ``horizon``-step prediction error of a model on a record.

    A Kalman filter on the model (``A, B, C, D``; process and sensor noise
    covariances ``process_noise`` and ``diag(noise)``) runs over ``u, y`` from
    zero; from every ``spacing``-th sample from ``first`` on, its state is
    propagated ``horizon`` steps on the inputs alone and compared with ``y``.
    Each output's squared error is divided by its variance over the predicted
    samples (the sum is ``m (1 - VAF)`` for a model that is as good on every
    output).

    Parameters
    ----------
    u : (N, 3) ndarray
    y : (N, m) ndarray
    first : int
        First starting point; starting points stop ``horizon`` before the end.

    Returns
    -------
    float
        The mean over starting points of the weighted squared error (inf if the
        predictions are not finite or there is no starting point).
    """
    a, b, c, d = mats[:4]
    kf = KalmanPredictor(a.shape[0], initial_covariance=1.0)
    starts, states = [], []
    for k in range(len(u) - horizon):
        if k >= first and (k - first) % spacing == 0:
            starts.append(k)
            states.append(kf.x.copy())
        kf.update(a, b, c, process_noise, noise, u[k], y[k])
    if not starts:
        return np.inf
    x = np.array(states).T                              # (n, starts)
    starts = np.array(starts)
    for h in range(horizon):
        x = a @ x + b @ u[starts + h].T
    predicted = c @ x + d @ u[starts + horizon].T
    actual = y[starts + horizon].T
    variance = np.var(actual, axis=1)
    with np.errstate(invalid="ignore", over="ignore"):
        error = ((predicted - actual) ** 2).sum(axis=1) / np.where(variance > 0, variance, 1.0)
    total = float(error.sum() / len(starts))
    return total if np.isfinite(total) else np.inf


class RecordReplay:
    """Mixin of :class:`~identifiers.structured.modal_regression.ModalRegression`: the
    replay of the kept record, in batch.

    The host provides ``_fits`` (sensor rows, regressor columns and RLS per
    group), ``_tracker``, ``_track_levels``, ``_sample``, ``_filter_step``,
    ``_export``, ``_mats``, ``_last_innovation``, ``refresh`` and the noise
    levels ``_r``, ``_resvar`` and ``_noise_gain``; for :meth:`_try_modes` also
    ``_history``, ``_rebuild``, ``_process_noise``, ``_snapshot`` and ``_restored``.
    """

    def _try_modes(self, found: list, replay: int) -> bool:
        """Rebuild on ``found`` and replay the last ``replay`` samples; keep the rebuild
        if its model predicts the last :data:`SEARCH_WINDOW` samples
        :data:`SEARCH_HORIZON` ahead better (:func:`horizon_error`) than the model in
        use, else return to the state before the rebuild. Returns whether the
        rebuild was kept."""
        samples = list(self._history)[-(SEARCH_WINDOW + _SEARCH_SETTLE):]
        u = np.array([s[0] for s in samples])
        y = np.array([s[1] for s in samples])
        first = max(0, len(samples) - SEARCH_WINDOW)
        before = self._snapshot()
        in_use = horizon_error(self._mats, self._process_noise(), self._r, u, y, first)
        self._rebuild(found, replay)
        if self._mats is not None and horizon_error(self._mats, self._process_noise(),
                                                    self._r, u, y, first) < in_use:
            return True
        vars(self).update(self._restored(before))
        return False

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
