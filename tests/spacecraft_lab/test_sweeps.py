"""Monte-Carlo sweeps: config files, resumable results, backends, summaries."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from spacecraft_lab.cli import main
from spacecraft_lab.control import control_task
from spacecraft_lab.identification import identify_task
from spacecraft_lab.paper import PAPER_TABLE5
from spacecraft_lab.sweeps import (
    ResultStore,
    SweepConfig,
    execute,
    load_config,
    make_backend,
    pending_tasks,
    run_sweep,
    summarize,
)

ROOT = Path(__file__).resolve().parents[2]

#: A small identify + control grid: every number a function of the task.
TINY_IDENTIFY = {
    "name": "tiny", "task": "identify", "seeds": 2,
    "params": {"scenario": "docking", "n_samples": 700, "convergence_s": 55.0},
    "grid": {"method": ["rigid-flexible", "improved-rpbsid"]},
    "cases": [{"label": "n22", "order": 22}],
}
TINY_CONTROL = {
    "name": "tiny-control", "task": "control", "seeds": [3, 4],
    "params": {"scenario": "docking", "max_steps": 300},
    "grid": {"controller": ["pd", "adaptive-lqg"]},
}


def _affine(**over) -> SweepConfig:
    data = {"name": "affine", "task": "sweep_tasks:affine", "seeds": 4,
            "grid": {"slope": [1.0, 2.0]}, **over}
    return SweepConfig.from_dict(data, allow_custom_tasks=True)


def _metrics(out: Path) -> dict[str, dict]:
    return {k: r["metrics"] for k, r in ResultStore(out / "results.jsonl").load().items()}


# --- configuration ---------------------------------------------------------------------------

def test_shipped_sweep_files_parse():
    table5 = load_config(ROOT / "configs" / "table5.toml")
    assert len(table5.tasks()) == 6 * 4 * 30  # cases x orders x runs
    assert {t.params["order"] for t in table5.tasks()} == {22, 30, 38, 46}
    # the references in the file are the paper's Table 5 as the code records it
    refs = {r.row: {int(k): v for k, v in r.values.items()} for r in table5.summary.reference}
    assert refs == PAPER_TABLE5
    assert len(load_config(ROOT / "configs" / "docking_mass.toml").tasks()) == 120
    assert len(load_config(ROOT / "configs" / "smoke.toml").tasks()) == 8


def test_toml_yaml_json_give_the_same_tasks(tmp_path):
    toml = tmp_path / "s.toml"
    toml.write_text('task = "identify"\nseeds = {start = 5, count = 2}\n[params]\nsnr_db = 30.0\n'
                    '[grid]\nmethod = ["improved-rpbsid", "classical-rpbsid"]\norder = [22, 30]\n')
    yaml_file = tmp_path / "s.yaml"
    yaml_file.write_text("task: identify\nseeds: {start: 5, count: 2}\nparams: {snr_db: 30.0}\n"
                         "grid:\n  method: [improved-rpbsid, classical-rpbsid]\n"
                         "  order: [22, 30]\n")
    json_file = tmp_path / "s.json"
    json_file.write_text(json.dumps({"task": "identify", "seeds": [5, 6],
                                     "params": {"snr_db": 30.0},
                                     "grid": {"method": ["improved-rpbsid", "classical-rpbsid"],
                                              "order": [22, 30]}}))
    ids = [[t.task_id for t in load_config(f).tasks()] for f in (toml, yaml_file, json_file)]
    assert len(ids[0]) == 8 and ids[0] == ids[1] == ids[2]
    assert load_config(toml).name == "s"


def test_task_ids_are_stable_and_ignore_labels():
    a = SweepConfig.from_dict({"task": "identify", "seeds": [0],
                               "cases": [{"label": "x", "method": "improved-rpbsid"}]}).tasks()[0]
    b = SweepConfig.from_dict({"task": "identify", "seeds": [0],
                               "params": {"method": "improved-rpbsid"}}).tasks()[0]
    assert a.task_id == b.task_id
    # a hash of canonical JSON, so results files stay resumable across versions
    blob = '{"kind":"identify","params":{"method":"improved-rpbsid","seed":0}}'
    assert a.task_id == hashlib.sha1(blob.encode()).hexdigest()[:16]
    assert a.label == "x" and b.label is None


@pytest.mark.parametrize(("data", "match"), [
    ({"task": "identify", "seeds": 2, "bogus": 1}, "unknown top-level"),
    ({"task": "identify"}, "needs 'task' and 'seeds'"),
    ({"task": "identify", "seeds": 2, "params": {"method": "improved-rpbsid", "ordr": 22}},
     "takes no parameter"),
    ({"task": "identify", "seeds": 2}, "needs parameter"),
    ({"task": "identify", "seeds": 2, "params": {"method": "improved-rpbsid", "seed": 1}}, "seed"),
    ({"task": "identify", "seeds": 2, "params": {"method": "improved-rpbsid", "snr_db": 10.0},
      "grid": {"snr_db": [5.0, 10.0]}}, "also set"),
    ({"task": "identify", "seeds": 2, "params": {"method": "improved-rpbsid"},
      "grid": {"snr_db": []}}, "non-empty"),
    ({"task": "identify", "seeds": 0, "params": {"method": "improved-rpbsid"}}, "positive"),
    ({"task": "identify", "seeds": [1, 1], "params": {"method": "improved-rpbsid"}}, "distinct"),
    ({"task": "identify", "seeds": [-1], "params": {"method": "improved-rpbsid"}}, "non-negative"),
    ({"task": "nope", "seeds": 1}, "unknown task kind"),
    ({"task": "nowhere.module:fn", "seeds": 1}, "cannot import"),
    ({"task": "identify", "seeds": 1, "cases": [{"method": "improved-rpbsid", "label": "a"},
                                                 {"method": "improved-rpbsid", "label": "b"}]},
     "identical tasks"),
    ({"task": "identify", "seeds": 1,
      "params": {"method": "improved-rpbsid", "snr_db": float("nan")}}, "finite"),
    ({"task": "identify", "seeds": 1, "params": {"method": "improved-rpbsid"},
      "summary": {"colums": "order"}}, "unknown keys"),
    ({"task": "identify", "seeds": 1, "params": {"method": "improved-rpbsid"},
      "summary": {"reference": [{"row": "a"}]}}, "needs row, metric"),
])
def test_bad_configs_raise_before_running(data, match):
    with pytest.raises((ValueError, TypeError), match=match):
        SweepConfig.from_dict(data, allow_custom_tasks=True)


def test_bad_files(tmp_path):
    bad = tmp_path / "s.ini"
    bad.write_text("x")
    with pytest.raises(ValueError, match=r"must be \.toml"):
        load_config(bad)
    broken = tmp_path / "s.toml"
    broken.write_text("task = identify\n")  # unquoted string
    with pytest.raises(ValueError, match="cannot parse"):
        load_config(broken)
    with pytest.raises(ValueError, match="seeds"):
        SweepConfig.from_dict({"task": "identify", "seeds": "3"})


# --- the result file -------------------------------------------------------------------------

def test_store_survives_a_torn_last_line(tmp_path):
    store = ResultStore(tmp_path / "r.jsonl")
    head = {"kind": "k", "params": {"seed": 0}}
    store.append({"task_id": "a", **head, "status": "ok", "metrics": {"v": 1}})
    store.append({"task_id": "b", **head, "status": "error"})
    with open(store.path, "a") as fh:
        fh.write('{"task_id": "c", "status": "o')  # killed mid-write
    with pytest.warns(RuntimeWarning, match="incomplete record"):
        assert set(store.load()) == {"a", "b"}
    store.append({"task_id": "b", **head, "status": "ok", "metrics": {"v": 2}})  # retried
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("ignore")
        loaded = store.load()
    assert loaded["b"]["status"] == "ok" and set(loaded) == {"a", "b"}
    assert store.path.read_text().count("\n") == 4
    with pytest.raises(ValueError):
        store.append({"task_id": "d", **head, "metrics": {"v": float("nan")}})


# --- execution -------------------------------------------------------------------------------

def test_execute_records_errors_instead_of_raising():
    task = _affine(params={"fail_on": 1}).tasks()[1].to_dict()
    rec = execute(task)
    assert rec["status"] == "error" and "planned failure on seed 1" in rec["error"]
    assert "RuntimeError" in rec["traceback"] and rec["wall_s"] >= 0
    ok = execute(_affine().tasks()[2].to_dict())
    assert ok["status"] == "ok" and ok["metrics"]["value"] == 2.0
    bad = SweepConfig.from_dict({"task": "sweep_tasks:not_a_dict", "seeds": 1},
                                allow_custom_tasks=True).tasks()[0]
    assert "expected" in execute(bad.to_dict())["error"]


def test_identify_task_is_a_pure_function_and_checks_the_order():
    kw = {"method": "rigid-flexible", "seed": 3, "order": 22, "n_samples": 700,
          "convergence_s": 55.0}
    a, b = identify_task(**kw), identify_task(**kw)
    assert a["metrics"] == b["metrics"] and a["metrics"]["order_n"] == 22
    # the long-horizon prediction of a warmed-up model beats 10 s of persistence
    base = identify_task(**kw, baselines=True)["metrics"]
    assert base["vaf_h100_rate"] > base["persistence_vaf_h100_rate"] + 20
    assert base["ceiling_vaf_h100_rate"] > 99.9
    other = identify_task(**{**kw, "seed": 4})
    assert other["metrics"]["vaf_h10_rate"] != a["metrics"]["vaf_h10_rate"]
    with pytest.raises(ValueError, match="6 \\+ 8 k"):
        identify_task(**{**kw, "order": 23})
    with pytest.raises(ValueError, match="unknown method"):
        identify_task(**{**kw, "method": "magic"})


def test_control_task_validates_names():
    with pytest.raises(ValueError, match="controller must be one of"):
        control_task(controller="mpc", seed=0)
    with pytest.raises(ValueError, match="scenario must be one of"):
        control_task(controller="pd", seed=0, scenario="mars")


# --- running, resuming -----------------------------------------------------------------------

def test_errors_are_recorded_and_the_sweep_goes_on(tmp_path):
    config = _affine(params={"fail_on": 2})
    report = run_sweep(config, tmp_path, "serial", progress=False)
    assert (report.total, report.ok, report.errors) == (8, 6, 2)
    text = (tmp_path / "summary.md").read_text()
    assert "planned failure on seed 2" in text and "1 failed" in text
    # a resumed run skips failed tasks unless asked to retry them
    again = run_sweep(config, tmp_path, "serial", progress=False, summarize=False)
    assert again.ran == 0 and again.skipped == 8
    retry = run_sweep(config, tmp_path, "serial", retry_errors=True, progress=False,
                      summarize=False)
    assert retry.ran == 2 and retry.errors == 2


def test_interrupted_sweep_resumes_without_redoing_tasks(tmp_path):
    config = _affine()
    run_sweep(config, tmp_path, "serial", progress=False, summarize=False)
    lines = (tmp_path / "results.jsonl").read_text().splitlines(keepends=True)
    # as if killed while writing the 6th record: 5 complete lines and a torn one
    (tmp_path / "results.jsonl").write_text("".join(lines[:5]) + lines[5][:40])
    with pytest.warns(RuntimeWarning, match="incomplete"):
        todo = pending_tasks(config.tasks(), ResultStore(tmp_path / "results.jsonl"))
    assert len(todo) == 3
    with pytest.warns(RuntimeWarning, match="moved 1 incomplete"):
        report = run_sweep(config, tmp_path, "local", workers=2, progress=False,
                           summarize=False)
    assert (report.ran, report.skipped) == (3, 5)
    assert (tmp_path / "results.jsonl.torn").read_text() == lines[5][:40] + "\n"
    records = ResultStore(tmp_path / "results.jsonl").load()  # clean again: no warning
    assert len(records) == 8 and all(r["status"] == "ok" for r in records.values())
    # extending the grid runs only the new tasks
    report = run_sweep(_affine(seeds=6), tmp_path, "serial", progress=False,
                       summarize=False)
    assert (report.ran, report.skipped) == (4, 8)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


# SIGKILL (no clean-up in the driver: the workers must notice alone) in the default run;
# SIGTERM (the driver unwinds as on Ctrl-C, which test_reliability's d12 tests cover)
# behind -m slow, 8 s for the default run's budget
@pytest.mark.parametrize("sig", [pytest.param(signal.SIGTERM, marks=pytest.mark.slow),
                                 signal.SIGKILL])
def test_killed_driver_leaves_no_workers_and_resumes(tmp_path, sig):
    cfg = tmp_path / "slow.toml"
    cfg.write_text('task = "sweep_tasks:sleepy"\nseeds = 8\n[params]\nduration = 0.5\n')
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parent)}
    proc = subprocess.Popen([sys.executable, "-m", "spacecraft_lab.cli", "sweep", "--config",
                             str(cfg), "--out", str(out), "--workers", "2",
                             "--allow-custom-tasks"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    results = out / "results.jsonl"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (
            not results.exists() or results.read_text().count("\n") < 2):
        time.sleep(0.1)
    proc.send_signal(sig)
    proc.wait(timeout=20)
    done = ResultStore(results).load()
    assert 2 <= len(done) < 8
    pids = {r["timings"]["pid"] for r in done.values()}
    deadline = time.monotonic() + 10  # workers notice a dead driver within ~1 s
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.2)
    assert not any(_alive(p) for p in pids)
    config = load_config(cfg, allow_custom_tasks=True)
    report = run_sweep(config, out, "local", workers=2, progress=False, summarize=False)
    assert report.skipped == len(done) and report.ran == 8 - len(done)


def test_a_dead_worker_fails_its_task_not_the_sweep(tmp_path):
    config = SweepConfig.from_dict({"task": "sweep_tasks:affine", "seeds": 3, "cases": [
        {"label": "ok"}, {"label": "crash", "task": "sweep_tasks:crash"}]},
        allow_custom_tasks=True)
    report = run_sweep(config, tmp_path, "local", workers=2, progress=False, summarize=False)
    records = ResultStore(tmp_path / "results.jsonl").load()
    assert len(records) == 6 and report.ran == 6
    crashed = [r for r in records.values() if r["label"] == "crash"]
    assert all(r["status"] == "error" and "BrokenProcessPool" in r["error"] for r in crashed)
    assert report.errors >= 3


def test_local_pool_matches_serial_bit_for_bit(tmp_path):
    config = SweepConfig.from_dict(TINY_IDENTIFY)
    run_sweep(config, tmp_path / "serial", "serial", progress=False, summarize=False)
    run_sweep(config, tmp_path / "local", "local", workers=2, progress=False, summarize=False)
    a, b = _metrics(tmp_path / "serial"), _metrics(tmp_path / "local")
    assert len(a) == 4 and a == b
    pids = {r["pid"] for r in ResultStore(tmp_path / "local" / "results.jsonl")}
    assert len(pids) >= 1 and all(r["backend"] == "local"
                                  for r in ResultStore(tmp_path / "local" / "results.jsonl"))


@pytest.mark.slow       # 31 s, most of it starting Ray; the local pool is checked above
def test_local_and_ray_backends_give_identical_numbers(tmp_path):
    """The issue's check: one grid (identify and control tasks) on a local
    process pool and on a local Ray instance with 2 CPUs."""
    pytest.importorskip("ray")
    for data in (TINY_IDENTIFY, TINY_CONTROL):
        config = SweepConfig.from_dict(data)
        run_sweep(config, tmp_path / "local" / config.name, "local", workers=2,
                  progress=False, summarize=False)
    with make_backend("ray", workers=2) as backend:
        assert backend.workers == 2
        for data in (TINY_IDENTIFY, TINY_CONTROL):
            config = SweepConfig.from_dict(data)
            # run_sweep's backend and this one share the Ray instance
            run_sweep(config, tmp_path / "ray" / config.name, "ray", progress=False,
                      summarize=False)
    for name in ("tiny", "tiny-control"):
        local, ray_ = _metrics(tmp_path / "local" / name), _metrics(tmp_path / "ray" / name)
        assert len(local) == 4 and local == ray_
        records = list(ResultStore(tmp_path / "ray" / name / "results.jsonl"))
        assert all(r["status"] == "ok" and r["backend"] == "ray" for r in records)
    control = _metrics(tmp_path / "local" / "tiny-control")
    assert all(np.isfinite(m["attitude_rms_deg"]) for m in control.values())


# --- summary ---------------------------------------------------------------------------------

def test_summary_statistics_match_closed_form(tmp_path):
    config = _affine(params={"offset": 1.0}, summary={
        "columns": "slope", "metrics": ["value", "even", "time_s"], "ratio_to": "all",
        "reference": [{"row": "all", "metric": "value", "source": "paper",
                       "values": {"1.0": 2.5, "2.0": 4.0}}]})
    run_sweep(config, tmp_path, "serial", progress=False)
    summary = json.loads((tmp_path / "summary.json").read_text())
    cell = summary["table"]["value"]["all"]["2.0"]  # 2 * seed + 1 over seeds 0..3
    values = 2.0 * np.arange(4) + 1.0
    assert cell["mean"] == pytest.approx(values.mean())
    assert cell["std"] == pytest.approx(values.std(ddof=1))
    assert (cell["median"], cell["min"], cell["max"], cell["count"]) == (4.0, 1.0, 7.0, 4)
    assert summary["table"]["even"]["all"]["1.0"]["mean"] == 0.5
    md = (tmp_path / "summary.md").read_text()
    assert "| all (paper) | 2.5 | 4 |" in md
    assert "Ratio of means" in md.split("## time_s")[1]  # timings only
    assert "Ratio of means" not in md.split("## time_s")[0]
    rows = (tmp_path / "summary.csv").read_text().splitlines()
    assert rows[0] == "label,offset,slope,metric,count,finite,errors,mean,std,median,min,max"
    assert len(rows) == 1 + 2 * 3
    value_row = next(r for r in rows[1:] if ",2.0,value," in r).split(",")
    assert value_row[:6] == ["", "1.0", "2.0", "value", "4", "4"]
    assert float(value_row[7]) == pytest.approx(values.mean())
    assert (tmp_path / "summary.png").stat().st_size > 10_000


def test_summary_counts_nonfinite_and_ignores_stale_records(tmp_path):
    config = _affine(seeds=[98, 99])
    run_sweep(config, tmp_path, "serial", progress=False, summarize=False)
    ResultStore(tmp_path / "results.jsonl").append(
        {"task_id": "stale", "kind": "sweep_tasks:affine", "params": {"seed": 7},
         "status": "ok", "metrics": {"value": 1e9}})
    summary = summarize(tmp_path)
    cell = summary["table"]["value"]["slope=1.0"] if "slope=1.0" in summary["table"]["value"] \
        else summary["table"]["value"]["all"]["1.0"]
    assert summary["ignored_records"] == 1
    assert cell["count"] == 2 and cell["finite"] == 1 and cell["mean"] == 98.0
    assert "1 non-finite" in (tmp_path / "summary.md").read_text()


def test_summary_of_an_empty_directory_raises(tmp_path):
    with pytest.raises(ValueError, match="no results"):
        summarize(tmp_path)


# --- command line ----------------------------------------------------------------------------

def test_cli_sweep_dry_run_run_and_summary(tmp_path, capsys):
    cfg = tmp_path / "affine.yaml"
    cfg.write_text("task: 'sweep_tasks:affine'\nseeds: 3\ngrid: {slope: [1.0, 3.0]}\n")
    out = tmp_path / "out"
    allow = "--allow-custom-tasks"
    assert main(["sweep", "--config", str(cfg), "--out", str(out), "--dry-run", allow]) == 0
    assert "6 tasks, 0 done, 6 to run" in capsys.readouterr().out
    assert main(["sweep", "--config", str(cfg), "--out", str(out), "--backend", "serial",
                 allow]) == 0
    text = capsys.readouterr().out
    assert "6 tasks run (6 ok, 0 failed)" in text and "## value" in text
    assert main(["sweep-summary", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["sweep", "--config", str(cfg), "--out", str(out), "--backend", "mpi", allow])


def test_make_backend_validates():
    with pytest.raises(ValueError, match="backend must be one of"):
        make_backend("slurm")
    with pytest.raises(ValueError, match="workers must be a positive integer"):
        make_backend("local", workers=0)


def test_summary_of_diverged_magnitudes_stays_strict_json(tmp_path):
    """Diverged identifiers report errors near 1e300: no overflow warning, no
    Infinity in the JSON."""
    run_sweep(_affine(grid={"slope": [1e300]}), tmp_path, "serial", progress=False)
    text = (tmp_path / "summary.json").read_text()
    (row,) = json.loads(text)["table"]["value"].values()  # one group: one cell
    (cell,) = row.values()
    assert "Infinity" not in text and cell["std"] is None and cell["max"] == 3e300


@pytest.mark.slow
def test_ray_cluster_address_with_shipped_code(tmp_path):
    """A separately started cluster (``ray start --head``), joined by address
    with the code uploaded, gives the local pool's numbers."""
    pytest.importorskip("ray")
    ray_cli = Path(sys.executable).with_name("ray")
    env = {**os.environ, "RAY_ADDRESS": ""}
    subprocess.run([str(ray_cli), "start", "--head", "--num-cpus", "2",
                    "--include-dashboard", "false", "--disable-usage-stats"],
                   check=True, env=env, capture_output=True, timeout=120)
    try:
        config = SweepConfig.from_dict(TINY_IDENTIFY)
        run_sweep(config, tmp_path / "local", "local", workers=2, progress=False,
                  summarize=False)
        report = run_sweep(config, tmp_path / "cluster", "ray", address="auto",
                           ship_code=True, progress=False, summarize=False)
        assert report.ok == 4 and report.workers == 2
        assert _metrics(tmp_path / "local") == _metrics(tmp_path / "cluster")
    finally:
        subprocess.run([str(ray_cli), "stop", "--force"], env=env, capture_output=True,
                       timeout=120)


