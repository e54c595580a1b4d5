"""The compiled matrix exponential of a stack against closed forms and SciPy."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from identifiers.core.expm import expm_stack


def test_closed_forms():
    t = 0.7
    rotation = np.array([[0.0, -t], [t, 0.0]])             # exp: a rotation by t
    nilpotent = np.array([[0.0, 1.0, 0.5], [0.0, 0.0, 2.0], [0.0, 0.0, 0.0]])
    diagonal = np.diag([-3.0, 0.0, 12.0])                  # degree 13 with squarings
    e_rot, e_nil, e_diag = expm_stack(np.stack([np.pad(rotation, ((0, 1), (0, 1))), nilpotent,
                                                diagonal]))
    np.testing.assert_allclose(e_rot[:2, :2], [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]],
                               rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(e_nil, np.eye(3) + nilpotent + nilpotent @ nilpotent / 2,
                               rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(np.diag(e_diag), np.exp([-3.0, 0.0, 12.0]), rtol=1e-14)


@pytest.mark.parametrize("scale", [1e-6, 1e-2, 0.2, 0.9, 2.0, 5.0, 40.0])
def test_equals_scipy_over_every_pade_degree(scale):
    # norms from below theta_3 to well above theta_13 (scaling and squaring)
    rng = np.random.default_rng(int(scale * 1e6) % 2**32)
    m = rng.normal(size=(6, 9, 9)) * scale / 3
    expected = scipy.linalg.expm(m)
    got = expm_stack(m)
    for e, g in zip(expected, got, strict=True):
        np.testing.assert_allclose(g, e, rtol=1e-11, atol=1e-13 * np.abs(e).max())


def test_any_leading_shape():
    rng = np.random.default_rng(1)
    m = rng.normal(size=(2, 3, 4, 4)) * 0.3
    got = expm_stack(m)
    assert got.shape == m.shape
    np.testing.assert_allclose(got[1, 2], scipy.linalg.expm(m[1, 2]), rtol=1e-13)
    np.testing.assert_allclose(expm_stack(m[0, 0]), got[0, 0], rtol=0, atol=0)


def test_bad_input():
    with pytest.raises(ValueError, match=r"\(\.\.\., n, n\)"):
        expm_stack(np.zeros((3, 2, 4)))
    with pytest.raises(ValueError, match=r"\(\.\.\., n, n\)"):
        expm_stack(np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        expm_stack(np.array([[np.nan, 0.0], [0.0, 1.0]]))
