"""Faults that used to degrade a run silently (D1-D14 of the reliability issue): each
test reproduces one and checks what happens now."""

from __future__ import annotations

import functools
import json
import os
import re
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from threadpoolctl import threadpool_info

import spacecraft_lab.control as control_job
from controllers import AdaptiveLQG, fast_identifier
from identifiers import (
    ClassicalRPBSID,
    ImprovedRPBSID,
    MomentRefitRPBSID,
    PredictorRPBSID,
    WindowedPBSID,
    add_measurement_noise,
    default_identifier,
    h_step_predictions,
    identification_inputs,
    prediction_vaf,
)
from identifiers.core.health import IdentifierHealthWarning, _estimators, _positive_definite
from identifiers.core.model_sequence import ModelSequence
from identifiers.core.rls import RecursiveLeastSquares
from spacecraft_conventions import STANDARD_OUTPUTS
from spacecraft_env import FlexibleSpacecraftEnv, FlexibleSpacecraftModel
from spacecraft_lab.cli import main
from spacecraft_lab.sweeps import ResultStore, SweepConfig, load_config, summarize
from spacecraft_lab.sweeps.runner import pending_tasks

ROOT = Path(__file__).resolve().parents[1]
SCALES = {"input_scale": np.ones(3), "output_scale": STANDARD_OUTPUTS.scales()}


def _cli(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spacecraft_lab.cli", *argv],
                          capture_output=True, text=True, cwd=ROOT, timeout=timeout)


def _one_line_error(proc: subprocess.CompletedProcess) -> None:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "error:" in proc.stderr.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def multisine():
    """1 N m multisine on the LTI plant, 40 dB: inputs, noisy and clean outputs."""
    truth = FlexibleSpacecraftModel(scenario="constant")
    rng = np.random.default_rng(0)
    u = identification_inputs(3000, rng)
    y_clean = truth.simulate(u)[1]
    return u, add_measurement_noise(y_clean, 40, rng), y_clean


# ----------------------------------------------------------------- D1
def _fallback_tail(fault: str, seed: int) -> tuple[float, AdaptiveLQG]:
    env = FlexibleSpacecraftEnv("paddle_rotation")
    ctrl = AdaptiveLQG(env, identifier=fast_identifier(env))
    obs, info = env.reset(seed=seed)
    ctrl.reset(seed)
    flown = []
    for k in range(2000):
        obs = obs.copy()
        if fault == "all" and k == 600:
            obs[:] = np.nan
        if fault == "rate" and 600 <= k < 700:
            obs[4] = np.nan
        before = ctrl.stats["fallback_steps"]
        obs, _, _, _, info = env.step(ctrl.act(obs, info))
        flown.append(ctrl.stats["fallback_steps"] - before)
    return float(np.mean(flown[-1000:])), ctrl


@functools.cache
def _clean_fallback_tail(seed: int) -> float:
    """The fault-free run's share, flown once for both D1 tests."""
    return _fallback_tail("none", seed)[0]


def _d1_gaps(fault: str) -> list[float]:
    gaps = []
    for seed in range(3):
        clean = _clean_fallback_tail(seed)
        share, ctrl = _fallback_tail(fault, seed)
        gaps.append(abs(share - clean))
        assert np.isfinite(ctrl._err2) and np.isfinite(ctrl._sig2)
        assert all(np.all(np.isfinite(x)) and np.all(np.isfinite(r)) for x, r, _ in ctrl._past)
        assert ctrl.stats["nonfinite_observations"] == {"all": 1, "rate": 100}[fault]
    return gaps


def test_d1_a_nan_observation_leaves_no_trace_in_the_adaptive_loop():
    # fallback share over the last 100 s against the clean run's, median over three seeds
    assert np.median(_d1_gaps("all")) <= 0.05


def test_d1_ten_seconds_without_a_rate_channel_leave_no_trace():
    assert np.median(_d1_gaps("rate")) <= 0.05


# ----------------------------------------------------------------- D2
def _vaf_10s(models: ModelSequence, u: np.ndarray, y_clean: np.ndarray, start: int) -> np.ndarray:
    v = prediction_vaf(y_clean, h_step_predictions(models, u, (100,)), start)[100]
    return np.array([v[:3].mean(), v[3:6].mean(), v[6:].mean()])


