"""The resonant part of an identified flexible model.

Flexible modes are stable, lightly damped resonators. A subspace method
fitted to high-passed data also places real poles, poles outside the unit
circle and poles below the high-pass's corner, where the data carry no
information; none is a mode of the plant, yet each shapes the model's slow
response. :func:`resonant_part` removes them, except a pole just outside the
circle (:data:`REFLECTED_DAMPING`), which is a lightly damped mode estimated on
the wrong side of it and is reflected inside.
"""

from __future__ import annotations

import numpy as np

from identifiers.core.modal_basis import MAX_DAMPING

__all__ = ["REFLECTED_DAMPING", "resonant_part"]

#: An oscillatory pole outside the unit circle by at most this (negative) damping ratio
#: is reflected inside (``lambda / |lambda|^2``: same frequency, the damping's sign
#: turned). The structure's modes are damped about 0.01; the subspace method places a
#: mode that light about as often just outside the circle as just inside (docking,
#: the dominant 0.088 Hz mode at |lambda| = 1.0003, damping -0.005: dropped, the 10 s
#: deflection prediction lost it).
REFLECTED_DAMPING = 0.02


def resonant_part(a: np.ndarray, b: np.ndarray, c: np.ndarray, dt: float, min_hz: float,
                  max_damping: float = MAX_DAMPING
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The part of ``(A, B, C)`` that is lightly damped resonance above ``min_hz``.

    Flexible modes are stable, lightly damped resonators; what a subspace method
    places at real poles, outside the unit circle, below ``min_hz`` (where
    high-passed data carry no information) or at a damping ratio above
    ``max_damping`` (default the modal identifier's bound, 0.3) is not a mode of
    the plant, yet it shapes the slow response and the one-step prediction. An
    oscillatory pole outside the circle by a damping ratio of at most
    :data:`REFLECTED_DAMPING` is first reflected inside (``lambda / |lambda|^2``).
    The spectral projection ``P`` onto the kept eigenvalues removes the rest from
    the input-output map and makes it inert: ``(V_k Lambda_k W_k, P B, C P)`` with
    ``P = V_k W_k`` (``A P`` when nothing is reflected; same order, the removed
    eigenvalues become 0). Returned unchanged when no eigenvalue is removed or
    reflected, or the eigenvectors are too ill-conditioned to project with.

    Returns
    -------
    (A, B, C) : ndarrays
        The projected model, same shapes as the input.
    """
    lam, vec = np.linalg.eig(a)
    hz = np.abs(np.angle(lam)) / (2.0 * np.pi * dt)
    oscillatory = np.abs(lam.imag) > 1e-9
    zeta = _damping(lam, dt)
    reflect = oscillatory & (np.abs(lam) >= 1.0) & (zeta >= -REFLECTED_DAMPING)
    lam = np.where(reflect, lam / np.abs(lam) ** 2, lam)
    zeta = np.where(reflect, -zeta, zeta)
    keep = oscillatory & (np.abs(lam) < 1.0) & (hz >= min_hz) & (zeta <= max_damping)
    if keep.all() and not reflect.any():
        return a, b, c
    if np.linalg.cond(vec) > 1e8:
        return a, b, c
    left = np.linalg.inv(vec)[keep, :]
    proj = np.real(vec[:, keep] @ left)
    return np.real((vec[:, keep] * lam[keep]) @ left), proj @ b, c @ proj


def _damping(lam: np.ndarray, dt: float) -> np.ndarray:
    """Damping ratio of each pole's continuous-time equivalent (a pole at 0: inf)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.log(lam.astype(complex)) / dt
        return np.where(np.abs(s) > 0, -s.real / np.abs(s), np.inf)
