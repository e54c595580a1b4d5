"""Judging identified time-varying models (docs/design/evaluation.md).

State coordinates are arbitrary, so models are compared through what they
predict and through coordinate-free quantities:

* the paper's test-response error (Sec. 4.3): the test inputs
  ``u_x = sin(0.1 t)``, ``u_y = sin(0.05 t)``, ``u_z = -sin(0.08 t)`` drive,
  from zero state, the true time-varying plant and the identified sequence
  ``{A_k, B_k, C_k}``; each channel is scored by
  ``||y_id - y_true|| / ||y_true||`` (%) (:func:`normalized_error`);
* h-step-ahead prediction VAF from the identifier's own state and model at
  each k, beside persistence (:func:`h_step_predictions`,
  :func:`persistence_predictions`, :func:`prediction_vaf`);
* modal frequency and damping errors (:func:`modal_errors`);
* the rigid-body gain ``J^-1`` read from a model (:func:`rigid_body_gain`);
* the share of models with poles outside the unit circle
  (:func:`unstable_share`).

The inputs and the noise of such an experiment are in :mod:`identifiers.signals`.

One-step VAF at dt = 0.1 s cannot tell a model from none (persistence
scores 99 % or more on this plant), so it is never the headline.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import schur, solve_sylvester

from identifiers.core.model import StateSpaceModel
from identifiers.core.model_sequence import ModelSequence

__all__ = [
    "HORIZONS",
    "h_step_predictions",
    "modal_errors",
    "normalized_error",
    "one_step_predictions",
    "persistence_predictions",
    "prediction_vaf",
    "relative_gain_error",
    "rigid_body_gain",
    "unstable_share",
    "vaf",
]

#: Default prediction horizons (samples): 0.1, 1, 5 and 10 s at dt = 0.1 s.
HORIZONS: tuple[int, ...] = (1, 10, 50, 100)


def normalized_error(y_id: np.ndarray, y_true: np.ndarray) -> np.ndarray:
    """Per-channel ``100 ||y_id - y_true||_2 / ||y_true||_2`` (%).

    Parameters
    ----------
    y_id : (N, m) ndarray
        Identified (or predicted) outputs.
    y_true : (N, m) ndarray
        True outputs, same units.

    Returns
    -------
    (m,) ndarray
        The error of each channel over the record, %.
    """
    return 100 * np.linalg.norm(y_id - y_true, axis=0) / np.linalg.norm(y_true, axis=0)


def vaf(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Per-channel variance accounted for, ``100 (1 - var(y - yhat) / var(y))`` (%).

    Parameters
    ----------
    y : (N, m) ndarray
        Measured (or true) outputs.
    yhat : (N, m) ndarray
        Predicted outputs, same units.

    Returns
    -------
    (m,) ndarray
        VAF of each channel, % (100: perfect; unbounded below).
    """
    return 100 * (1 - np.var(y - yhat, axis=0) / np.var(y, axis=0))


def one_step_predictions(models: ModelSequence, inputs: np.ndarray,
                         outputs: np.ndarray) -> np.ndarray:
    """One-step-ahead predictions of a record with the time-varying predictor.

    Thin wrapper of :meth:`ModelSequence.predict`.

    Parameters
    ----------
    models : ModelSequence
        The identified sequence, one model (or warm-up gap) per sample.
    inputs : (N, r) ndarray
        Inputs of the record (torques, N m, for the spacecraft).
    outputs : (N, m) ndarray
        Measured outputs of the record.

    Returns
    -------
    (N, m) ndarray
        Row k is ``yhat_{k|k-1}``, in the units of ``outputs``; steps before
        the first valid model (and invalid ones) use the first valid model.
    """
    return models.predict(inputs, outputs)