def _tail(seq: ModelSequence, first: int) -> ModelSequence:
    return ModelSequence(seq.A[first:], seq.B[first:], seq.C[first:], seq.D[first:],
                         seq.K[first:], seq.valid[first:], seq.dt, seq.consistent_basis,
                         states=seq.states[first:])


def test_d2_a_dead_sensor_stretch_does_not_shut_the_identifier_off():
    # 1000 all-zero samples, then good data: update never raises, and 100 s after the
    # good data start the 10 s-ahead VAF is within 1 point of a run without the zeros
    # (median over three records)
    truth = FlexibleSpacecraftModel(scenario="constant")
    gaps = []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        u = identification_inputs(2500, rng)
        y_clean = truth.simulate(u)[1]
        y = y_clean + 0.01 * STANDARD_OUTPUTS.scales() * rng.normal(size=y_clean.shape)
        clean = default_identifier().fit(u, y)
        ident = default_identifier()
        faulty = ident.fit(np.vstack([np.zeros((1000, 3)), u]),
                           np.vstack([np.zeros((1000, 10)), y]))
        assert ident.health.healthy and ident.n_idle == 999
        gaps.append(_vaf_10s(clean, u, y_clean, 1000)
                    - _vaf_10s(_tail(faulty, 1000), u, y_clean, 1000))
    assert np.all(np.median(gaps, axis=0) <= 1.0), gaps


IDENTIFIERS = {
    "default": lambda: default_identifier(),
    "improved": lambda: ImprovedRPBSID(22, **SCALES),
    "improved-paper": lambda: ImprovedRPBSID.paper(22, **SCALES),
    "classical": lambda: ClassicalRPBSID(22, **SCALES),
    "predictor": lambda: PredictorRPBSID(22, **SCALES),
    "moment-refit": lambda: MomentRefitRPBSID(22, **SCALES),
    "windowed": lambda: WindowedPBSID(22, 15, window=400, refit_every=50, **SCALES),
}


@pytest.mark.parametrize("name", sorted(IDENTIFIERS))
def test_d2_update_never_raises_on_data_of_the_right_shape(multisine, name):
    u, y, _ = multisine
    rng = np.random.default_rng(3)
    junk = [np.nan, np.inf, -np.inf, 0.0, 1e300, -1e-300]
    ident = IDENTIFIERS[name]()
    for k in range(1200):
        uk, yk = u[k].copy(), y[k].copy()
        if 400 <= k < 700 and rng.random() < 0.3:
            yk[rng.integers(10)] = junk[rng.integers(len(junk))]
        if 700 <= k < 800:
            uk[:], yk[:] = 0.0, 0.0
        if 900 <= k < 950 and rng.random() < 0.5:
            uk[rng.integers(3)] = junk[rng.integers(len(junk))]
        ident.update(uk, yk)
    model = ident.model
    assert model is None or all(np.all(np.isfinite(m)) for m in (model.A, model.B, model.C))


# ----------------------------------------------------------------- D3
def _warm(make, multisine, n: int = 700):
    u, y, _ = multisine
    ident = make()
    for k in range(n):
        ident.update(u[k], y[k])
    return ident


def _covariances_positive(ident) -> bool:
    return all(_positive_definite(e.P) for e in _estimators(ident)
               if isinstance(e, RecursiveLeastSquares))


def test_d3_an_indefinite_covariance_is_found_rolled_back_and_counted(multisine):
    u, y, _ = multisine
    ident = _warm(lambda: ImprovedRPBSID(22, **SCALES), multisine)
    good = ident.health.last_good_sample
    ident._gamma._q[0, 0] = -5.0                      # what rounding did on the long run
    for k in range(700, 800):
        ident.update(u[k], y[k])
    health = ident.health
    assert health.rollbacks == 1 and health.restarts == 0 and health.healthy
    assert "not positive definite" in health.last_fault
    assert health.last_good_sample == good == 700        # the copy it returned to
    assert _covariances_positive(ident) and np.all(np.isfinite(ident.model.A))


@pytest.mark.parametrize("name", ["improved", "default"])
def test_d3_a_non_finite_state_is_rolled_back_at_once(multisine, name):
    u, y, _ = multisine
    ident = _warm(IDENTIFIERS[name], multisine)
    state = ident._kf.x if name == "default" else ident._x
    state[:] = np.inf                                 # an overflow in the state
    ident.update(u[700], y[700])
    assert ident.health.rollbacks == 1 and "not finite" in ident.health.last_fault
    assert np.all(np.isfinite(ident.state)) and np.all(np.isfinite(ident.model.A))


