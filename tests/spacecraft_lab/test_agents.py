"""Saved agents: loading, evaluation beside the LQGs, the shipped agent, bad input."""

import json
import shutil

import numpy as np
import pytest

from spacecraft_lab.agents import (
    HELD_OUT_SEEDS,
    SHIPPED_AGENTS,
    evaluate_agent,
    evaluation_table,
    load_agent,
)
from spacecraft_lab.cli import main
from spacecraft_lab.training import COMPARATORS, EVAL_SEEDS, _evaluate

SHIPPED = "residual-scheduled-family"


def test_held_out_seeds_are_disjoint_from_training_and_checkpoint_selection():
    assert not set(HELD_OUT_SEEDS) & set(EVAL_SEEDS)
    assert min(HELD_OUT_SEEDS) > max(EVAL_SEEDS)


def test_every_shipped_agent_is_in_the_repository_with_what_it_needs():
    for path in SHIPPED_AGENTS.values():
        assert path.is_file()
        assert path.with_name(f"{path.stem}_vecnormalize.pkl").is_file()
        assert (path.parent / "metrics.json").is_file()


@pytest.mark.parametrize("name, features, repeat, settle", [
    # trained before the integral's settle time was recorded: its base integrates at once
    ("residual-scheduled-family", "residual-scheduled", 2, 0.0),
    ("ars-averaged-family", "attitude-error-averaged", 10, None),      # no base
    ("ars-residual-scheduled-family", "residual-scheduled-averaged", 10, 50.0),
])
def test_each_shipped_agent_flies_as_it_did_when_it_was_trained(name, features, repeat,
                                                                 settle):
    """Loaded from the repository, the agent scores the training run's final evaluation
    episodes exactly as the run recorded them (same policy, same statistics)."""
    pytest.importorskip("stable_baselines3")
    if name.startswith("ars-"):
        pytest.importorskip("sb3_contrib")
    policy, settings = load_agent(name)
    assert settings["features"] == features and settings["repeat"] == repeat
    recorded = json.loads((SHIPPED_AGENTS[name].parent / "metrics.json").read_text())
    expected = recorded["runs"][0]["final"]["cost_after_100s_per_seed"][:2]
    if settle is not None:
        assert settings["base_integral_settle_s"] == settle
    score = _evaluate(policy, settings["scenario"], settings["features"],
                      settings["env_kwargs"], EVAL_SEEDS[:2],
                      base_settle_s=settings["base_integral_settle_s"])
    np.testing.assert_allclose(score["cost_after_100s_per_seed"], expected, rtol=1e-6)


def test_evaluation_scores_the_agent_and_every_comparator_on_the_same_episodes():
    pytest.importorskip("stable_baselines3")
    result = evaluate_agent(SHIPPED, seeds=(2000,), workers=1, progress=False)
    assert result["eval_seeds"] == [2000]
    assert set(result["scores"]) == {"agent"} | {key for key, _ in COMPARATORS}
    mine = result["scores"]["agent"]["cost_after_100s_per_seed"][0]
    for key, _ in COMPARATORS:
        theirs = result["scores"][key]["cost_after_100s_per_seed"][0]
        assert result["agent_over"][key]["median"] == pytest.approx(mine / theirs)
    # the residual flies on its base: within a few percent of it, far below zero torque
    assert 0.5 < result["agent_over"]["scheduled_lqg"]["median"] < 2.0
    assert result["agent_over"]["zero_torque"]["median"] < 0.01
    table = evaluation_table(result)
    assert "| agent |" in table and "| oracle LQG |" in table and "seeds 2000-2000" in table
    # the protocol: intervals, and the probability of beating the base and the adaptive LQG
    assert set(result["protocol"]["estimates"]) == set(result["scores"])
    assert set(result["protocol"]["improvement"]) == {"scheduled_lqg", "adaptive_lqg"}
    assert "| agent | 1 |" in table and "P(agent costs less than scheduled LQG on a draw)" in table
    assert "Below the protocol: 1 held-out draws" in table


def test_cli_evaluate_writes_json_and_table(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    code = main(["evaluate", SHIPPED, "--episodes", "1", "--workers", "1",
                 "--out", str(tmp_path / "ev")])
    assert code == 0
    result = json.loads((tmp_path / "ev" / "evaluation.json").read_text())
    assert result["agent"]["scenario"] == "family" and result["eval_seeds"] == [2000]
    assert (tmp_path / "ev" / "table.md").read_text().startswith("PPO residual-scheduled")
    assert (tmp_path / "ev" / "performance_profiles.png").stat().st_size > 10_000
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["evaluate", "no-such-agent"], "must be a saved model (.zip) or one of"),
    (["evaluate", "/nonexistent/agent.zip"], "no saved model at"),
    (["evaluate", SHIPPED, "--episodes", "0"], "--episodes"),
])
def test_cli_evaluate_refuses_bad_input_in_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_a_model_without_its_record_or_statistics_is_refused(tmp_path):
    source = SHIPPED_AGENTS[SHIPPED]
    shutil.copy(source, tmp_path / source.name)
    with pytest.raises(FileNotFoundError, match="observation statistics"):
        load_agent(tmp_path / source.name)
    shutil.copy(source.with_name(f"{source.stem}_vecnormalize.pkl"), tmp_path)
    with pytest.raises(FileNotFoundError, match=r"no metrics\.json beside it"):
        load_agent(tmp_path / source.name)
    (tmp_path / "metrics.json").write_text(json.dumps({"algo": "ppo"}))
    with pytest.raises(ValueError, match="lacks the training settings"):
        load_agent(tmp_path / source.name)
    record = json.loads((source.parent / "metrics.json").read_text())
    (tmp_path / "metrics.json").write_text(json.dumps({**record, "features": "telepathy"}))
    with pytest.raises(ValueError, match="not ones this version trains"):
        load_agent(tmp_path / source.name)
    # a residual trained with another authority would fly another law than it learnt
    (tmp_path / "metrics.json").write_text(json.dumps({**record, "residual_scale": 0.2}))
    with pytest.raises(ValueError, match=r"residual authority of 0\.2 of full torque"):
        load_agent(tmp_path / source.name)


def test_evaluation_refuses_empty_or_negative_seeds():
    with pytest.raises(ValueError, match="seeds"):
        evaluate_agent(SHIPPED, seeds=())
    with pytest.raises(ValueError, match="seeds"):
        evaluate_agent(SHIPPED, seeds=(-1,))


def test_training_seeds_of_one_setting_are_scored_together():
    """Several models of one setting: the protocol's (training seeds, draws) matrix; the
    agent's row pools them (each draw's mean over the seeds); another setting refused."""
    pytest.importorskip("stable_baselines3")
    result = evaluate_agent([SHIPPED, SHIPPED], seeds=(2000,), workers=1, progress=False)
    assert result["protocol"]["training_seeds"] == 2 and len(result["agent_runs"]) == 2
    one = result["agent_runs"][0]["cost_after_100s_per_seed"]
    assert result["scores"]["agent"]["cost_after_100s_per_seed"] == pytest.approx(one)
    table = evaluation_table(result)
    assert "| agent | 2 |" in table and "the mean over its 2 training seeds" in table
    with pytest.raises(ValueError, match="trained otherwise"):
        evaluate_agent([SHIPPED, "ars-averaged-family"], seeds=(2000,), progress=False)
