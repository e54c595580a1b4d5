"""What :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier` gives:
the minimal innovation-form model and the estimates behind it.

:class:`MinimalModelExport` turns the current gains into the exported model
(order ``n``, state ``[psi (3); omega (3); one complex mode per resonator
rank as 2 real states]``; each resonator's couplings factored into input
and output vectors by a complex SVD, the input vectors' phase aligned from
one export to the next so the state keeps its meaning) and reports the
rigid-body gain with its calibrated covariance, the tracked modes and the
detected changes.
"""

from __future__ import annotations

import numpy as np

from identifiers.core.change_detection import ChangeEvent
from identifiers.core.checks import all_finite
from identifiers.core.rigid_gain import RigidGainEstimate
from identifiers.core.state_filter import ATTITUDE_STATES, RATE_STATES

__all__ = ["MinimalModelExport"]


class MinimalModelExport:
    """Mixin of :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier`:
    the exported model, its state and the estimates it reports."""

    # ------------------------------------------------------------ the model
    def _export(self) -> None:
        """Minimal innovation-form model from the current gains (normalized units)."""
        bank = self._bank
        m = self.n_outputs
        theta = self._theta() / self._scale
        # the rigid body's blocks: kinematics (fixed) and the estimated inverse inertia
        a, c = (x.copy() for x in self._rigid_blocks())
        b = np.zeros((self.n, 3))
        g = theta[self._rate_rows, bank.slices["rate"]]       # normalized inverse inertia
        dt, ratio = self.dt, self._ratio
        b[ATTITUDE_STATES] = 0.5 * dt * dt * ratio * g
        b[RATE_STATES] = dt * g
        n_res = len(self.resonators)
        if n_res:
            # every resonator at once: its complex mode, and the SVD of its couplings
            # factored through that mode
            mus, to_complex = self._complex_modes()
            flexible = theta[:, bank.slices["flexible"]].reshape(m, n_res, 3, 2)
            chats = 2.0 * np.einsum("imas,is->ima", flexible.transpose(1, 0, 2, 3),
                                    to_complex)                                 # (M, m, 3)
            lefts, svs, rights = np.linalg.svd(chats, full_matrices=False)
            # one exported mode per (resonator, rank): its singular triple, as complex
            # output and input vectors
            res, rank = self._export_modes()
            c_vecs = lefts[res, :, rank] * svs[res, rank][:, None]             # (R, m)
            b_vecs = rights[res, rank]                                          # (R, 3)
            b_vecs, c_vecs = self._align_phases(res, rank, b_vecs, c_vecs)
            # mode r is the real 2x2 block of mu at states 6 + 2 r and 6 + 2 r + 1
            re = np.arange(6, 6 + 2 * res.size, 2)
            mu = mus[res]
            a[re, re] = a[re + 1, re + 1] = mu.real
            a[re, re + 1] = -mu.imag
            a[re + 1, re] = mu.imag
            b[re], b[re + 1] = b_vecs.real, b_vecs.imag
            c[:, re], c[:, re + 1] = c_vecs.real.T, -c_vecs.imag.T
        if not (all_finite(a) and all_finite(b) and all_finite(c)):
            return
        self._mats = (a, b, c, np.zeros((m, 3)), None)

    def _complex_modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Every resonator's complex mode ``mu`` (M,) and the map (M, 2) from its real
        states ``[q, q']`` to the mode's coordinate, scaled by the input's share of it.

        They change only when the resonators move (a refinement, a rebuild): kept
        until then."""
        bank = self._bank
        cached = self.__dict__.get("_complex_mode_cache")
        if cached is not None and cached[0] is bank and cached[1] is bank.resonators:
            return cached[2]
        modes_a, modes_b = bank.mode_matrices
        every = np.arange(len(bank.resonators))
        vals, vecs = np.linalg.eig(modes_a)                                   # (M, 2)
        top = np.argmax(vals.imag, axis=1)
        mus = vals[every, top]
        shares = np.linalg.solve(vecs, modes_b[:, :, None])[:, :, 0]           # (M, 2)
        to_complex = vecs[every, :, top] * shares[every, top][:, None]          # (M, 2)
        self.__dict__["_complex_mode_cache"] = (bank, bank.resonators, (mus, to_complex))
        return mus, to_complex

    def _align_phases(self, res: np.ndarray, rank: np.ndarray, b_vecs: np.ndarray,
                      c_vecs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fix the free phase of every exported mode's singular pair.

        The input vector ``b`` of each mode is rotated to agree in phase with
        its last export (its largest entry made real at the first), and the
        output vector ``c`` by the opposite phase, so the product is unchanged
        and the state keeps its meaning from one export to the next.

        Returns
        -------
        b_vecs, c_vecs : ndarray
            The rotated vectors; the new references are recorded.
        """
        phases = np.ones(res.size, dtype=complex)
        for j, key in enumerate(zip(res.tolist(), rank.tolist(), strict=True)):
            b_vec = b_vecs[j]
            ref = self._phases.get(key)
            phase = b_vec[np.argmax(np.abs(b_vec))] if ref is None else np.vdot(ref, b_vec)
            if abs(phase) > 0:
                phases[j] = phase / abs(phase)
        b_vecs = b_vecs / phases[:, None]
        c_vecs = c_vecs * phases[:, None]
        self._phases.update(zip(zip(res.tolist(), rank.tolist(), strict=True), b_vecs,
                                strict=True))
        return b_vecs, c_vecs

    def _rigid_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """The fixed part of the exported ``A`` and ``C`` (kinematics, sensor selection):
        attitude integrates rate, both are measured; the modal blocks are left 0."""
        key = (self.n, self.n_outputs, self.dt, self._ratio)
        cached = self.__dict__.get("_rigid_block_cache")
        if cached is not None and cached[0] == key:
            return cached[1]
        psi, omega = ATTITUDE_STATES, RATE_STATES
        a = np.zeros((self.n, self.n))
        c = np.zeros((self.n_outputs, self.n))
        a[psi, psi] = np.eye(3)
        a[psi, omega] = self.dt * self._ratio * np.eye(3)
        a[omega, omega] = np.eye(3)
        c[self._att_rows, psi] = np.eye(3)
        c[self._rate_rows, omega] = np.eye(3)
        self.__dict__["_rigid_block_cache"] = (key, (a, c))
        return a, c

    def _export_modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Resonator and rank of every exported mode, in state order."""
        ranks = [r.rank for r in self.resonators]
        cached = self.__dict__.get("_export_mode_cache")
        if cached is not None and cached[0] == ranks:
            return cached[1]
        res = np.repeat(np.arange(len(ranks)), ranks)
        rank = np.concatenate([np.arange(r) for r in ranks]) if ranks else res
        self.__dict__["_export_mode_cache"] = (ranks, (res, rank))
        return res, rank

    def input_uncertainty(self) -> np.ndarray | None:
        """Covariance (3, 3) of the rigid gains' torque directions, from the rate
        regression's RLS (larger = less known), for shaping an excitation;
        None before warm-up.

        Returns
        -------
        (3, 3) ndarray or None
            The covariance, in the regression's normalized units; None before warm-up.
        """
        if not self._fits:
            return None
        bank = self._bank
        rate_cols = np.arange(bank.size)[bank.slices["rate"]]
        for rows, cols, rls in self._fits:
            if rows[0] == self.layout.slice("rate").start:
                where = np.flatnonzero(np.isin(cols, rate_cols))
                scale = self._scale[rate_cols]
                return rls.P[np.ix_(where, where)] / np.outer(scale, scale)
        return None

    @property
    def rigid_gain(self) -> RigidGainEstimate | None:
        """The rigid-body gain ``G = J^-1`` (rad/s^2 per N m) with its calibrated
        covariance (:class:`identifiers.core.rigid_gain.RigidGainEstimate`), from the rate
        regression; None before warm-up."""
        if not self._fits or self._resvar is None:
            return None
        bank = self._bank
        rate = self.layout.slice("rate")
        rate_cols = np.arange(bank.size)[bank.slices["rate"]]
        for rows, cols, rls in self._fits:
            if rows[0] != rate.start:
                continue
            where = np.searchsorted(cols, rate_cols) if np.all(np.diff(cols) > 0) else \
                np.array([int(np.flatnonzero(cols == c)[0]) for c in rate_cols])
            theta = rls.theta[:, where]
            p = rls.P[np.ix_(where, where)]
            return RigidGainEstimate.from_regression(
                theta, p, self._resvar[rate], self._sy[rate],
                self._scale[rate_cols] * self._su)
        return None

    @property
    def mode_estimates(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The tracked resonators: frequencies (Hz), damping ratios and the covariance
        of ``[log f_1, zeta_1, ..., log f_M, zeta_M]`` from the last refinement (None
        before one or without tracking)."""
        freq = np.array([r.frequency_hz for r in self.resonators])
        zeta = np.array([r.damping for r in self.resonators])
        cov = None if self._tracker is None else self._tracker.covariance
        return freq, zeta, cov

    @property
    def events(self) -> list[ChangeEvent]:
        """Changes detected so far (empty before warm-up)."""
        return [] if self._detector is None else list(self._detector.events)