def test_d3_a_rollback_restores_the_last_good_copy_each_time(multisine):
    u, y, _ = multisine
    ident = _warm(IDENTIFIERS["default"], multisine)          # checked and copied at 700
    gains = [rls.theta.copy() for _, _, rls in ident._fits]
    first_sample = ident._history[0]
    for k in (700, 701):                               # twice to the same copy
        ident._kf.x[:] = np.nan
        ident.update(u[k], y[k])
        assert [np.array_equal(rls.theta, g) for (_, _, rls), g in
                zip(ident._fits, gains, strict=True)] == [True] * len(gains)
    assert ident.health.rollbacks == 2 and ident.health.last_good_sample == 700
    # the kept record is a new container of the same (never changed) samples
    assert ident._history[0] is first_sample and ident._history is not ident._good[1][1]["_history"]
    assert np.all(np.isfinite(ident.state))


@pytest.mark.parametrize("name", ["classical", "moment-refit", "predictor"])
def test_d3_a_non_finite_estimate_is_rolled_back(multisine, name):
    u, y, _ = multisine
    ident = _warm(IDENTIFIERS[name], multisine)
    ident._varx.theta[0, 0] = np.nan                  # what an overflow leaves behind
    for k in range(700, 800):
        ident.update(u[k], y[k])
    assert ident.health.rollbacks == 1 and "not finite" in ident.health.last_fault
    assert np.all(np.isfinite(ident._varx.theta)) and np.all(np.isfinite(ident.model.A))


def test_d3_with_no_good_copy_the_identifier_restarts_and_says_so(multisine):
    u, y, _ = multisine
    ident = _warm(lambda: ImprovedRPBSID(22, warmup=100, **SCALES), multisine, 150)
    ident._good = None                                # as if no check had passed yet
    ident._x[:] = np.nan
    ident.update(u[150], y[150])
    assert not ident.health.healthy and ident.health.restarts == 1
    with pytest.warns(IdentifierHealthWarning, match="restarted its estimator"):
        assert ident.model is None
    for k in range(151, 500):
        ident.update(u[k], y[k])
    assert ident.health.healthy and np.all(np.isfinite(ident.model.A))


@pytest.mark.slow
def test_d3_improved_rpbsid_survives_100k_samples():
    truth = FlexibleSpacecraftModel(scenario="constant")
    rng = np.random.default_rng(7)
    u = identification_inputs(100_000, rng)
    y = add_measurement_noise(truth.simulate(u)[1], 40, rng)
    ident = ImprovedRPBSID(22, **SCALES)
    for k in range(len(u)):
        ident.update(u[k], y[k])
    assert ident.health.healthy and ident.health.restarts == 0
    assert ident.health.last_good_sample == 100_000
    assert _covariances_positive(ident) and np.all(np.isfinite(ident.model.A))


# ----------------------------------------------------------------- D4
def _markov(model, count: int = 100) -> np.ndarray:
    out, x = [], model.B
    for _ in range(count):
        out.append(model.C @ x)
        x = model.A @ x
    return np.array(out)


def _outlier_distance(make, multisine, magnitude: float) -> tuple[float, int]:
    u, y, _ = multisine
    clean, faulty = make(), make()
    bad = y.copy()
    bad[1000, 0] += magnitude * STANDARD_OUTPUTS.scales()[0]
    for k in range(1800):
        clean.update(u[k], y[k])
        faulty.update(u[k], bad[k])
    ref = _markov(clean.model)
    return float(np.linalg.norm(_markov(faulty.model) - ref) / np.linalg.norm(ref)), \
        faulty.n_outliers


@pytest.mark.parametrize("name", ["default", "classical", "predictor"])
@pytest.mark.parametrize("magnitude", [1e2, 1e4])
def test_d4_one_outlier_is_rejected_by_default(multisine, name, magnitude):
    distance, outliers = _outlier_distance(IDENTIFIERS[name], multisine, magnitude)
    assert outliers == 1 and distance < 0.01, distance


@pytest.mark.parametrize("name", [
    pytest.param("improved", marks=pytest.mark.xfail(strict=True, reason=(
        "not converged: a 1e-6 x nominal change of one sample moves its Markov parameters "
        "by about 7 %, one sample left out by about 13 %"))),
    pytest.param("moment-refit", marks=pytest.mark.xfail(strict=True, reason=(
        "not converged (Markov parameters 50 % from the truth's): one sample left out, as "
        "a NaN or as an outlier, moves them by 1.7 %")))])