# ----------------------------------------------------------------- model quality
def h_step_predictions(models: ModelSequence, inputs: ArrayLike,
                       horizons: Sequence[int] = HORIZONS) -> dict[int, np.ndarray]:
    """h-step-ahead output predictions from the identifier's own state and model.

    For every sample k with a valid model, start from the state estimate
    ``x_{k+1|k}`` (``models.states[k]``) and model k, and run the model
    open-loop on the *true* future inputs::

        x_{k+j+1} = A_k x_{k+j} + B_k u_{k+j},     yhat_{k+h|k} = C_k x_{k+h} + D_k u_{k+h}

    ``h = 1`` is the one-step-ahead prediction. This is what a model-based
    controller relies on; unlike one-step VAF it separates a model from
    none (persistence, ``y_{k+h} = y_k``, is far worse at 10 s).

    Parameters
    ----------
    models : ModelSequence
        With ``states`` (as :meth:`OnlineIdentifier.fit` returns it), or the
        true model frozen at each k with the true states (the ceiling).
    inputs : (N, r) array_like
        The inputs of the record the models were identified on.
    horizons : sequence of int
        Prediction horizons h >= 1, in samples.

    Returns
    -------
    dict
        h -> (N, m) array whose row t is ``yhat_{t|t-h}`` (NaN where ``t - h``
        had no valid model or ``t < h``).
    """
    if models.states is None:
        raise ValueError("the model sequence has no states; use OnlineIdentifier.fit()")
    u = np.asarray(inputs, dtype=float)
    hs = sorted({int(h) for h in horizons})
    if not hs or hs[0] < 1:
        raise ValueError(f"horizons must be integers >= 1, got {list(horizons)}")
    n_samples = min(len(models), u.shape[0])
    out = {h: np.full((n_samples, models.C.shape[1]), np.nan) for h in hs}
    start = np.flatnonzero(models.valid[:n_samples - 1])
    if start.size == 0:
        return out
    a, b, c, d = (m[start] for m in (models.A, models.B, models.C, models.D))
    x = models.states[start].copy()
    for j in range(1, hs[-1] + 1):
        target = start + j                       # time whose output is predicted
        live = target < n_samples
        if not live.any():
            break
        uj = u[np.minimum(target, n_samples - 1)]
        if j in out:
            y = np.einsum("kij,kj->ki", c, x) + np.einsum("kij,kj->ki", d, uj)
            out[j][target[live]] = y[live]
        x = np.einsum("kij,kj->ki", a, x) + np.einsum("kij,kj->ki", b, uj)
    return out


def persistence_predictions(outputs: ArrayLike, horizons: Sequence[int] = HORIZONS
                            ) -> dict[int, np.ndarray]:
    """The trivial baseline: ``yhat_{t|t-h} = y_{t-h}`` (NaN for ``t < h``).

    Parameters
    ----------
    outputs : (N, m) array_like
        The measured outputs.
    horizons : sequence of int
        Prediction horizons h >= 1, in samples (default :data:`HORIZONS`).

    Returns
    -------
    dict
        h -> (N, m) array whose row t is ``y_{t-h}`` (NaN for ``t < h``), for
        each distinct horizon in increasing order.

    Raises
    ------
    ValueError
        ``outputs`` not 2-D, or a horizon that is not an integer >= 1.
    """
    y = np.asarray(outputs, dtype=float)
    if y.ndim != 2:
        raise ValueError(f"outputs must be (N, m), got shape {y.shape}")
    bad = [h for h in horizons if isinstance(h, bool) or int(h) != h or h < 1]
    if bad:
        raise ValueError(f"horizons must be integers >= 1, got {bad}")
    out = {}
    for h in sorted({int(h) for h in horizons}):
        pred = np.full_like(y, np.nan)
        pred[h:] = y[:-h]
        out[h] = pred
    return out


def prediction_vaf(target: ArrayLike, predictions: dict[int, np.ndarray], start: int = 0
                   ) -> dict[int, np.ndarray]:
    """Per-channel VAF (%) of each horizon's predictions over ``t >= start``.

    Rows where every prediction is missing (all NaN: the model did not
    exist yet) are left out. A row with some non-finite predictions is a
    broken model's and is kept: its channels score ``-inf``, as does a
    channel whose prediction diverged or whose target has no variance (VAF
    undefined).

    Parameters
    ----------
    target : (N, m) array_like
        The outputs predicted.
    predictions : dict
        h -> (N, m) ndarray of predictions, as :func:`h_step_predictions` or
        :func:`persistence_predictions` return them.
    start : int
        First sample scored.

    Returns
    -------
    dict
        h -> (m,) ndarray: each channel's VAF (%), NaN for a horizon with no
        scored row.
    """
    y = np.asarray(target, dtype=float)
    out = {}
    for h, pred in predictions.items():
        rows = np.arange(y.shape[0]) >= start
        rows &= ~np.all(np.isnan(pred), axis=1)
        if not rows.any():
            out[h] = np.full(y.shape[1], np.nan)
            continue
        with np.errstate(all="ignore"):
            v = vaf(y[rows], pred[rows])
        out[h] = np.where(np.isfinite(v), v, -np.inf)
    return out


def unstable_share(models: ModelSequence, start: int = 0, bound: float = 1.001) -> float:
    """Share of the valid models from sample ``start`` on with a pole ``|z| > bound``.

    Parameters
    ----------
    models : ModelSequence
        Identified discrete-time models.
    start : int
        First sample counted.
    bound : float
        Pole modulus above which a model counts as unstable (default 1.001,
        a margin for the rigid body's poles at ``z = 1``).

    Returns
    -------
    float
        Share in [0, 1] (a model with non-finite entries counts as unstable);
        NaN if no model from ``start`` on is valid.
    """
    idx = np.flatnonzero(models.valid)
    idx = idx[idx >= start]
    if idx.size == 0:
        return float("nan")
    with np.errstate(all="ignore"):
        finite = np.all(np.isfinite(models.A[idx]), axis=(1, 2))
        radius = np.full(idx.size, np.inf)
        radius[finite] = np.abs(np.linalg.eigvals(models.A[idx[finite]])).max(axis=1)
    return float(np.mean(radius > bound))


