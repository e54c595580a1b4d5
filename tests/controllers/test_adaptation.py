"""RMA-style adaptation: the module's regression, the estimated and nominal vectors."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import spacecraft_env  # noqa: F401  (registers the environments)
from controllers import AdaptationModule, EstimatedFeatures, PrivilegedFeatures
from controllers.features import PHYSICAL_FEATURE_NAMES

N_FEAT = len(PHYSICAL_FEATURE_NAMES)           # 17 with two modes
ESTIMATED = np.r_[0:6, 7:11]                   # gain and the two modes' frequency, damping
PADDLE = slice(N_FEAT - 4, N_FEAT - 2)


def _pairs(n: int = 600, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Physical vectors (the last third before the warm-up) and privileged ones that are
    a known affine function of them, or of the paddle angle before the warm-up."""
    rng = np.random.default_rng(seed)
    physical = rng.normal(size=(n, N_FEAT))
    angle = rng.uniform(0, 2 * np.pi, n)
    physical[:, PADDLE] = np.column_stack([np.sin(angle), np.cos(angle)])
    physical[:, -2] = rng.integers(0, 2, n)
    physical[:, -1] = 1.0
    early = np.arange(n) >= 2 * n // 3
    physical[early, :-4] = 0.0
    physical[early, -2:] = 0.0
    weights = rng.normal(size=(N_FEAT, ESTIMATED.size))
    privileged = np.zeros((n, N_FEAT))
    privileged[:, ESTIMATED] = physical @ weights + 0.3
    rows = np.flatnonzero(early)
    privileged[np.ix_(rows, ESTIMATED)] = 0.0
    privileged[rows, 0] = 0.2 * np.sin(angle[rows]) - 0.1        # the drive alone
    privileged[:, PADDLE] = physical[:, PADDLE]
    privileged[:, -1] = 1.0
    return physical, privileged, early


def test_the_module_recovers_an_affine_map_after_the_warm_up_and_the_drive_map_before():
    physical, privileged, early = _pairs()
    module = AdaptationModule(ridge=1e-10).fit(physical, privileged)
    got = module.predict(physical)
    np.testing.assert_allclose(got[~early][:, ESTIMATED], privileged[~early][:, ESTIMATED],
                               atol=1e-6)
    np.testing.assert_allclose(got[early][:, ESTIMATED], privileged[early][:, ESTIMATED],
                               atol=1e-6)
    # what the privileged vector knows exactly: no uncertainty, the drive's angle, ready
    assert np.all(got[:, 6] == 0.0) and np.all(got[:, 11:13] == 0.0)
    np.testing.assert_array_equal(got[:, PADDLE], physical[:, PADDLE])
    np.testing.assert_array_equal(got[:, -2], physical[:, -2])
    assert np.all(got[:, -1] == 1.0)
    # one vector is another product shape: equal to rounding
    np.testing.assert_allclose(module.predict(physical[0]), got[0], rtol=1e-12, atol=1e-12)


def test_the_ridge_shrinks_towards_the_mean_answer():
    physical, privileged, early = _pairs()
    exact = AdaptationModule(ridge=1e-10).fit(physical, privileged).predict(physical)
    heavy = AdaptationModule(ridge=1e3).fit(physical, privileged).predict(physical)
    spread = np.std(heavy[~early][:, ESTIMATED], axis=0)
    assert np.all(spread < 0.05 * np.std(exact[~early][:, ESTIMATED], axis=0))


def test_module_rejects_bad_input_and_pickles():
    physical, privileged, _ = _pairs()
    module = AdaptationModule()
    with pytest.raises(RuntimeError, match="fit the adaptation module"):
        module.predict(physical[0])
    with pytest.raises(ValueError, match=r"shape \(N, 17\)"):
        module.fit(physical[:, :5], privileged)
    with pytest.raises(ValueError, match="pair up"):
        module.fit(physical, privileged[:-1])
    bad = physical.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="finite"):
        module.fit(bad, privileged)
    unready = physical.copy()
    unready[:, -1] = 0.0
    with pytest.raises(ValueError, match="identifier ready"):
        module.fit(unready, privileged)
    with pytest.raises(ValueError, match="ridge"):
        AdaptationModule(ridge=-1.0)
    module.fit(physical, privileged)
    clone = pickle.loads(pickle.dumps(module))
    np.testing.assert_array_equal(clone.predict(physical), module.predict(physical))


def _family(**kwargs):
    return gym.make("FlexibleSpacecraftFamily-v2", task="slew", **kwargs)


def test_the_estimated_vector_takes_the_privileged_vectors_place():
    """A policy trained with the truth flies the estimated env unchanged: same space,
    same channels; before the identifier's warm-up the estimate is the drive-only map."""
    physical, privileged, _ = _pairs()
    module = AdaptationModule().fit(physical, privileged)
    estimated = EstimatedFeatures(_family(), module)
    truth = PrivilegedFeatures(_family())
    assert estimated.observation_space == truth.observation_space
    obs, info = estimated.reset(seed=3)
    inner = np.zeros(N_FEAT)
    inner[PADDLE] = np.sin(info["paddle_angle"]), np.cos(info["paddle_angle"])
    np.testing.assert_allclose(obs[-N_FEAT:], module.predict(inner), atol=1e-6)
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(EstimatedFeatures(_family(), module), skip_render_check=True)
    with pytest.raises(ValueError, match="fitted AdaptationModule"):
        EstimatedFeatures(_family(), AdaptationModule())


def test_the_nominal_vector_is_the_frames_origin_whatever_the_draw():
    plant = {"inertia_scale": 1.3, "stiffness_scale": 0.8, "actuator_gain": 0.7,
             "module_masses_kg": [0.0, 0.0], "paddle_angle_deg": 120.0,
             "paddle_rate_deg_s": 0.0}
    nominal = PrivilegedFeatures(_family(), source="nominal")
    truth = PrivilegedFeatures(_family())
    obs_n, _ = nominal.reset(seed=0, options={"plant": plant})
    obs_t, _ = truth.reset(seed=0, options={"plant": plant})
    feats_n, feats_t = obs_n[-N_FEAT:], obs_t[-N_FEAT:]
    np.testing.assert_allclose(feats_n[0:3], 0.0, atol=1e-6)        # nominal gain
    np.testing.assert_allclose(feats_n[7:9], 0.0, atol=1e-6)        # nominal modes
    assert np.all(np.abs(feats_t[0:3]) > 0.1)                        # this draw is not
    np.testing.assert_allclose(feats_n[PADDLE], feats_t[PADDLE], atol=1e-6)   # the drive
    assert feats_n[-1] == 1.0 and feats_n[-2] == 0.0
    with pytest.raises(ValueError, match="source"):
        PrivilegedFeatures(_family(), source="estimate")
