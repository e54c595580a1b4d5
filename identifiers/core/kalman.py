"""Kalman filtering on a (possibly changing) linear model.

:class:`KalmanPredictor` is a time-varying Kalman filter in predictor form
for ``x_{k+1} = A x_k + B u_k + w_k``, ``y_k = C x_k + v_k`` with
``w ~ N(0, Q)``, ``v ~ N(0, R)``. Each :meth:`KalmanPredictor.update`
takes the model of that step, so the filter follows a model that an
identifier refines every sample; its covariance adapts with it (no
steady-state gain to recompute when the model moves). The predictor gain
``K_k = A P C^T (C P C^T + R)^-1`` turns the filter into the innovation form
that identified models carry.

:func:`steady_state_gain` solves the filtering Riccati equation once, for a
fixed model (the fixed LQG of the controllers).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import solve_discrete_are

from identifiers.core.checks import all_finite
from identifiers.core.kalman_kernels import (
    _correct_all,
    _f64,
    _full_update,
    _predict,
    _predict_correct,
    _within,
)
from spacecraft_conventions import KeptWhileEqual, single_threaded_blas

__all__ = ["STEADY_TOLERANCE", "KalmanPredictor", "steady_state_gain"]

#: Largest change of the prior covariance between two steps on the same model,
#: relative to its largest entry, at which :class:`KalmanPredictor` holds its
#: covariance and gain (the Riccati recursion has converged to rounding).
STEADY_TOLERANCE = 1e-10


@single_threaded_blas
def steady_state_gain(a: ArrayLike, c: ArrayLike, q: ArrayLike,
                      r: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state Kalman filter of ``(A, C)`` with noise covariances ``Q``, ``R``.

    Parameters
    ----------
    a : (n, n) array_like
        Discrete-time state matrix ``A``.
    c : (m, n) array_like
        Output matrix ``C``.
    q : (n, n) array_like
        Process (state) noise covariance ``Q``, in the state's units squared.
    r : (m, m) array_like
        Measurement noise covariance ``R``, in the outputs' units squared
        (positive definite); a scalar is taken as a 1 x 1 matrix.

    Returns
    -------
    L : (n, m) ndarray
        Filter (measurement-update) gain: ``x_{k|k} = x_{k|k-1} + L (y_k - C x_{k|k-1})``.
    P : (n, n) ndarray
        Prior (one-step-ahead) error covariance.

    Raises
    ------
    ValueError
        If the Riccati equation has no stabilizing solution.
    """
    a, c = np.asarray(a, dtype=float), np.asarray(c, dtype=float)
    q, r = np.atleast_2d(np.asarray(q, dtype=float)), np.atleast_2d(np.asarray(r, dtype=float))
    try:
        p = solve_discrete_are(a.T, c.T, q, r)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(f"no stabilizing filter Riccati solution: {exc}") from None
    return p @ c.T @ np.linalg.inv(c @ p @ c.T + r), p


#: Stands for "no transition matrix given" in :class:`_Steady`'s keys.
_NO_MATRIX = np.zeros((0, 0))


class _Steady:
    """A converged filter: its model's bits and the held covariances and gains."""

    def __init__(self) -> None:
        self.prediction: KeptWhileEqual[bool] = KeptWhileEqual()   # (A, B, Q)
        self.correction: KeptWhileEqual[bool] = KeptWhileEqual()   # (C, R, A or none)

    @classmethod
    def hold(cls, prior: np.ndarray, a: np.ndarray, b: np.ndarray, q: np.ndarray,
             c: np.ndarray, r: np.ndarray, a_gain: np.ndarray) -> _Steady:
        """The steady filter of the model, from its converged prior covariance."""
        st = cls()
        st.prediction.keep((a, b, q), True)
        st.correction.keep((c, r, a_gain), True)
        st.a, st.b, st.c = _f64(a).copy(), _f64(b).copy(), _f64(c).copy()
        st.prior = prior
        _, st.post, st.filter_gain, _, st.s, _ = _correct_all(
            np.zeros(prior.shape[0]), prior, st.c, _f64(r), np.zeros(st.c.shape[0]))
        st.gain = st.filter_gain if a_gain.size == 0 else a_gain @ st.filter_gain
        for held in (st.prior, st.post, st.filter_gain, st.s, st.gain):
            held.flags.writeable = False        # handed out every step: nobody may change them
        return st