def modal_errors(model: StateSpaceModel, true_frequencies_hz: ArrayLike,
                 true_damping: ArrayLike, max_damping: float = 0.5
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Frequency and damping errors of the identified modes against the truth's.

    Each true mode is matched to the identified oscillatory mode nearest in
    frequency (among those with damping ratio in ``[-0.05, max_damping]``).

    Parameters
    ----------
    model : StateSpaceModel
        The identified model.
    true_frequencies_hz : (n_true,) array_like
        Natural frequencies of the true modes, Hz.
    true_damping : (n_true,) array_like
        Damping ratios of the true modes.
    max_damping : float
        Largest damping ratio of an identified mode that may be matched.

    Returns
    -------
    freq_error : (n_true,) ndarray
        ``|f_id - f_true| / f_true`` (NaN if no identified mode qualifies).
    damping_error : (n_true,) ndarray
        ``zeta_id - zeta_true``.
    """
    f_true = np.asarray(true_frequencies_hz, dtype=float)
    z_true = np.asarray(true_damping, dtype=float)
    f_id, z_id = model.modal(unique=False)
    keep = (z_id >= -0.05) & (z_id <= max_damping) & np.isfinite(f_id)
    f_id, z_id = f_id[keep], z_id[keep]
    if f_id.size == 0:
        return np.full(f_true.shape, np.nan), np.full(f_true.shape, np.nan)
    nearest = np.abs(f_id[None, :] / f_true[:, None] - 1.0).argmin(axis=1)
    return np.abs(f_id[nearest] / f_true - 1.0), z_id[nearest] - z_true


def rigid_body_gain(model: StateSpaceModel, rate_rows: ArrayLike | slice,
                    n_rigid: int = 6) -> np.ndarray:
    """The rigid-body gain ``G ~ J^-1`` (rad/s^2 per N m) read from a model.

    The rigid body is the cluster of ``n_rigid`` poles nearest ``z = 1``
    (three double integrators: 6 for a spacecraft). The model is split into
    that invariant subspace and the rest (ordered Schur form and a Sylvester
    solve, which handles the Jordan block at ``z = 1``), and the gain is the
    rigid part's first Markov parameter from torque to body rate divided by
    ``dt``: for the ZOH-sampled rigid body ``omega_{k+1} = omega_k + J^-1 dt
    u_k`` that is exactly ``J^-1``, and the flexible modes do not enter it.

    Parameters
    ----------
    model : StateSpaceModel
        Identified (or true) model; inputs are torques (N m).
    rate_rows : array_like of int or slice
        Rows of the body-rate outputs (rad/s).
    n_rigid : int
        Poles in the rigid cluster.

    Returns
    -------
    (len(rate_rows), r) ndarray
    """
    a = model.A
    if not np.all(np.isfinite(a)):
        return np.full((model.C[rate_rows].shape[0], model.n_inputs), np.nan)
    dist = np.abs(np.linalg.eigvals(a) - 1.0)
    radius = np.sort(dist)[min(n_rigid, a.shape[0]) - 1]
    t, z, sdim = schur(a.astype(complex), output="complex",
                       sort=lambda x: abs(x - 1.0) <= radius * (1 + 1e-9))
    t11, t12, t22 = t[:sdim, :sdim], t[:sdim, sdim:], t[sdim:, sdim:]
    x = solve_sylvester(t11, -t22, -t12) if sdim < a.shape[0] else np.zeros((sdim, 0))
    b_mod = z.conj().T @ model.B
    b_rigid = b_mod[:sdim] - x @ b_mod[sdim:]
    c_rigid = model.C[rate_rows] @ z[:, :sdim]
    return np.real(c_rigid @ b_rigid) / model.dt


def relative_gain_error(estimate: ArrayLike, truth: ArrayLike) -> float:
    """``||G - G_true||_2 / ||G_true||_2`` (spectral norms).

    Parameters
    ----------
    estimate : (3, 3) array_like
        Estimated rigid-body gain ``G`` (e.g. :func:`rigid_body_gain`), rad/s^2
        per N m.
    truth : (3, 3) array_like
        True gain ``J^-1``, same units.

    Returns
    -------
    float
        The relative error (0: exact); ``inf`` if ``estimate`` has a
        non-finite entry.
    """
    g, g_true = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    if not np.all(np.isfinite(g)):
        return float("inf")
    return float(np.linalg.norm(g - g_true, 2) / np.linalg.norm(g_true, 2))
