"""The replay of the kept record after a rebuild of
:class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier`.

When the modes change, the estimator is rebuilt on them and learns the
kept record again. :class:`RecordReplay` does that replay in batch where
the order of operations allows it: the record's head (the gains, the
error and signal levels, the modal tracker's moments) in one pass, and the
tail, over which the Kalman filter also runs, in stretches between the
model exports. The results are those of feeding every sample through
:meth:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier._sample`
in turn, bit for bit (tests).

A search's modes are a candidate, not a verdict (:meth:`RecordReplay._try_modes`):
the rebuild on them is undone if its model predicts the last
:data:`SEARCH_WINDOW` samples :data:`SEARCH_HORIZON` ahead clearly worse than
the model in use (beyond the spread of the difference: the search has seen
more data than the window, so the benefit of the doubt is its). A search
over a record in which the modes moved (turning paddles) can find fewer or
averaged modes, which the tracker has already left behind.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SEARCH_HORIZON", "SEARCH_WINDOW", "RecordReplay", "clearly_worse", "horizon_errors"]

#: Samples at the end of the record (50 s at dt = 0.1 s) on which a search's
#: modes and the modes in use are compared.
SEARCH_WINDOW = 500
#: Prediction horizon of that comparison, samples (10 s at dt = 0.1 s), and the
#: spacing of its starting points.
SEARCH_HORIZON = 100
_SEARCH_SPACING = 10
#: Samples the comparison's predictors run before the window, to settle.
_SEARCH_SETTLE = 300


def horizon_errors(mats: tuple[np.ndarray, ...], u: np.ndarray, y: np.ndarray, first: int,
                   horizon: int = SEARCH_HORIZON, spacing: int = _SEARCH_SPACING) -> np.ndarray:
    """Squared ``horizon``-step prediction errors of a model in innovation form.

    The model's predictor (``x_{k+1} = A x_k + B u_k + K (y_k - C x_k - D u_k)``
    from ``x_0 = 0``) runs over ``u, y``; from every ``spacing``-th sample from
    ``first`` on, its state is propagated ``horizon`` steps on the inputs alone
    and compared with ``y``. Each output's squared error is divided by that
    output's variance over the predicted samples and summed over the outputs
    (``m (1 - VAF)`` on average for a model that is as good on every output).

    Parameters
    ----------
    mats : tuple of ndarray
        ``(A, B, C, D, K)``: ``(n, n)``, ``(n, r)``, ``(m, n)``, ``(m, r)``, ``(n, m)``.
    u : (N, r) ndarray
    y : (N, m) ndarray
    first : int
        First starting point; starting points stop ``horizon`` before the end.
    horizon, spacing : int
        Prediction horizon and spacing of the starting points, samples.

    Returns
    -------
    (S,) ndarray
        The weighted squared error from each starting point (inf where the
        prediction is not finite; empty if there is no starting point).
    """
    a, b, c, d, k_gain = mats
    starts = np.arange(first, len(u) - horizon, spacing)
    if starts.size == 0:
        return np.zeros(0)
    a_closed, drive = a - k_gain @ c, u @ (b - k_gain @ d).T + y @ k_gain.T
    x, states = np.zeros(a.shape[0]), np.empty((starts[-1] + 1, a.shape[0]))
    with np.errstate(invalid="ignore", over="ignore"):
        for k in range(starts[-1] + 1):
            states[k] = x
            x = a_closed @ x + drive[k]
        x = states[starts].T                                # (n, starts)
        for h in range(horizon):
            x = a @ x + b @ u[starts + h].T
        predicted = c @ x + d @ u[starts + horizon].T
        actual = y[starts + horizon].T
        variance = np.var(actual, axis=1)
        error = ((predicted - actual) ** 2 / np.where(variance > 0, variance, 1.0)[:, None]
                 ).sum(axis=0)
    return np.where(np.isfinite(error), error, np.inf)


def clearly_worse(candidate: np.ndarray, in_use: np.ndarray,
                  block: int = SEARCH_HORIZON // _SEARCH_SPACING,
                  no_skill: float = np.inf) -> bool:
    """Whether the errors ``candidate`` exceed ``in_use`` (paired, per starting point)
    beyond their spread.

    The paired differences are averaged over consecutive blocks of ``block``
    starting points (one horizon: predictions of different blocks do not
    overlap); the candidate is worse if the mean of the block means exceeds
    twice its standard error (with fewer than two blocks: if its mean is
    larger). A candidate that is not finite where the model in use is, is
    worse; none is worse than a model in use that is finite nowhere or whose
    mean error is at least ``no_skill`` (that of predicting each output by its
    mean: the number of outputs for :func:`horizon_errors`): such a model has
    no prediction to defend.

    Returns
    -------
    bool
        True when the candidate's errors are larger beyond their spread.
    """
    finite = np.isfinite(in_use)
    if not finite.any() or np.mean(in_use[finite]) >= no_skill:
        return False
    if not np.isfinite(candidate[finite]).all():
        return True
    diff = np.where(finite, candidate, 0.0) - np.where(finite, in_use, 0.0)
    n_blocks = len(diff) // block
    if n_blocks < 2:
        return bool(diff.mean() > 0.0)
    means = diff[:n_blocks * block].reshape(n_blocks, block).mean(axis=1)
    return bool(means.mean() > 2.0 * means.std(ddof=1) / np.sqrt(n_blocks))


class RecordReplay:
    """Mixin of :class:`identifiers.modal.modal_regression.ModalRegression`: the
    replay of the kept record, in batch.

    The host provides ``_fits`` (sensor rows, regressor columns and RLS per
    group), ``_tracker``, ``_track_levels``, ``_sample``, ``_filter_step``,
    ``_export``, ``_mats``, ``_last_innovation``, ``refresh`` and the noise
    levels ``_r``, ``_resvar`` and ``_noise_gain``; for :meth:`_try_modes` also
    ``_history``, ``_rebuild``, ``_matrices``, ``_snapshot`` and ``_restored``.
    """

    def _try_modes(self, found: list, replay: int) -> bool:
        """Rebuild on ``found`` and replay the last ``replay`` samples; undo the rebuild
        (return to the state before it) if its model predicts the last
        :data:`SEARCH_WINDOW` samples :data:`SEARCH_HORIZON` ahead clearly worse
        (:func:`horizon_errors`, :func:`clearly_worse`) than the model in use, each
        model with its own predictor gain. Returns whether the rebuild was kept."""
        samples = list(self._history)[-(SEARCH_WINDOW + _SEARCH_SETTLE):]
        u = np.array([s[0] for s in samples])
        y = np.array([s[1] for s in samples])
        first = max(0, len(samples) - SEARCH_WINDOW)
        before = self._snapshot()
        in_use = horizon_errors(self._matrices(), u, y, first)
        self._rebuild(found, replay)
        if self._mats is not None and not clearly_worse(
                horizon_errors(self._matrices(), u, y, first), in_use,
                no_skill=self.n_outputs):
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