@pytest.mark.parametrize("backend", ["serial", "local"])
def test_a_task_over_its_time_limit_is_recorded_and_the_sweep_goes_on(tmp_path, backend):
    config = SweepConfig.from_dict({"task": "sweep_tasks:sleepy", "seeds": 2, "timeout_s": 0.5,
                                    "grid": {"duration": [0.05, 30.0]}},
                                   allow_custom_tasks=True)
    start = time.monotonic()
    report = run_sweep(config, tmp_path, backend, workers=2, progress=False, summarize=False)
    assert time.monotonic() - start < 20  # the 30 s tasks were cut at 0.5 s
    records = ResultStore(tmp_path / "results.jsonl").load().values()
    slow = [r for r in records if r["params"]["duration"] == 30.0]
    assert report.ok == 2 and report.errors == 2
    assert all("TimeoutError: task exceeded its 0.5 s limit" in r["error"] for r in slow)
    assert all(r["wall_s"] < 5 for r in slow)
    # the limit is not part of a task's identity: same ids with another limit
    relaxed = SweepConfig.from_dict({"task": "sweep_tasks:sleepy", "seeds": 2,
                                     "grid": {"duration": [0.05, 30.0]}},
                                    allow_custom_tasks=True)
    assert [t.task_id for t in relaxed.tasks()] == [t.task_id for t in config.tasks()]
    with pytest.raises(ValueError, match="timeout_s"):
        SweepConfig.from_dict({"task": "sweep_tasks:sleepy", "seeds": 1, "timeout_s": 0},
                              allow_custom_tasks=True)