def test_d4_one_outlier_leaves_the_unconverged_methods_within_1_percent(multisine, name):
    distance, outliers = _outlier_distance(IDENTIFIERS[name], multisine, 1e3)
    assert outliers == 1
    assert distance < 0.01


@pytest.mark.parametrize("name", ["improved", "moment-refit"])
def test_d4_the_unconverged_methods_reject_the_outlier_and_stay_stable(multisine, name):
    u, y, _ = multisine
    bad = y.copy()
    bad[1000, 0] += 1e3 * STANDARD_OUTPUTS.scales()[0]
    ident = IDENTIFIERS[name]()
    for k in range(1800):
        ident.update(u[k], bad[k])
    assert ident.n_outliers == 1
    assert np.abs(np.linalg.eigvals(ident.model.A)).max() < 1.01


def test_d4_a_lasting_shift_is_learned_not_rejected_for_ever(multisine):
    # a plant that changes is not an outlier: after a short run of rejections the
    # guard follows the data again
    u, y, _ = multisine
    ident = ClassicalRPBSID(22, **SCALES)
    shifted = y.copy()
    shifted[1000:, 6:] *= 3.0                          # the deflection sensors' gain triples
    for k in range(1500):
        ident.update(u[k], shifted[k])
    assert 1 <= ident.n_outliers <= 5


# ----------------------------------------------------------------- D5 / D6
GOOD = {"kind": "identify", "status": "ok", "metrics": {"vaf_h10_rate": 99.0}}


@pytest.mark.parametrize("record", [
    {**GOOD, "metrics": {"vaf_h10_rate": "abc"}},
    {**GOOD, "metrics": {"vaf_h10_rate": [1, 2]}},
    {**GOOD, "metrics": {}},
    {**GOOD, "params": {"seed": "5"}},
    {**GOOD, "status": "done"},
    {**GOOD, "timings": {"time_s": "slow"}},
])
def test_d5_d6_a_wrong_typed_record_is_torn_and_its_task_runs_again(tmp_path, record):
    config = SweepConfig.from_dict({"task": "identify", "seeds": 2, "params": {
        "method": "moment-refit-rpbsid", "n_samples": 600, "convergence_s": 55.0}})
    tasks = config.tasks()
    store = ResultStore(tmp_path / "results.jsonl")
    store.append({"task_id": tasks[0].task_id, "params": tasks[0].params, **GOOD})
    store.append({"task_id": tasks[1].task_id, "params": tasks[1].params, **record})
    with pytest.warns(RuntimeWarning, match="skipping an incomplete record"):
        todo = pending_tasks(tasks, store)
    assert [t.task_id for t in todo] == [tasks[1].task_id]           # re-run, not finished
    with pytest.warns(RuntimeWarning, match="skipping an incomplete record"):
        summary = summarize(tmp_path)                                # never crashes
    assert summary["records"] == 1 and summary["skipped_lines"] == 1
    assert "1 lines that are not complete records skipped" in \
        (tmp_path / "summary.md").read_text()
    with pytest.warns(RuntimeWarning, match="moved 1"):
        assert store.repair() == 1


def test_d6_a_control_records_own_types_are_accepted(tmp_path):
    store = ResultStore(tmp_path / "results.jsonl")
    store.append({"task_id": "a", "kind": "control", "params": {"seed": 1}, "status": "ok",
                  "metrics": {"attitude_rms_deg": 0.1, "verdict": "stable", "stable": True,
                              "settling_s": [12.0, None], "return": None}})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert set(store.load()) == {"a"}


# ----------------------------------------------------------------- D7 - D9
def _sweep_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


def test_d7_a_scored_window_inside_the_warm_up_fails_before_any_task(tmp_path):
    path = _sweep_file(tmp_path, 'task = "identify"\nseeds = 2\n[params]\n'
                                 'method = "rigid-flexible"\nconvergence_s = 20.0\n')
    with pytest.raises(ValueError, match="warm-up"):
        load_config(path)
    proc = _cli("sweep", "--config", str(path), "--out", str(tmp_path / "o"))
    _one_line_error(proc)
    assert "warm-up (50 s)" in proc.stderr
    assert not (tmp_path / "o" / "results.jsonl").exists()


