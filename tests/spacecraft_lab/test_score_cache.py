"""The disk cache of the comparison controllers' scores."""

from __future__ import annotations

import numpy as np
import pytest

from spacecraft_lab import score_cache, training
from spacecraft_lab.score_cache import CACHE_ENV, ScoreCache, code_fingerprint, default_cache

INPUTS = {"scenario": "docking", "env_kwargs": {"task": "slew", "reward": "bounded"},
          "seeds": [1000, 1001], "controller": "oracle_lqg"}
# what the harness returns: floats of every size, an infinite cost, per-episode lists
SCORE = {"cost_after_100s": 0.1 + 0.2, "cost_after_100s_mean": np.inf,
         "cost_after_100s_per_seed": [3.0e-3, np.inf], "worst_episode_seed": 1001,
         "attitude_rms_deg": 1.2345678901234567e-5, "stable_share": 0.5}


def test_a_stored_score_reads_back_exactly_under_its_inputs_only(tmp_path):
    cache = ScoreCache(tmp_path / "new")              # created on the first write
    assert cache.get(INPUTS) is None
    cache.put(INPUTS, SCORE)
    assert cache.get(INPUTS) == SCORE                 # bit for bit, inf included
    assert [p.suffix for p in (tmp_path / "new").iterdir()] == [".json"]   # no temporary left
    for changed in ({"seeds": [1000]}, {"controller": "fixed_lqg"},
                    {"env_kwargs": {"task": "slew", "reward": "cost"}}):
        assert cache.get({**INPUTS, **changed}) is None
    # key order in the inputs does not matter
    assert cache.get(dict(reversed(list(INPUTS.items())))) == SCORE


def test_a_change_to_the_code_is_a_new_key(tmp_path, monkeypatch):
    cache = ScoreCache(tmp_path)
    cache.put(INPUTS, SCORE)
    monkeypatch.setattr(score_cache, "code_fingerprint", lambda: "edited")
    assert cache.get(INPUTS) is None


def test_the_fingerprint_covers_every_package_file_and_the_library_versions(
        tmp_path, monkeypatch):
    package = tmp_path / "pkg_for_fingerprint"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("x = 1\n")
    (package / "sub" / "data.txt").write_text("table\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(score_cache, "PACKAGES", ("pkg_for_fingerprint",))

    def fingerprint() -> str:
        code_fingerprint.cache_clear()
        return code_fingerprint()

    try:
        before = fingerprint()
        assert len(before) == 64 and fingerprint() == before
        (package / "sub" / "data.txt").write_text("table, edited\n")
        after_edit = fingerprint()
        assert after_edit != before
        (package / "__pycache__").mkdir()
        (package / "__pycache__" / "x.pyc").write_bytes(b"compiled")
        assert fingerprint() == after_edit            # compiled files are not the code
        monkeypatch.setattr(score_cache, "_LIBRARIES", ("numpy", "torch"))
        assert fingerprint() != after_edit
    finally:
        code_fingerprint.cache_clear()        # recomputed after monkeypatch restores


def test_an_unreadable_entry_is_ignored_and_replaced(tmp_path):
    cache = ScoreCache(tmp_path)
    cache.put(INPUTS, SCORE)
    path = tmp_path / f"{cache.key(INPUTS)}.json"
    for text in ("{\"score\": ", "[1, 2]", ""):
        path.write_text(text)
        assert cache.get(INPUTS) is None
    cache.put(INPUTS, SCORE)
    assert cache.get(INPUTS) == SCORE


def test_a_score_that_is_not_json_raises_and_leaves_nothing(tmp_path):
    cache = ScoreCache(tmp_path)
    with pytest.raises(TypeError):
        cache.put(INPUTS, {"cost": object()})
    assert list(tmp_path.iterdir()) == []


def test_the_default_cache_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "mine"))
    assert default_cache().directory == tmp_path / "mine"
    monkeypatch.setenv(CACHE_ENV, "")
    assert default_cache() is None                    # set empty: no cache
    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache().directory == tmp_path / "xdg" / "flexible-spacecraft"


def test_the_comparators_are_scored_once_then_read(tmp_path, monkeypatch, capsys):
    calls = []

    def fake(scenario, env_kwargs, seeds, make):
        calls.append(make)
        return {**SCORE, "cost_after_100s": 0.1 * len(calls)}

    monkeypatch.setattr(training, "_score_comparator", fake)
    cache = ScoreCache(tmp_path)
    kwargs = {"task": "slew", "randomize": False, "reward": "bounded"}
    first = training._score_comparators("docking", kwargs, (1000, 1001), 1, True,
                                        cache=cache)
    assert len(calls) == len(training.COMPARATORS) == len(list(tmp_path.iterdir()))
    second = training._score_comparators("docking", kwargs, (1000, 1001), 1, True,
                                         cache=cache)
    assert len(calls) == len(training.COMPARATORS)    # nothing scored again
    assert second == first and list(second) == list(first)
    assert "all 6 of the 6 comparison controllers' scores" in capsys.readouterr().out
    # one entry lost: only that comparator is scored, the others read
    lost = {"scenario": "docking", "env_kwargs": kwargs, "seeds": [1000, 1001],
            "controller": "fixed_lqg"}
    (tmp_path / f"{cache.key(lost)}.json").unlink()
    third = training._score_comparators("docking", kwargs, (1000, 1001), 1, True,
                                        cache=cache)
    assert len(calls) == len(training.COMPARATORS) + 1
    assert third["fixed_lqg"]["cost_after_100s"] != first["fixed_lqg"]["cost_after_100s"]
    assert {k: v for k, v in third.items() if k != "fixed_lqg"} == {
        k: v for k, v in first.items() if k != "fixed_lqg"}
    assert "The other 5 of the 6" in capsys.readouterr().out
    # other episodes, or no cache: scored
    training._score_comparators("docking", kwargs, (1000,), 1, False, cache=cache)
    training._score_comparators("docking", kwargs, (1000, 1001), 1, False, cache=None)
    assert len(calls) == 3 * len(training.COMPARATORS) + 1


def test_the_no_cache_option_reaches_every_command_that_scores_comparators():
    from spacecraft_lab.cli import build_parser

    parser = build_parser()
    for argv in (["train"], ["evaluate", "agent.zip"], ["adapt", "agent.zip"]):
        assert parser.parse_args(argv).cache is True
        assert parser.parse_args([*argv, "--no-cache"]).cache is False