def test_summary_plot_reads_without_raw_keys_empty_panels_or_runaway_axes(tmp_path):
    """Readable titles with units, no panel for an all-zero metric, and a diverged run
    drawn at the axis bound instead of stretching it to 1e221."""
    from spacecraft_lab.sweeps.config import SummarySpec
    from spacecraft_lab.sweeps.summary import _plot

    def cell(mean, median=None):
        return {"mean": mean, "median": mean if median is None else median, "std": 0.1}

    table = {
        "time_s": {"a": {"22": cell(1.0), "30": cell(2.0)}, "b": {"22": cell(1.5),
                                                                   "30": cell(2.5)}},
        "test_error_attitude_pct": {"a": {"22": cell(5.0), "30": cell(-1e221, 6.0)},
                                    "b": {"22": cell(4.0), "30": cell(7.0)}},
        "vaf_h100_rate": {"a": {"22": cell(0.0), "30": cell(0.0)},
                          "b": {"22": cell(0.0), "30": cell(0.0)}},
    }
    summary = {"metrics": list(table), "table": table, "row_names": ["a", "b"],
               "column_names": ["22", "30"], "columns": "order", "sweep": "t"}
    path = tmp_path / "summary.png"
    _plot(path, summary, SummarySpec())
    assert path.stat().st_size > 5000
    # rebuild the figure's axes to inspect them
    import matplotlib.image

    assert matplotlib.image.imread(path).shape[1] > 500
    from matplotlib.figure import Figure

    captured = {}
    original = Figure.savefig

    def spy(self, *args, **kwargs):
        captured["axes"] = [ax for ax in self.axes if ax.get_visible()]
        return original(self, *args, **kwargs)

    Figure.savefig = spy
    try:
        _plot(path, summary, SummarySpec())
    finally:
        Figure.savefig = original
    titles = [ax.get_title() for ax in captured["axes"]]
    assert len(titles) == 2                                   # the all-zero metric dropped
    assert titles[0] == "run time (s)"
    assert titles[1].startswith("test-response error, attitude (%)")
    low, high = captured["axes"][1].get_ylim()
    assert low > -1e5 and high < 1e5