@pytest.mark.parametrize("seeds", ['"abc"', "true", "{start = 0}", "[1, 1]", "2.5"])
def test_d8_a_bad_seeds_entry_is_a_one_line_error(tmp_path, seeds):
    path = _sweep_file(tmp_path, f'task = "identify"\nseeds = {seeds}\n[params]\n'
                                 'method = "moment-refit-rpbsid"\n')
    _one_line_error(_cli("sweep", "--config", str(path), "--out", str(tmp_path / "o"),
                         "--dry-run"))


def test_d9_the_task_count_is_bounded_before_anything_is_listed(tmp_path):
    path = _sweep_file(tmp_path, 'task = "identify"\nseeds = {start = 0, count = 100000000}\n'
                                 '[params]\nmethod = "moment-refit-rpbsid"\n')
    start = time.perf_counter()
    proc = _cli("sweep", "--config", str(path), "--out", str(tmp_path / "o"), "--dry-run")
    _one_line_error(proc)
    assert "100,000,000 tasks" in proc.stderr and "--max-tasks" in proc.stderr
    small = _sweep_file(tmp_path, 'task = "identify"\nseeds = 20\n[params]\n'
                                  'method = "moment-refit-rpbsid"\n')
    with pytest.raises(ValueError, match="more than the limit of 10"):
        load_config(small, max_tasks=10)
    assert len(load_config(small, max_tasks=20).tasks()) == 20
    assert time.perf_counter() - start < 60        # a bound, not a benchmark


# ----------------------------------------------------------------- D10 / D11
def test_d10_step_before_reset_is_a_clear_error():
    env = FlexibleSpacecraftEnv("docking")
    with pytest.raises(gym.error.ResetNeeded, match="before reset"):
        env.step(np.zeros(3, dtype=np.float32))


@pytest.mark.parametrize("reward", ["cost", "bounded"])
def test_d11_stepping_past_termination_warns_once_and_pays_nothing(reward):
    env = FlexibleSpacecraftEnv("constant", reward=reward, task="regulation")
    env.reset(seed=0, options={"initial_rate": [0.05, 0.0, 0.0]})     # ~3 deg/s: out in 7 s
    terminated, steps = False, 0
    while not terminated:
        _, r_end, terminated, _, _ = env.step(np.zeros(3, dtype=np.float32))
        steps += 1
    assert steps < 200
    with pytest.warns(UserWarning, match="already returned terminated = True") as caught:
        after = [env.step(np.zeros(3, dtype=np.float32)) for _ in range(5)]
    assert len(caught) == 1
    assert all(r == 0.0 and term for _, r, term, _, _ in after)
    if reward == "cost":
        assert r_end < -1e4                              # the penalty, once


