"""The resonant part of an identified flexible model.

Flexible modes are stable, lightly damped resonators. A subspace method
fitted to high-passed data also places real poles, poles outside the unit
circle and poles below the high-pass's corner, where the data carry no
information; none is a mode of the plant, yet each shapes the model's slow
response. :func:`resonant_part` removes them.
"""

from __future__ import annotations

import numpy as np

from identifiers.structured.modal_basis import MAX_DAMPING

__all__ = ["resonant_part"]


def resonant_part(a: np.ndarray, b: np.ndarray, c: np.ndarray, dt: float, min_hz: float,
                  max_damping: float = MAX_DAMPING
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The part of ``(A, B, C)`` that is lightly damped resonance above ``min_hz``.

    Flexible modes are stable, lightly damped resonators; what a subspace method
    places at real poles, outside the unit circle, below ``min_hz`` (where
    high-passed data carry no information) or at a damping ratio above
    ``max_damping`` (default the modal identifier's bound, 0.3) is not a mode of
    the plant, yet it shapes the slow response and the one-step prediction. The
    spectral projection ``P`` onto the kept eigenvalues removes the rest from the
    input-output map and makes it inert: ``(A P, P B, C P)`` (same order; the
    removed eigenvalues become 0). Returned unchanged when no eigenvalue is
    removed or the eigenvectors are too ill-conditioned to project with.
    """
    lam, vec = np.linalg.eig(a)
    hz = np.abs(np.angle(lam)) / (2.0 * np.pi * dt)
    # damping ratio of each pole's continuous-time equivalent (a pole at 0: inf damping)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.log(lam.astype(complex)) / dt
        zeta = np.where(np.abs(s) > 0, -s.real / np.abs(s), np.inf)
    keep = ((np.abs(lam.imag) > 1e-9) & (np.abs(lam) < 1.0) & (hz >= min_hz)
            & (zeta <= max_damping))
    if keep.all():
        return a, b, c
    if np.linalg.cond(vec) > 1e8:
        return a, b, c
    proj = np.real(vec[:, keep] @ np.linalg.inv(vec)[keep, :])
    return a @ proj, proj @ b, c @ proj