class KalmanPredictor:
    """Time-varying Kalman filter in one-step predictor form.

    Parameters
    ----------
    n : int
        State dimension.
    initial_covariance : float
        ``P_0 = initial_covariance * I`` around the initial state 0.

    Attributes
    ----------
    x : (n,) ndarray
        ``x_{k+1|k}`` after the last update (``x_{0|-1} = 0`` initially).
    P : (n, n) ndarray
        Its error covariance.
    gain : (n, m) ndarray or None
        The last predictor gain ``K_k``.
    innovation, innovation_covariance : ndarray or None
        The last ``e_k = y_k - C x_{k|k-1}`` and ``S_k = C P C^T + R``.

    Notes
    -----
    :meth:`correct` then :meth:`predict` (or :meth:`advance`) on a model that
    holds still become a steady-state filter (:attr:`steady`): once two
    consecutive steps on the same model (``A, B, Q, C, R`` with the same bits,
    every output seen) left the prior covariance changed by at most :data:`STEADY_TOLERANCE` of
    its largest entry, the covariance and the gain are held and a step costs
    two matrix-vector products. A step on another model, a missing output,
    :meth:`inflate` or :meth:`transform` returns to the full recursion.
    """

    def __init__(self, n: int, initial_covariance: float = 1.0) -> None:
        self.n = int(n)
        self.initial_covariance = float(initial_covariance)
        self.reset()

    def reset(self) -> None:
        """Back to ``x = 0``, ``P = P_0``."""
        self.x = np.zeros(self.n)
        self.P = np.eye(self.n) * self.initial_covariance
        self.gain: np.ndarray | None = None
        self.innovation: np.ndarray | None = None
        self.innovation_covariance: np.ndarray | None = None
        self._steady: _Steady | None = None
        #: (C, R, A) of the last correction that saw every output, until the next prediction
        self._corrected: tuple[np.ndarray, ...] | None = None
        #: the prior covariance of the last full time update
        self._last_prior: np.ndarray | None = None
        #: the model of the last full step that left the prior settled
        self._last_step: KeptWhileEqual[bool] = KeptWhileEqual()

    @property
    def steady(self) -> bool:
        """Whether the covariance is held at its converged value (see Notes)."""
        st = self._steady
        return st is not None and (self.P is st.prior or self.P is st.post)

    def update(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, q: np.ndarray,
               r: np.ndarray, u: np.ndarray, y: np.ndarray | None) -> np.ndarray:
        """One step: measurement ``y_k`` (None or NaN entries: skipped), then time update.

        Parameters
        ----------
        a, b, c : ndarray
            Model of this step.
        q : (n, n) ndarray
            Process noise covariance.
        r : (m,) ndarray
            Measurement noise variances (diagonal ``R``).
        u : (r,) ndarray
            Input applied at this step.
        y : (m,) ndarray or None
            Measurement; non-finite entries are not used.

        Returns
        -------
        (n,) ndarray
            ``x_{k+1|k}``.
        """
        if y is not None and y.shape[0] == c.shape[0] and all_finite(y):
            x, p, gain, e, s, ok = _full_update(self.x, self.P, a, b, c, q,
                                                np.asarray(r, dtype=float), u, y)
            if ok:
                self.x, self.P, self.gain = x, p, gain
                self.innovation, self.innovation_covariance = e, s
                self._corrected = None
                return self.x
        self.correct(c, r, y, a=a)
        return self.predict(a, b, q, u)

    def within(self, c: np.ndarray, r: np.ndarray, y: np.ndarray, sigmas: float) -> np.ndarray:
        """Which outputs of ``y`` lie within ``sigmas`` predicted standard deviations
        of their prediction: ``|y - C x| <= sigmas sqrt(diag(C P C^T) + r)`` (an outlier
        guard; the filter is not changed).

        Returns
        -------
        (m,) ndarray of bool
            False also where the prediction or its spread is not finite.
        """
        return _within(self.x, self.P, np.ascontiguousarray(c, dtype=float),
                       np.asarray(r, dtype=float), np.asarray(y, dtype=float), float(sigmas))

    def filtered(self, c: np.ndarray, r: np.ndarray, y: np.ndarray | None) -> np.ndarray:
        """``x_{k|k}``: the prediction corrected by ``y_k``, without changing the filter.

        Returns
        -------
        (n,) ndarray
            ``x_{k|k}``.
        """
        return self._correction(c, r, y)[0]

    def correct(self, c: np.ndarray, r: np.ndarray, y: np.ndarray | None,
                a: np.ndarray | None = None) -> np.ndarray:
        """Measurement update with ``y_k``: the filter now holds ``x_{k|k}`` (returned).

        ``a`` (the step's transition matrix) only serves to record the
        predictor gain ``K_k = A L_k`` in :attr:`gain`.

        Returns
        -------
        (n,) ndarray
            ``x_{k|k}``.
        """
        a_key = _NO_MATRIX if a is None else a
        st = self._steady
        if (st is not None and self.P is st.prior and y is not None
                and st.correction.holds((c, r, a_key)) and all_finite(y)):
            e = y - st.c @ self.x
            self.x = self.x + st.filter_gain @ e
            self.P = st.post
            self.gain, self.innovation, self.innovation_covariance = st.gain, e, st.s
            self._corrected = None
            return self.x
        x, p, gain, innovation, s = self._correction(c, r, y)
        self._corrected = None
        if gain is not None:
            seen = np.isfinite(y)
            if seen.all():
                self.gain = gain if a is None else a @ gain
                self._corrected = (c, r, a_key)
            else:
                full = np.zeros((self.n, c.shape[0]))
                full[:, seen] = gain if a is None else a @ gain
                self.gain = full
            self.innovation = innovation
            self.innovation_covariance = s if seen.all() else None
        self.x, self.P = x, p
        return x

    def predict(self, a: np.ndarray, b: np.ndarray, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Time update with the input applied: the filter now holds ``x_{k+1|k}``.

        Returns
        -------
        (n,) ndarray
            ``x_{k+1|k}``.
        """
        st = self._steady
        if st is not None and self.P is st.post and st.prediction.holds((a, b, q)):
            self.x = st.a @ self.x + st.b @ u
            self.P = st.prior
            return self.x
        x, p = _predict(self.x, self.P, _f64(a), _f64(b), _f64(q), _f64(u))
        self._note_prior(a, b, q, p)
        self.x, self.P = x, p
        return x

    def advance(self, a: np.ndarray, b: np.ndarray, q: np.ndarray, u: np.ndarray,
                c: np.ndarray, r: np.ndarray, y: np.ndarray | None,
                a_now: np.ndarray | None = None) -> np.ndarray:
        """:meth:`predict` with the last step's model ``(a, b, q)`` and input ``u``, then
        :meth:`correct` with this step's ``(c, r, y)`` (``a_now``: this step's transition
        matrix, for :attr:`gain`): the same numbers, in one compiled call where every
        output is seen. Returns ``x_{k|k}``.

        Returns
        -------
        (n,) ndarray
            ``x_{k|k}``.
        """
        st = self._steady
        if (st is not None and self.P is st.post) or y is None or y.shape[0] != c.shape[0] \
                or not all_finite(y):
            # a held filter (two products each) or a sample with outputs missing
            self.predict(a, b, q, u)
            return self.correct(c, r, y, a=a_now)
        xf, pf, gain, e, s, prior, _ = _predict_correct(
            self.x, self.P, _f64(a), _f64(b), _f64(q), _f64(u), _f64(c), _f64(r), _f64(y))
        self._note_prior(a, b, q, prior)
        st = self._steady
        if st is not None and st.prior is prior:
            pf = st.post                # held from this step on (the same numbers)
        # as correct() with every output seen (a zero gain where S could not be factored)
        self.x, self.P = xf, pf
        self.gain = gain if a_now is None else a_now @ gain
        self.innovation, self.innovation_covariance = e, s
        self._corrected = (c, r, _NO_MATRIX if a_now is None else a_now)
        return xf

    def _note_prior(self, a: np.ndarray, b: np.ndarray, q: np.ndarray, p: np.ndarray) -> None:
        """After a full time update to the prior ``p``: hold the filter (:attr:`steady`)
        when the last two steps moved the prior by at most :data:`STEADY_TOLERANCE` on
        the same model (its bits are compared only once the prior has settled)."""
        corrected, self._corrected = self._corrected, None
        last, self._last_prior = self._last_prior, p
        if (corrected is None or last is None or last.shape != p.shape
                or np.abs(p - last).max() > STEADY_TOLERANCE * np.abs(p).max()):
            self._last_step.clear()
            return
        step = (a, b, q, *corrected)
        if self._last_step.holds(step):
            self._steady = _Steady.hold(p, a, b, q, *corrected)
        else:
            self._last_step.keep(step, True)

    def _correction(self, c: np.ndarray, r: np.ndarray, y: np.ndarray | None) -> tuple:
        """``(x_{k|k}, P_{k|k}, L, innovation, S)``; the last three None without data."""
        x, p = self.x, self.P
        if y is None:
            return x, p, None, None, None
        seen = np.isfinite(y)
        if seen.all():
            xf, pf, gain, e, s, _ = _correct_all(x, p, _f64(c), _f64(r), _f64(y))
            return xf, pf, gain, e, s
        if not seen.any():
            return x, p, None, None, None
        cs = c[seen]
        pct = p @ cs.T
        s = cs @ pct + np.diag(r[seen])
        e = y[seen] - cs @ x
        try:
            gain = np.linalg.solve(s, pct.T).T            # filter gain L
        except np.linalg.LinAlgError:
            gain = np.zeros_like(pct)
        innovation = np.full(c.shape[0], np.nan)
        innovation[seen] = e
        return x + gain @ e, p - gain @ pct.T, gain, innovation, s

    def inflate(self, covariance: ArrayLike) -> None:
        """Add ``covariance`` to ``P`` (state uncertainty after a detected change)."""
        self.P = self.P + np.asarray(covariance, dtype=float)

    def transform(self, t: np.ndarray) -> None:
        """Change coordinates: ``x <- T x``, ``P <- T P T^T``."""
        self.x = t @ self.x
        self.P = t @ self.P @ t.T