# ----------------------------------------------------------------- D12 - D14
def test_d12_an_interrupted_comparison_writes_the_completed_seeds(tmp_path, monkeypatch,
                                                                   capsys):
    calls = {"n": 0}
    real = control_job.compare.__globals__["run_episode"]

    def interrupted(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 5:                 # two controllers: seeds 0 and 1 are complete
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setitem(control_job.compare.__globals__, "run_episode", interrupted)
    with pytest.raises(SystemExit) as stop:       # in this process, where the patch holds
        main(["control", "--seeds", "5", "--controllers", "pd", "fixed-lqg", "--steps", "150",
              "--workers", "1", "--out", str(tmp_path)])
    assert stop.value.code == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("spacecraft control: interrupted; wrote")
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["seeds"] == 2 and metrics["seeds_requested"] == 5
    assert all(row["runs"] == 2 for row in metrics["controllers"].values())
    assert (tmp_path / "table.md").read_text().startswith("Interrupted: 2 of 5 seeds")


def test_d12_ctrl_c_prints_one_line_and_exits_130(tmp_path):
    # a shell's background job inherits an ignored SIGINT, and Python then installs no
    # KeyboardInterrupt handler: give the child the default disposition, as a terminal does
    proc = subprocess.Popen([sys.executable, "-m", "spacecraft_lab.cli", "control", "--seeds",
                             "1000", "--controllers", "pd", "--steps", "100", "--out",
                             str(tmp_path)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    buffer = ""
    # the progress bar has counted a seed: the pool is up and the driver waits on it. An
    # interrupt sent as the bar first appeared once ended with status 0 in a loaded full
    # run (not reproduced in 6 tries alone); interrupting during the pool's start-up is
    # left to a test of its own
    while not re.search(r"\b[1-9]\d*/1000\b", buffer):
        char = proc.stderr.read(1)
        assert char, "the command ended before it started its work"
        buffer += char
    os.kill(proc.pid, signal.SIGINT)
    _, rest = proc.communicate(timeout=120)
    assert proc.returncode == 130, rest[-2000:]
    assert "Traceback" not in rest
    assert rest.strip().splitlines()[-1].startswith("spacecraft control: interrupted")


def test_d12_leaving_at_once_after_an_interrupt_leaks_no_semaphore():
    """The interrupt's last resort (a pool thread that cannot be joined: exit at once)
    still unlinks the pool's semaphores: multiprocessing's resource tracker printed a
    "leaked semaphore objects" warning after the interrupted line (1 CI run in about 16;
    the warning came on every such exit while the pool's queues were still referenced)."""
    code = ("import multiprocessing\n"
            "from spacecraft_conventions import exit_now\n"
            "if __name__ == '__main__':\n"
            "    queue = multiprocessing.get_context('spawn').Queue()\n"
            "    queue.put(1)\n"
            "    exit_now(130, 'spacecraft control: interrupted\\n')\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 130
    assert proc.stderr.strip().splitlines() == ["spacecraft control: interrupted"], proc.stderr


def test_d12_a_worker_whose_driver_died_while_it_started_ends_at_once():
    """A ``spawn`` worker imports for seconds before its initializer runs; if the driver
    dies meanwhile (SIGKILL right after the first seed: 1 CI run in several), the worker
    is already re-parented there, so the parent it read then was not its driver and it
    stayed behind. Given the driver's id it ends at once (exit 1, nothing after)."""
    code = ("import os\n"
            "from spacecraft_conventions import exit_with_parent\n"
            "exit_with_parent(parent=os.getpid())   # any id but its parent's\n"
            "print('still running')\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 1 and not proc.stdout and not proc.stderr, proc.stderr


def _children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_d12_a_killed_comparison_leaves_no_worker_behind(tmp_path, sig):
    """``kill`` (SIGTERM: unwinds as Ctrl-C, exit 130) or SIGKILL on a comparison running
    on a process pool: its workers end too (they stayed as orphans before)."""
    proc = subprocess.Popen([sys.executable, "-m", "spacecraft_lab.cli", "control", "--seeds",
                             "1000", "--controllers", "pd", "--steps", "2000", "--workers", "2",
                             "--out", str(tmp_path)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    buffer = ""
    while not re.search(r"\b[1-9]\d*/1000\b", buffer):      # the pool is up and working
        char = proc.stderr.read(1)
        assert char, "the command ended before it started its work"
        buffer += char
    workers = _children(proc.pid)
    assert workers
    os.kill(proc.pid, sig)
    _, rest = proc.communicate(timeout=120)
    if sig == signal.SIGTERM:
        assert proc.returncode == 130
        assert "spacecraft control: interrupted" in rest and "Traceback" not in rest
    deadline = time.monotonic() + 10.0
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(_alive(w) for w in workers)


def test_d13_an_unwritable_out_fails_before_any_work(tmp_path):
    proc = _cli("control", "--out", "/proc/nope", "--seeds", "1", "--controllers", "pd")
    _one_line_error(proc)
    assert "closed loop" not in proc.stderr and "cannot write to --out" in proc.stderr


@pytest.mark.parametrize("argv", [["identify", "--p", "15"], ["control", "--seed", "3"],
                                  ["train", "--time", "10"]])
def test_d14_options_are_never_abbreviated(argv):
    proc = _cli(*argv)
    _one_line_error(proc)
    assert "unrecognized arguments" in proc.stderr


# ----------------------------------------------------------------- threads
@pytest.mark.parametrize("name", sorted(IDENTIFIERS))
def test_every_identifier_runs_single_threaded_blas(multisine, name, monkeypatch):
    # whatever the caller's thread count, the per-sample work runs with one BLAS thread
    # (no wall-clock assertion: benchmarks/bench_threads.py measures the time)
    u, y, _ = multisine
    ident = IDENTIFIERS[name]()
    seen = []
    step = type(ident)._step

    def spy(self, *args, **kwargs):
        seen.append({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})
        return step(self, *args, **kwargs)

    monkeypatch.setattr(type(ident), "_step", spy)
    for k in range(60):
        ident.update(u[k], y[k])
    assert seen and all(threads == {1} for threads in seen)