def test_summary_plot_draws_at_most_five_rows_and_bars_within_the_observed_range(tmp_path):
    """``[summary] plot_rows`` picks the rows the figure draws (at most five, the title
    says how many of how many); a share's std bar never reaches below its smallest value."""
    from spacecraft_lab.sweeps.config import SummarySpec
    from spacecraft_lab.sweeps.summary import _plot

    rows = [f"m{i}" for i in range(7)]
    share = {"mean": 0.1, "median": 0.0, "std": 0.3, "min": 0.0, "max": 1.0}
    table = {"nonfinite": {r: {"22": dict(share), "30": dict(share)} for r in rows}}
    summary = {"metrics": ["nonfinite"], "table": table, "row_names": rows,
               "column_names": ["22", "30"], "columns": "order", "sweep": "t"}
    fig = _plot(tmp_path / "a.png", summary, SummarySpec())
    (ax,) = [a for a in fig.axes if a.get_visible()]
    assert len(ax.containers) == 5 and "5 of 7 rows drawn" in fig.get_suptitle()
    assert ax.get_title() == "runs that overflowed (share)"
    for container in ax.containers:           # errorbar: (line, caps, bar collections)
        segments = container.lines[2][0].get_segments()
        assert min(seg[:, 1].min() for seg in segments) >= 0.0 - 1e-12
    picked = _plot(tmp_path / "b.png", summary, SummarySpec(plot_rows=("m6", "m1")))
    (ax,) = [a for a in picked.axes if a.get_visible()]
    assert sorted(c.get_label() for c in ax.containers) == ["m1", "m6"]
    assert len(picked.legends) == 1 and ax.get_legend() is None
    with pytest.raises(TypeError, match="plot_rows"):
        SummarySpec.from_dict({"plot_rows": [f"r{i}" for i in range(6)]})
