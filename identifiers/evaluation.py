"""Judging identified time-varying models (paper Sec. 4.3; docs/design/evaluation.md).

State coordinates are arbitrary, so models are compared through responses:
the paper's test inputs ``u_x = sin(0.1 t)``, ``u_y = sin(0.05 t)``,
``u_z = -sin(0.08 t)`` drive, from zero state, the true time-varying plant
and the identified sequence ``{A_k, B_k, C_k}``; each output channel is
scored by the normalized error ``||y_id - y_true|| / ||y_true||`` (%) and by
VAF. One-step-ahead prediction VAF on held-out noisy data complements it.
"""

from __future__ import annotations

import numpy as np

from identifiers.model import ModelSequence

__all__ = [
    "add_measurement_noise",
    "identification_inputs",
    "normalized_error",
    "one_step_predictions",
    "paper_test_inputs",
    "vaf",
]


def paper_test_inputs(n_samples: int, dt: float = 0.1) -> np.ndarray:
    """The paper's test torques (Fig. 5), (N, 3), N m, at t = k dt."""
    t = np.arange(n_samples) * dt
    return np.column_stack([np.sin(0.1 * t), np.sin(0.05 * t), -np.sin(0.08 * t)])


def identification_inputs(n_samples: int, rng: np.random.Generator, dt: float = 0.1,
                          rms: float = 1.0, band_hz: tuple[float, float] = (0.004, 1.5),
                          n_tones: int = 60) -> np.ndarray:
    """Reaction-wheel-like identification torques (stand-in for the paper's Fig. 2).

    Independent random-phase multisines per axis: ``n_tones`` log-spaced
    frequencies in ``band_hz`` (covering the rigid-body band and the first
    flexible modes), equal amplitudes, scaled to ``rms`` N m. Zero mean over
    the record, persistently exciting, and reproducible from ``rng``.

    Returns
    -------
    (n_samples, 3) ndarray
    """
    t = np.arange(n_samples) * dt
    freqs = np.geomspace(band_hz[0], band_hz[1], n_tones)
    phases = rng.uniform(0, 2 * np.pi, size=(3, n_tones))
    u = np.sin(2 * np.pi * freqs[None, None, :] * t[:, None, None] + phases[None, :, :]).sum(-1)
    u -= u.mean(axis=0)
    return rms * u / u.std(axis=0)


def add_measurement_noise(y: np.ndarray, snr_db: float | None,
                          rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise per channel at ``snr_db`` relative to the channel's RMS."""
    if snr_db is None:
        return y.copy()
    rms = np.sqrt(np.mean(y**2, axis=0))
    return y + rng.standard_normal(y.shape) * rms * 10 ** (-snr_db / 20)


def normalized_error(y_id: np.ndarray, y_true: np.ndarray) -> np.ndarray:
    """Per-channel ``100 ||y_id - y_true||_2 / ||y_true||_2`` (%)."""
    return 100 * np.linalg.norm(y_id - y_true, axis=0) / np.linalg.norm(y_true, axis=0)


def vaf(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Per-channel variance accounted for, ``100 (1 - var(y - yhat) / var(y))`` (%)."""
    return 100 * (1 - np.var(y - yhat, axis=0) / np.var(y, axis=0))


def one_step_predictions(models: ModelSequence, inputs: np.ndarray,
                         outputs: np.ndarray) -> np.ndarray:
    """One-step-ahead predictions of a record with the time-varying predictor.

    Thin wrapper of :meth:`ModelSequence.predict`.
    """
    return models.predict(inputs, outputs)
