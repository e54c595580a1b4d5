"""Fault suite: each test reproduces one failure mode found on the earlier main
(threads, test-order dependence, corrupt samples, sweeps, bad input) and
checks that it is gone."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from filelock import FileLock
from threadpoolctl import threadpool_limits

from controllers import AdaptiveLQG, IdentifiedModelFeatures, dlqr, fast_identifier
from identifiers import (
    ClassicalRPBSID,
    ImprovedRPBSID,
    MomentRefitRPBSID,
    PredictorRPBSID,
    StateSpaceModel,
    default_identifier,
)
from spacecraft_conventions import STANDARD_OUTPUTS, single_threaded_blas
from spacecraft_env import FlexibleSpacecraftEnv, FlexibleSpacecraftModel
from spacecraft_lab.cli import main
from spacecraft_lab.identification import identify_task
from spacecraft_lab.sweeps import (
    ResultStore,
    SweepConfig,
    SweepLockedError,
    load_config,
    run_sweep,
    summarize,
)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def record() -> tuple[np.ndarray, np.ndarray]:
    """1500 samples of the docking plant under random torques, with sensor noise."""
    truth = FlexibleSpacecraftModel(scenario="docking")
    rng = np.random.default_rng(0)
    u = rng.normal(size=(1500, 3))
    y = truth.simulate(u)[1] + 0.01 * STANDARD_OUTPUTS.scales() * rng.normal(size=(1500, 10))
    return u, y


# ----------------------------------------------------------------- threads
def test_the_users_thread_setting_is_restored():
    from threadpoolctl import threadpool_info

    with threadpool_limits(limits=2, user_api="blas"):
        ident = default_identifier()
        ident.update(np.zeros(3), np.zeros(10))
        assert all(i["num_threads"] == 2 for i in threadpool_info() if i["user_api"] == "blas")
        with single_threaded_blas:
            assert all(i["num_threads"] == 1 for i in threadpool_info()
                       if i["user_api"] == "blas")
        assert all(i["num_threads"] == 2 for i in threadpool_info() if i["user_api"] == "blas")


def test_fit_equals_the_update_loop_whatever_the_threads(record):
    u, y = record
    with threadpool_limits(limits=2, user_api="blas"):
        looped = default_identifier()
        for k in range(600):
            looped.update(u[k], y[k])
    fitted = default_identifier().fit(u[:600], y[:600])
    np.testing.assert_array_equal(fitted.A[599], looped.model.A)


def test_truth_matrices_are_bit_identical_across_thread_counts():
    with threadpool_limits(limits=2, user_api="blas"):
        two = FlexibleSpacecraftModel(scenario="solar_rotation").discrete(37.3).A
    with threadpool_limits(limits=1, user_api="blas"):
        one = FlexibleSpacecraftModel(scenario="solar_rotation").discrete(37.3).A
    np.testing.assert_array_equal(one, two)


def test_identify_task_numbers_do_not_depend_on_the_callers_threads():
    kw = {"method": "rigid-flexible", "seed": 3, "order": 22, "n_samples": 700,
          "convergence_s": 55.0}
    with threadpool_limits(limits=2, user_api="blas"):
        two = identify_task(**kw)["metrics"]
    with threadpool_limits(limits=1, user_api="blas"):
        one = identify_task(**kw)["metrics"]
    assert one == two and one["vaf_h10_rate"] is not None


# ----------------------------------------------------------------- one bad sample
IDENTIFIERS = {
    "default": lambda: default_identifier(),
    "improved": lambda: ImprovedRPBSID(22, 15, 0.98, input_scale=np.ones(3),
                                       output_scale=STANDARD_OUTPUTS.scales()),
    "classical": lambda: ClassicalRPBSID(22, 15, 0.999, input_scale=np.ones(3),
                                         output_scale=STANDARD_OUTPUTS.scales()),
    "predictor": lambda: PredictorRPBSID(22, 15, 0.999, input_scale=np.ones(3),
                                         output_scale=STANDARD_OUTPUTS.scales()),
}


@pytest.mark.parametrize("name", sorted(IDENTIFIERS))
def test_one_huge_finite_sample_is_skipped_not_learned(record, name):
    u, y = record
    y = y.copy()
    y[700, 2] = 1e154
    ident = IDENTIFIERS[name]()
    for k in range(1000):
        ident.update(u[k], y[k])
    assert ident.n_skipped == 1
    assert np.all(np.isfinite(ident.model.A)) and np.all(np.isfinite(ident.state))


@pytest.mark.parametrize("name", ["default", "classical"])
def test_outlier_guard_keeps_a_million_fold_outlier_out(record, name):
    u, y = record
    y = y.copy()
    y[700, 8] *= 1e6                       # finite, within max_abs, absurd for the channel
    make = {"default": lambda: default_identifier(),
            "classical": lambda: ClassicalRPBSID(22, 15, 0.999, outlier_threshold=100.0,
                                                 input_scale=np.ones(3),
                                                 output_scale=STANDARD_OUTPUTS.scales())}
    ident = make[name]()
    for k in range(1500):
        ident.update(u[k], y[k])
    assert ident.n_outliers == 1
    assert np.abs(np.linalg.eigvals(ident.model.A)).max() < 1.01


def test_no_excitation_at_all_never_raises():
    ident = default_identifier()
    for _ in range(800):                    # exactly at rest: no information, no warm-up
        ident.update(np.zeros(3), np.zeros(10))
    assert ident.model is None and ident.n_idle == 799
    quiet = 1e-9 * np.random.default_rng(0).normal(size=(800, 10))
    for q in quiet:                         # zero torque, outputs at the 1e-9 level
        ident.update(np.zeros(3), q)
    assert ident.model is not None and np.all(np.isfinite(ident.model.A))


def test_data_near_the_float_limit_do_not_overflow_the_automatic_scale(record):
    u, y = record
    ident = MomentRefitRPBSID(22, 15, 0.999)          # no scales: taken from the data
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in range(600):
            ident.update(u[k] * 1e200, y[k] * 1e200)
    assert ident.n_skipped == 0 and np.all(np.isfinite(ident.model.A))


class _SensorDropouts(gym.ObservationWrapper):
    """Replaces the first attitude channel by NaN on the given steps."""

    def __init__(self, env: gym.Env, steps: set[int]) -> None:
        super().__init__(env)
        self.steps, self.k = steps, 0

    def reset(self, **kwargs):
        self.k = 0
        return super().reset(**kwargs)

    def step(self, action):
        self.k += 1
        return super().step(action)

    def observation(self, observation):
        if self.k in self.steps:
            observation = observation.copy()
            observation[0] = np.nan
        return observation


def test_features_wrapper_feeds_every_sample_and_the_identifier_counts_nans():
    env = IdentifiedModelFeatures(_SensorDropouts(gym.make("FlexibleSpacecraftDocking-v2"),
                                                  {100, 200, 300}))
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(400):
        env.step(rng.uniform(-0.2, 0.2, 3).astype(np.float32))
    ident = env.identifier
    assert ident.n_samples == 400          # every (u_k, y_k) pair up to the last step
    assert ident.n_skipped == 3            # the dropouts are counted, not lost


def test_adaptive_lqg_feeds_nan_samples_to_the_identifier():
    env = FlexibleSpacecraftEnv("docking")
    ctrl = AdaptiveLQG(env, identifier=fast_identifier(env))
    obs, info = env.reset(seed=0)
    ctrl.reset(0)
    for k in range(50):
        if k % 10 == 5:
            obs = obs.copy()
            obs[3] = np.nan
        obs, _, _, _, info = env.step(ctrl.act(obs, info))
    # 49 of 50 samples: the last waits for the torque applied after it (next step)
    assert ctrl.identifier.n_samples == 49 and ctrl.identifier.n_skipped == 5


# ----------------------------------------------------------------- sweeps
def test_a_second_driver_on_the_same_directory_stops_at_once(tmp_path):
    config = SweepConfig.from_dict({"task": "identify", "seeds": 1,
                                    "params": {"method": "moment-refit-rpbsid", "n_samples": 600,
                                               "convergence_s": 55.0}})
    with FileLock(tmp_path / ".sweep.lock"):
        with pytest.raises(SweepLockedError, match="another sweep is running"):
            run_sweep(config, tmp_path, "serial", progress=False)
    assert not (tmp_path / "results.jsonl").exists()


def test_malformed_result_lines_are_treated_like_torn_ones(tmp_path):
    store = ResultStore(tmp_path / "results.jsonl")
    good = {"task_id": "a", "kind": "identify", "params": {"seed": 0}, "status": "ok",
            "metrics": {"v": 1.0}}
    store.append(good)
    with open(store.path, "ab") as fh:
        fh.write(b'{"task_id": "b", "kind": "identify", "params": {"seed": 1}, "x": "\xff"}\n')
        fh.write(b'{"task_id": "c", "status": "ok"}\n')        # no params, no metrics
    with pytest.warns(RuntimeWarning, match="incomplete"):
        assert set(store.load()) == {"a"}
    with pytest.warns(RuntimeWarning, match="moved 2"):
        assert store.repair() == 2
    assert set(store.load()) == {"a"}
    summary = summarize(tmp_path)                         # no KeyError
    assert summary["records"] == 1


def test_custom_task_kinds_need_permission_and_are_not_imported_without_it(tmp_path):
    marker = tmp_path / "imported"
    module = tmp_path / "side_effect_tasks.py"
    module.write_text(f"open({str(marker)!r}, 'w').close()\n"
                      "def task(*, seed): return {'metrics': {}}\n")
    cfg = tmp_path / "s.toml"
    cfg.write_text('task = "side_effect_tasks:task"\nseeds = 1\n')
    sys.path.insert(0, str(tmp_path))
    try:
        with pytest.raises(ValueError, match="allow-custom-tasks"):
            load_config(cfg)
        assert not marker.exists()
        with pytest.raises(SystemExit):
            main(["sweep", "--config", str(cfg), "--out", str(tmp_path / "o"), "--dry-run"])
        assert not marker.exists()
        load_config(cfg, allow_custom_tasks=True)
        assert marker.exists()
    finally:
        sys.path.remove(str(tmp_path))


# ----------------------------------------------------------------- command line
@pytest.mark.parametrize("argv", [
    "control --seeds 0", "control --seeds -3", "identify --seeds -1", "demo --steps -10",
    "demo --seed -5", "sweep --config /no/such.toml --out results/x",
    "sweep --config configs/smoke.toml --out /dev/null/x", "rl-table /no/such/dir",
    "identify --methods foo", "identify --snr-db -7000", "control --max-torque 1e308",
    "identify --forgetting 1.5"])
def test_cli_rejects_bad_values_with_a_one_line_error(argv):
    proc = subprocess.run([sys.executable, "-m", "spacecraft_lab.cli", *argv.split()],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "error:" in proc.stderr.splitlines()[-1]


def test_cli_help_shows_defaults_and_version(capsys):
    with pytest.raises(SystemExit):
        main(["control", "--help"])
    text = capsys.readouterr().out
    assert "(default: 10)" in text and "--torque-weight" in text
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.startswith("spacecraft ")


# ----------------------------------------------------------------- constructors and solvers
def test_forgetting_errors_name_the_parameter_the_user_gave():
    with pytest.raises(ValueError, match=r"^forgetting must be in \(0, 1\], got 1.5"):
        ImprovedRPBSID(22, forgetting=1.5)
    with pytest.raises(ValueError, match="varx_forgetting must be in"):
        MomentRefitRPBSID(22, varx_forgetting=0.0)
    with pytest.raises(ValueError, match="output_forgetting must be in"):
        PredictorRPBSID(22, output_forgetting=0.0)


def test_dlqr_validates_shapes_and_stabilizability():
    with pytest.raises(ValueError, match=r"B must have shape \(2, m\)"):
        dlqr(np.eye(2), np.array([0.0, 1.0]), np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match=r"B must have shape \(2, m\).*\(3, 1\)"):
        dlqr(np.eye(2), np.ones((3, 1)), np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match="closed loop"):
        dlqr(np.eye(2), np.array([[0.0], [1.0]]), np.diag([0.0, 1.0]), np.eye(1))


def test_state_space_model_validates_dt_and_initial_state():
    args = (np.eye(2), np.ones((2, 1)), np.ones((1, 2)), np.zeros((1, 1)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="dt"):
        StateSpaceModel(*args, dt=np.inf)
    with pytest.raises(ValueError, match=r"x0 must have shape \(2,\)"):
        StateSpaceModel(*args).simulate(np.zeros((5, 1)), x0=np.zeros(3))


@pytest.mark.parametrize(("kwargs", "error"), [
    ({"snr_db": -7000.0}, ValueError), ({"randomize": "no"}, TypeError),
    ({"max_torque": 1e308}, ValueError)])
def test_env_rejects_values_that_used_to_overflow_or_coerce(kwargs, error):
    with pytest.raises(error):
        FlexibleSpacecraftEnv("docking", **kwargs)


def test_env_bounds_the_initial_rate():
    env = FlexibleSpacecraftEnv("constant")
    with pytest.raises(ValueError, match="initial_rate"):
        env.reset(seed=0, options={"initial_rate": [1.0, 0.0, 0.0]})     # 57 deg/s
