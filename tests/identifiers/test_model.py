"""StateSpaceModel against a peer: python-control's modal analysis."""

from __future__ import annotations

import numpy as np
import pytest

from identifiers import StateSpaceModel


def test_modal_agrees_with_python_control_damp():
    """StateSpaceModel.modal is python-control's damp() for a sampled system, restricted
    to the oscillatory poles (one per conjugate pair), in Hz."""
    control = pytest.importorskip("control")
    rng = np.random.default_rng(3)
    # a sampled plant with three lightly damped modes and a real pole
    blocks = []
    for f_hz, zeta in ((0.08, 0.01), (0.24, 0.05), (0.51, 0.2)):
        wn = 2 * np.pi * f_hz
        blocks.append(np.array([[0.0, 1.0], [-wn * wn, -2 * zeta * wn]]))
    a_c = np.zeros((7, 7))
    for i, blk in enumerate(blocks):
        a_c[2 * i:2 * i + 2, 2 * i:2 * i + 2] = blk
    a_c[6, 6] = -0.3
    dt = 0.1
    from scipy.linalg import expm

    a = expm(a_c * dt)
    b, c = rng.normal(size=(7, 2)), rng.normal(size=(3, 7))
    model = StateSpaceModel(a, b, c, np.zeros((3, 2)), np.zeros((7, 3)), dt)
    freq, zeta = model.modal()
    wn, z, poles = control.damp(control.ss(a, b, c, np.zeros((3, 2)), dt), doprint=False)
    upper = poles.imag > 1e-12
    order = np.argsort(wn[upper])
    np.testing.assert_allclose(freq, wn[upper][order] / (2 * np.pi), rtol=1e-10)
    np.testing.assert_allclose(zeta, z[upper][order], rtol=1e-10)
    np.testing.assert_allclose(freq, [0.08, 0.24, 0.51], rtol=1e-10)
