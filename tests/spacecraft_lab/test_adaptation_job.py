"""``spacecraft adapt``: one policy flown with the true, estimated and nominal parameters."""

import contextlib
import io
import json

import numpy as np
import pytest

from spacecraft_lab.adaptation import COLLECTION_SEED, SOURCES, adaptation_table, run_adaptation
from spacecraft_lab.agents import HELD_OUT_SEEDS, SHIPPED_AGENTS, load_agent
from spacecraft_lab.cli import main
from spacecraft_lab.training import EVAL_SEEDS, _evaluate, run_training


@pytest.fixture(scope="module")
def privileged_agent(tmp_path_factory):
    """A residual on the scheduled LQG with the truth's parameters observed, one rollout."""
    pytest.importorskip("stable_baselines3")
    out = tmp_path_factory.mktemp("privileged")
    run_training("ppo", "residual-scheduled-privileged", 2048, 1, out, scenario="family",
                 eval_every=10**9, progress=False, reward="cost", eval_seeds=(1000,), workers=1)
    return out / "ppo-residual-scheduled-privileged-seed0.zip"


def test_collection_and_scored_episodes_are_disjoint_from_training_and_selection():
    collection = set(range(COLLECTION_SEED, COLLECTION_SEED + 100))
    assert not collection & set(HELD_OUT_SEEDS) and not collection & set(EVAL_SEEDS)


@pytest.fixture(scope="module")
def adapted(privileged_agent, tmp_path_factory):
    """``spacecraft adapt`` on the agent, one collection and one scored episode: the
    CLI's output directory, the result it holds and what it printed (one run serves
    the tests below)."""
    out = tmp_path_factory.mktemp("rma")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["adapt", str(privileged_agent), "--episodes", "1", "--scored-episodes",
                     "1", "--workers", "1", "--out", str(out)])
    assert code == 0
    return out, json.loads((out / "adaptation.json").read_text()), printed.getvalue()


# the two tests below share a module fixture that trains an agent and runs ``spacecraft
# adapt`` (about 25 s): kept out of the default run (``-m slow``) for its 10-minute budget
@pytest.mark.slow
def test_one_policy_flies_with_each_parameter_source_on_the_same_episodes(privileged_agent,
                                                                         adapted):
    _, result, _ = adapted
    assert result["collection_seeds"] == [COLLECTION_SEED]
    assert result["eval_seeds"] == [HELD_OUT_SEEDS[0]]
    (seed,) = result["eval_seeds"]
    (agent,) = result["agents"]
    assert set(agent["scores"]) == set(SOURCES)
    per = {s: agent["scores"][s]["cost_after_100s_per_seed"][0] for s in SOURCES}
    assert agent["estimated_over_true"]["median"] == pytest.approx(per["estimated"] / per["true"])
    assert agent["nominal_over_estimated"]["median"] == pytest.approx(
        per["nominal"] / per["estimated"])
    # "true" is the env the policy trained and was evaluated on
    policy, settings = load_agent(privileged_agent)
    again = _evaluate(policy, "family", settings["features"], settings["env_kwargs"], (seed,),
                      base_settle_s=settings["base_integral_settle_s"])
    assert per["true"] == pytest.approx(again["cost_after_100s_per_seed"][0], rel=1e-9)
    # the estimate and the identifier's raw vector are scored against the truth
    assert set(agent["errors"]) == {"estimated", "identifier", "nominal"}
    for errors in agent["errors"].values():
        assert all(np.isfinite(v) and v >= 0 for v in errors.values())
    sched = result["comparators"]["scheduled_lqg"]["cost_after_100s_per_seed"][0]
    assert agent["over"]["estimated/scheduled_lqg"]["median"] == pytest.approx(
        per["estimated"] / sched)
    table = adaptation_table(result)
    assert "| true parameters | estimated | nominal |" in table and "| identifier |" in table


def test_a_policy_without_the_privileged_vector_is_refused():
    pytest.importorskip("stable_baselines3")
    with pytest.raises(ValueError, match="trained on the truth's parameters"):
        run_adaptation([SHIPPED_AGENTS["residual-scheduled-family"]], episodes=1,
                       seeds=(2000,), workers=1, progress=False)
    with pytest.raises(ValueError, match="at least one agent"):
        run_adaptation([], progress=False)


@pytest.mark.slow
def test_cli_adapt_writes_json_and_table(adapted):
    out, result, printed = adapted
    assert result["features"] == "residual-scheduled-privileged"
    assert (out / "table.md").read_text().startswith("RMA comparison")
    assert (out / "adaptation.png").stat().st_size > 10_000
    assert "wrote" in printed


def test_paired_rollouts_record_both_vectors_where_the_setting_reads_its_parameters():
    """The adaptation module's pairs on a setting whose agent reads the parameters through
    averaged, scheduled channels (``residual-scheduled-averaged-privileged``): one pair
    per refresh (1 s), the policy flying the truth's vector exactly as in training."""
    from controllers import PrivilegedFeatures, run_episode
    from spacecraft_lab.adaptation import _paired_rollouts
    from spacecraft_lab.training import ZeroTorque, _make_env

    kwargs = {"task": "slew", "reward": "cost", "randomize": True, "max_episode_steps": 600}
    features = "residual-scheduled-averaged-privileged"
    seen = []

    class Spy(ZeroTorque):
        def act(self, obs, info=None):
            seen.append(np.asarray(obs).copy())
            return super().act(obs, info)

    def make(parameters):
        return _make_env("family", features, kwargs, parameters=parameters)

    physical, privileged, times = _paired_rollouts(Spy(), make, (3000,))
    assert physical.shape == privileged.shape == (60, 17) and times.shape == (60,)
    np.testing.assert_allclose(np.diff(times), 1.0)
    assert np.all(privileged[:, -1] == 1.0) and np.all(physical[:5, -1] == 0.0)  # ready
    assert np.all(physical[-1, -1] == 1.0)           # the identifier is warm after 50 s
    np.testing.assert_allclose(times[[0, -1]], [0.0, 59.0])
    # what the policy saw is the training env's observation
    truth = make(PrivilegedFeatures)
    spy_obs = list(seen)
    seen.clear()
    run_episode(truth, Spy(), seed=3000)
    np.testing.assert_allclose(np.array(spy_obs), np.array(seen), rtol=1e-6, atol=1e-9)
