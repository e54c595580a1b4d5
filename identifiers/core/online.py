"""The streaming API every online identifier shares: ``update(u, y)`` one sample at a time.

:class:`OnlineIdentifier` is the algorithm-free part of every method: sizes
inferred from the first sample, scales, the past window
``phi = [z_{k-1}; ...; z_{k-p}]``, warm-up, ``fit`` and ``reset``, and the
model and state it exports. It is composed of two parts in their own
modules: :class:`identifiers.core.screening.SampleScreening` (what may be
learned from: validation, NaN/inf, the outlier guard, re-scaling) and
:class:`identifiers.core.rollback.HealthGuard` (the estimator's own state:
health checks, rollback, restart). A method fills in the hooks
``_allocate``, ``_step``, ``_matrices`` and ``_current_state``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.checks import (
    forgetting_factor,
    positive_float,
    positive_int,
    positive_scales,
    rms_scale,
)
from identifiers.core.data_monitor import DataMonitor
from identifiers.core.health import degenerate
from identifiers.core.model import StateSpaceModel
from identifiers.core.model_sequence import ModelSequence
from identifiers.core.rollback import HealthGuard
from identifiers.core.screening import SampleScreening
from spacecraft_conventions import KeptWhileEqual, single_threaded_blas

__all__ = ["OnlineIdentifier"]


class OnlineIdentifier(SampleScreening, HealthGuard, ABC):
    """Base class of the streaming identifiers: ``update(u, y)`` one sample at a time.

    Parameters
    ----------
    n : int
        Model order.
    p : int
        Past window (VARX lags); ``p * m >= n`` is required.
    forgetting : float
        Forgetting factor in (0, 1].
    dt : float
        Sample time (s) stamped on the models.
    warmup : int, optional
        Samples before ``model`` is available; default ``4 p``.
    input_scale, output_scale : array_like, optional
        Per-channel scales (RMS levels) of u and y. Every estimator runs on
        ``u / input_scale`` and ``y / output_scale`` so that its constants
        (initial covariances, bounds) mean the same whatever the units;
        models are returned in physical units and the state in the internal
        coordinates that ``model`` uses. Default: the RMS of the first ``p``
        samples (a period in which nothing is learned anyway), 1 where that
        is zero.
    max_abs : float
        Largest normalized magnitude a sample may have (default 1e6: a
        million nominal levels, far beyond any physical signal); larger
        entries are treated as corrupt and the sample is skipped.

    Attributes
    ----------
    n_samples : int
        Samples received (including skipped ones).
    n_skipped : int
        Samples that were skipped: NaN/inf, beyond ``max_abs``, or rejected
        as outliers (see :meth:`update`).
    n_outliers : int
        Of those, the ones rejected by the outlier guard.
    n_idle : int
        Samples passed over because they carried no information at all: zero
        input and an output equal bit for bit to the previous one (a plant at
        rest, or a frozen sensor). They move no estimate and no clock.
    n_rollbacks, n_restarts : int
        Faults of the internal state repaired by a rollback, or by a restart
        of the estimator (see :attr:`health`).
    n_inputs, n_outputs : int or None
        r and m, inferred from the first sample.
    """

    #: Whether successive models share state coordinates.
    consistent_basis = True
    #: Attributes that describe the recent signals rather than what was learnt
    #: (past windows, filter states driven by the data): a rollback keeps their
    #: current values, so they stay aligned with the samples still to come.
    _SIGNAL_STATE: ClassVar[tuple[str, ...]] = ("_phi",)
    #: Attributes whose items are never changed in place (lists of sample
    #: tuples): the rollback copy shares their items instead of copying them.
    #: Each must be referenced only from its own attribute (see
    #: :meth:`identifiers.core.rollback.HealthGuard._snapshot`).
    _SHARED_ITEMS: ClassVar[tuple[str, ...]] = ("_pending",)

    def __init__(self, n: int, p: int = 15, forgetting: float = 0.98, *, dt: float = 0.1,
                 warmup: int | None = None, input_scale: ArrayLike | None = None,
                 output_scale: ArrayLike | None = None, max_abs: float = 1e6) -> None:
        self.n = positive_int("n", n)
        self.p = positive_int("p", p)
        self.forgetting = forgetting_factor("forgetting", forgetting)
        self.dt = float(dt)
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive finite number of seconds, got {dt}")
        self.max_abs = positive_float("max_abs", max_abs)
        self.warmup = 4 * self.p if warmup is None else positive_int("warmup", warmup)
        if self.warmup < self.p:
            raise ValueError(f"warmup must be >= p = {self.p}, got {self.warmup}")
        self._user_scales = (
            None if input_scale is None else positive_scales("input_scale", input_scale),
            None if output_scale is None else positive_scales("output_scale", output_scale))
        self.reset()

    # ------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        """Forget everything, including the input and output sizes."""
        self.n_inputs: int | None = None
        self.n_outputs: int | None = None
        self.n_samples = 0
        self.n_skipped = 0
        self.n_outliers = 0
        self._k = 0            # samples processed by the estimator
        self._quiet = 0
        self._outlier_run = 0
        self._skip_run = 0
        self._last_y: np.ndarray | None = None
        self.n_idle = 0
        self._phi = None
        self._su = self._sy = None
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        self._monitor: DataMonitor | None = None
        self._range_skips = 0
        #: the model last exported, kept while its matrices and scales keep their bits
        self._exported: KeptWhileEqual[StateSpaceModel | None] = KeptWhileEqual()
        self._reset_health()

    def restart(self) -> None:
        """Begin a new record of the same plant family (a new episode), keeping what was learnt.

        The next sample does not follow the last one in time: an episode
        reset, a data gap. An identifier that can carry its estimates over
        keeps them and restarts only what describes the old record's signals
        (past windows, filter states, the state estimate).
        :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier` does;
        this default forgets everything (:meth:`reset`), because the
        past-window methods also keep data windows and bases built from the
        old record.
        """
        self.reset()

    def _check_sizes(self, r: int, m: int) -> None:
        """Reject sizes the method cannot identify an order-n model from (the
        past-window methods need ``p m >= n``)."""
        if self.p * m < self.n:
            raise ValueError(f"p * m = {self.p * m} must be >= n = {self.n} "
                             f"(m = {m} outputs); increase p")

    def _init_sizes(self, r: int, m: int) -> None:
        self._check_sizes(r, m)
        su, sy = self._user_scales
        if su is not None and su.shape != (r,):
            raise ValueError(f"input_scale must have shape ({r},), got {su.shape}")
        if sy is not None and sy.shape != (m,):
            raise ValueError(f"output_scale must have shape ({m},), got {sy.shape}")
        self.n_inputs, self.n_outputs = r, m
        self._zr = r + m
        self._phi = np.zeros(self.p * self._zr)
        self._monitor = DataMonitor(r, m, self._memory(), self._output_names(m))
        self._allocate(r, m)

    def _memory(self) -> float:
        """The estimator's memory in samples, ``1 / (1 - forgetting)`` (inf without
        forgetting): an input constant for longer is reported ``unexcited``."""
        return np.inf if self.forgetting >= 1.0 else 1.0 / (1.0 - self.forgetting)

    def _output_names(self, m: int) -> tuple[str, ...]:
        """A label per output for the health messages (default ``y[i]``)."""
        return tuple(f"y[{i}]" for i in range(m))

    @abstractmethod
    def _allocate(self, r: int, m: int) -> None:
        """Create the estimator state once r and m are known."""

    @abstractmethod
    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        """Process one sample; must call :meth:`_push` once."""

    @abstractmethod
    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        """Current ``(A, B, C, D, K)`` or None."""

    @abstractmethod
    def _current_state(self) -> np.ndarray | None:
        """State estimate for the next sample time, x_{k+1|k}."""

    def _fill_output(self) -> np.ndarray:
        """Stand-in for a missing output sample (default zeros)."""
        return np.zeros(self.n_outputs)

    # ------------------------------------------------------------ streaming
    def _push(self, u: np.ndarray, y: np.ndarray) -> None:
        """Shift ``z_k = [u_k; y_k]`` into the past window (newest first)."""
        phi = self._phi
        zr = self._zr
        phi[zr:] = phi[:-zr]
        phi[:self.n_inputs] = u
        phi[self.n_inputs:zr] = y

    @single_threaded_blas
    def update(self, u: ArrayLike, y: ArrayLike) -> None:
        """Process one sample ``(u_k, y_k)``.

        BLAS runs single-threaded during the call (the library's small
        per-sample products are fastest and bit-reproducible that way; see
        :mod:`spacecraft_conventions.blas`), whatever the caller's setting.

        A sample that cannot be learned from is skipped and counted in
        ``n_skipped``: one with NaN or inf, or with a normalized magnitude
        beyond ``max_abs`` (a corrupt reading: a million nominal levels), or
        (if ``outlier_threshold`` is set) an outlier of the one-step
        prediction error. Its unusable entries are replaced (inputs by 0,
        outputs by their prediction) to keep the past window aligned in
        time; the sample itself is not learned from. A single stand-in is off
        by about the noise, so learning goes on; after two or more in a row
        it pauses until they have left the window. ``update`` never raises on
        such data (nor on any finite or non-finite data of the right shape).

        Raises
        ------
        ValueError
            Wrong shape, or a size different from the first sample's.
        TypeError
            Non-numeric data.
        """
        u, y = self._validate(u, y)
        self.n_samples += 1
        if self._su is None:
            su, sy = self._user_scales
            if su is not None and sy is not None:
                self._su, self._sy = su, sy
            else:
                self._pending.append((u.copy(), y.copy()))
                if len(self._pending) < self.p:
                    return
                pending_u = np.array([pu for pu, _ in self._pending])
                pending_y = np.array([py for _, py in self._pending])
                self._su = su if su is not None else rms_scale(pending_u)
                self._sy = sy if sy is not None else rms_scale(pending_y)
                for pu, py in self._pending:
                    self._process(pu, py)
                self._pending = []
                return
        self._process(u, y)

    def _physical(self, mats: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """Matrices of the normalized model in physical units (state unchanged)."""
        a, b, c, d, k = mats
        su, sy = self._su, self._sy
        return a, b / su, sy[:, None] * c, sy[:, None] * d / su, k / sy

    def fit(self, U: ArrayLike, Y: ArrayLike) -> ModelSequence:
        """Feed a whole record sample by sample; return the model after each.

        Parameters
        ----------
        U : (N, r) array_like
        Y : (N, m) array_like

        Returns
        -------
        ModelSequence
            Entry k is the model after sample k (None while warming up),
            with the state estimate ``x_{k+1|k}`` in ``states``; identical to
            calling :meth:`update` in a loop.
        """
        u = np.asarray(U, dtype=float)
        y = np.asarray(Y, dtype=float)
        if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
            raise ValueError(f"U and Y must have shapes (N, r) and (N, m), got {u.shape} and "
                             f"{y.shape}")
        with single_threaded_blas:       # one entry for the loop; updates nest cheaply
            return self._fit(u, y)

    def _fit(self, u: np.ndarray, y: np.ndarray) -> ModelSequence:
        N = u.shape[0]
        mats: list[np.ndarray] = []
        states = np.empty((N, 0))
        valid = np.zeros(N, dtype=bool)
        for k in range(N):
            self.update(u[k], y[k])
            if self.ready and self._exportable():
                # as quiet as update: a broken state is the health checks' to find
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    cur = self._matrices()
                    x = self._current_state()
                if cur is not None and x is not None and not degenerate(cur):
                    if not mats:       # the model order is known once there is a model
                        mats = [np.full((N, *mat.shape), np.nan) for mat in cur]
                        states = np.full((N, x.shape[0]), np.nan)
                    valid[k] = True
                    states[k] = x
                    for arr, mat in zip(mats, self._physical(cur), strict=True):
                        arr[k] = mat
        if not mats:
            n, r, m = self.n, u.shape[1], y.shape[1]
            mats = [np.full((N, *shape), np.nan)
                    for shape in ((n, n), (n, r), (m, n), (m, r), (n, m))]
            states = np.full((N, n), np.nan)
        return ModelSequence(*mats, valid, self.dt, self.consistent_basis, states=states)

    # ------------------------------------------------------------ results
    @property
    def ready(self) -> bool:
        """True once warmed up."""
        return self.n_samples >= self.warmup and self._su is not None

    @property
    def model(self) -> StateSpaceModel | None:
        """Current identified model, or None until warmed up (and, with an
        :class:`identifiers.core.health.IdentifierHealthWarning`, while the
        estimator is restarting after a fault: see :attr:`health`)."""
        if not self._exportable():
            return None
        if not self.ready:
            return None
        mats = self._matrices()
        if mats is None:
            return None
        # the same (read-only) model object while the matrices and scales keep their
        # bits: an identifier that holds its model between exports is read every step
        return self._exported.get(
            (*mats, self._su, self._sy, self.dt),
            lambda: None if degenerate(mats) else StateSpaceModel(*self._physical(mats),
                                                                  dt=self.dt))

    @property
    def state(self) -> np.ndarray | None:
        """State estimate for the next sample, x_{k+1|k}, in the model's coordinates."""
        if not self.ready:
            return None
        x = self._current_state()
        return None if x is None else x.copy()

    @property
    def rigid_states(self) -> tuple[slice, slice] | None:
        """Slices of the model state that are the attitude and the body rate, if
        the identifier's state has that physical layout (default None: a
        subspace method's state is in coordinates of its own)."""
        return None

    def filtered_state(self, y: ArrayLike) -> np.ndarray | None:
        """State estimate at the current sample given its measurement, ``x_{k|k}``.

        :attr:`state` is the prediction ``x_{k|k-1}`` made before ``y_k`` was
        seen; a controller that acts on ``y_k`` before passing it to
        :meth:`update` uses this instead. Identifiers with a Kalman filter
        correct the prediction with ``y_k`` (non-finite entries ignored);
        the default returns the prediction. The identifier is not changed.

        Returns
        -------
        (n,) ndarray or None
            ``x_{k|k}`` in the model's coordinates; None before the identifier has a
            model.
        """
        return self.state

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n={self.n}, p={self.p}, forgetting={self.forgetting}, "
                f"samples={self.n_samples}, skipped={self.n_skipped})")
