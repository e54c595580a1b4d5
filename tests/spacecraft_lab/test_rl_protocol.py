"""The RL evaluation protocol's statistics (rliable): closed-form cases, crashes, seeding,
bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from spacecraft_lab.rl_protocol import (
    MIN_DRAWS,
    improvement_probabilities,
    interval_estimates,
    performance_profiles,
    protocol_table,
    score_matrix,
)

pytest.importorskip("rliable")
RNG = np.random.default_rng(7)
AGENT = RNG.lognormal(0.0, 0.5, (5, 20))        # 5 training seeds x 20 draws
BASE = AGENT.mean(axis=0) * 2.0                  # a deterministic law, twice the agent's mean


def test_the_estimates_are_rliables_aggregates_and_their_intervals_hold_them():
    est = interval_estimates({"agent": AGENT, "base": BASE}, reps=300, seed=1)
    agent = est["agent"]
    assert agent["IQM"][0] == pytest.approx(stats.trim_mean(AGENT.ravel(), 0.25))
    # rliable's median: over the draws, of each draw's mean over the seeds
    assert agent["median"][0] == pytest.approx(np.median(AGENT.mean(axis=0)))
    assert agent["mean"][0] == pytest.approx(AGENT.mean())
    for stat in ("IQM", "median", "mean"):
        point, low, high = agent[stat]
        assert low <= point <= high and low < high
    # seeded: the same intervals again, others with another seed
    assert interval_estimates({"agent": AGENT}, reps=300, seed=1)["agent"] == agent
    assert interval_estimates({"agent": AGENT}, reps=300, seed=2)["agent"] != agent


def test_an_agent_that_always_costs_less_improves_with_probability_one():
    p = improvement_probabilities({"agent": AGENT, "base": BASE * 10}, "agent", ["base"],
                                  reps=100)
    assert p["base"] == (1.0, 1.0, 1.0)
    p = improvement_probabilities({"agent": AGENT, "same": AGENT}, "agent", ["same"],
                                  reps=100)
    assert p["same"][0] == pytest.approx(0.5)
    # one seed against a deterministic law: the draws resampled, an interval that is one
    one = AGENT[0]
    cheaper = np.where(np.arange(one.size) % 2 == 0, one * 0.5, one * 2.0)   # half the draws
    point, low, high = improvement_probabilities({"agent": one, "law": cheaper}, "agent",
                                                 ["law"], reps=200)["law"]
    assert point == pytest.approx(0.5) and low < 0.5 < high
    with pytest.raises(ValueError, match="equal numbers, or one"):
        improvement_probabilities({"a": AGENT, "b": AGENT[:3]}, "a", ["b"])


def test_a_crash_costs_infinity_in_the_mean_not_in_the_iqm():
    crashed = AGENT.copy()
    crashed[0, :3] = np.inf                      # 3 of 100 runs x draws
    est = interval_estimates({"agent": crashed}, reps=200)["agent"]
    assert np.isinf(est["mean"][0]) and np.isfinite(est["IQM"][0])
    assert "inf (crashes)" in protocol_table({"agent": est})


def test_the_profile_is_the_share_at_or_below_each_cost():
    taus = np.array([0.5, 1.0, 2.0])
    share, low, high = performance_profiles({"agent": AGENT}, taus, reps=200)["agent"]
    np.testing.assert_allclose(share, [np.mean(AGENT <= t) for t in taus])
    assert np.all(low <= share) and np.all(share <= high) and np.all(np.diff(share) >= 0)


def test_the_table_flags_what_falls_below_the_protocol():
    est = interval_estimates({"agent": AGENT[:1]}, reps=200)
    text = protocol_table(est, seeds={"agent": 1}, draws=20)
    assert f"20 held-out draws (the protocol asks for >= {MIN_DRAWS})" in text
    assert "fewer than 5 training seeds: agent" in text
    assert "Below the protocol" not in protocol_table(est, seeds={"agent": 5}, draws=50)


@pytest.mark.parametrize("costs, message", [
    (np.zeros((2, 2, 2)), "shape"), ([], "shape"), ([1.0, np.nan], "NaN"),
    ([1.0, -1.0], "negative")])
def test_bad_costs_are_refused(costs, message):
    with pytest.raises(ValueError, match=message):
        score_matrix(costs)


def test_bad_calls_are_refused():
    with pytest.raises(ValueError, match="same draws"):
        interval_estimates({"a": AGENT, "b": BASE[:5]})
    with pytest.raises(ValueError, match="reps must be >= 100"):
        interval_estimates({"a": AGENT}, reps=10)
    with pytest.raises(KeyError, match="no costs for"):
        improvement_probabilities({"a": AGENT}, "a", ["b"])
    with pytest.raises(ValueError, match="increasing"):
        performance_profiles({"a": AGENT}, [2.0, 1.0])
    with pytest.raises(ValueError, match="at least one"):
        interval_estimates({})


def test_numpys_global_generator_is_left_as_it_was():
    """rliable draws from numpy's global generator: seeded inside, restored after."""
    np.random.seed(123)  # noqa: NPY002
    expected = np.random.random()  # noqa: NPY002
    np.random.seed(123)  # noqa: NPY002
    interval_estimates({"agent": AGENT}, reps=100)
    assert np.random.random() == expected  # noqa: NPY002
