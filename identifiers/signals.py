"""The signals of an identification experiment: the paper's test torques, a
persistently exciting identification input and measurement noise at a given
signal-to-noise ratio (docs/design/evaluation.md).

Randomness comes only from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import numpy as np

__all__ = ["add_measurement_noise", "identification_inputs", "paper_test_inputs"]


def paper_test_inputs(n_samples: int, dt: float = 0.1) -> np.ndarray:
    """The paper's test torques (Fig. 5), (N, 3), N m, at t = k dt.

    Parameters
    ----------
    n_samples : int
        N, the number of samples.
    dt : float
        Sample time, s.

    Returns
    -------
    (N, 3) ndarray
        ``[sin(0.1 t), sin(0.05 t), -sin(0.08 t)]`` N m (t in s) at ``t = k dt``,
        ``k = 0..N-1``.
    """
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

    Parameters
    ----------
    n_samples : int
        Samples of the record.
    rng : numpy.random.Generator
        Source of the random phases (3 x ``n_tones`` uniform draws).
    dt : float
        Sample time, s.
    rms : float
        RMS torque of every axis over the record, N m.
    band_hz : (float, float)
        Lowest and highest tone frequency, Hz.
    n_tones : int
        Tones per axis.

    Returns
    -------
    (n_samples, 3) ndarray
        Torques, N m, one column per body axis.
    """
    t = np.arange(n_samples) * dt
    freqs = np.geomspace(band_hz[0], band_hz[1], n_tones)
    phases = rng.uniform(0, 2 * np.pi, size=(3, n_tones))
    u = np.sin(2 * np.pi * freqs[None, None, :] * t[:, None, None] + phases[None, :, :]).sum(-1)
    u -= u.mean(axis=0)
    return rms * u / u.std(axis=0)


def add_measurement_noise(y: np.ndarray, snr_db: float | None,
                          rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise per channel at ``snr_db`` relative to the channel's RMS.

    Parameters
    ----------
    y : (N, m) ndarray
        Noise-free outputs, one column per channel (any units).
    snr_db : float or None
        Signal-to-noise ratio, dB: the noise standard deviation of a channel
        is its RMS over the record times ``10^(-snr_db / 20)``. None: no noise.
    rng : numpy.random.Generator
        Source of the noise.

    Returns
    -------
    (N, m) ndarray
        A new array: ``y`` plus the noise (a copy of ``y`` for ``snr_db=None``),
        in ``y``'s units.
    """
    if snr_db is None:
        return y.copy()
    rms = np.sqrt(np.mean(y**2, axis=0))
    return y + rng.standard_normal(y.shape) * rms * 10 ** (-snr_db / 20)
