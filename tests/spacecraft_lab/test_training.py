"""The RL training job (stable-baselines3)."""

from __future__ import annotations

import json
import os
import pickle
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from spacecraft_env import env_id
from spacecraft_lab.reporting import load_training_metrics
from spacecraft_lab.training import (
    ACTION_REPEAT,
    FEATURES,
    PPO_MINIBATCH,
    NormalizedPolicy,
    _make_env,
    _one_torch_thread,
    ppo_rollout,
    run_training,
)


def test_training_job_writes_model_curves_and_metrics(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    # SB3's default logger would leave an empty SB3-<date> folder in the temp directory
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    m = run_training("ppo", "none", 2000, 1, tmp_path, eval_every=1000, progress=False,
                     eval_seeds=(1000, 1001))
    assert (tmp_path / "ppo-none-seed0.zip").exists()
    assert not list(scratch.glob("SB3-*"))
    assert (tmp_path / "learning_curves.png").exists()
    # the VecNormalize saved beside the model no longer updates its statistics
    with open(tmp_path / "ppo-none-seed0_vecnormalize.pkl", "rb") as fh:
        assert pickle.load(fh).training is False
    assert m["runs"][0]["curve"] and np.isfinite(m["final_attitude_rms_deg"])
    # the defaults: one decision per ACTION_REPEAT env steps, the bounded reward (returns
    # are then counts of well-held steps: the LQG holds nearly all 2500)
    assert m["repeat"] == ACTION_REPEAT and m["reward"] == "bounded"
    assert m["torch_threads"] == 1
    assert 2000 < m["adaptive_lqg"]["return"] <= 2500
    # curves count env steps, not decisions; the budget is trained exactly (PPO's rollout
    # set from it: 200 decisions x 10 env steps, one update, so no evaluation before it)
    assert m["timesteps_requested"] == 2000 == m["timesteps"] and m["complete"] is True
    # what trained it: the env id and version, the package's version, the commit
    from spacecraft_conventions import __version__

    assert m["provenance"]["env_id"] == env_id("docking")
    assert m["provenance"]["package_version"] == __version__
    commit = m["provenance"]["commit"]
    assert commit is None or len(commit.removesuffix("+dirty")) == 40
    assert m["hyperparameters"]["n_steps"] == 200
    assert [c["timesteps"] for c in m["runs"][0]["curve"]] == [2000]
    assert m["runs"][0]["env_steps"] == 2000
    # SB3's log and the Monitor's episodes are kept beside the run
    assert (tmp_path / "logs" / "ppo-none-seed0" / "progress.csv").exists()
    assert (tmp_path / "monitor" / "ppo-none-seed0-env0.monitor.csv").exists()
    # the final result is the curve's last point, scored on the comparators' episodes
    run = m["runs"][0]
    assert run["final"] == {k: v for k, v in run["curve"][-1].items() if k != "timesteps"}
    assert m["eval_seeds"] == [1000, 1001]
    # the best checkpoint: the curve's point of least mean cost (what the agent minimizes)
    best = min(run["curve"], key=lambda point: point["cost_after_100s_mean"])
    assert run["best_checkpoint"] == {key: best[key] for key in (
        "timesteps", "cost_after_100s_mean", "cost_after_100s")}
    assert (tmp_path / "ppo-none-seed0_best.zip").exists()
    # and it is the saved model's score: the evaluation due at the last rollout's end
    # waits for that rollout's update (the curve has one point per evaluation step)
    from spacecraft_lab.agents import load_agent
    from spacecraft_lab.training import _evaluate

    policy, settings = load_agent(tmp_path / "ppo-none-seed0.zip")
    saved = _evaluate(policy, "docking", "none", settings["env_kwargs"], (1000, 1001))
    assert saved["cost_after_100s_per_seed"] == run["final"]["cost_after_100s_per_seed"]
    steps = [c["timesteps"] for c in run["curve"]]
    assert steps == sorted(set(steps))
    # the comparators' scores are kept for the next run with these settings
    assert len(list(Path(os.environ["SPACECRAFT_CACHE_DIR"]).glob("*.json"))) == 6
    # the learning-speed threshold is on the score (the cost from 100 s), and every mean
    # names its worst episode
    assert m["threshold"] == "cost_after_100s"
    assert m["target_cost_after_100s"] == 2 * m["adaptive_lqg"]["cost_after_100s"]
    reached = [c for c in run["curve"] if c["cost_after_100s"] <= m["target_cost_after_100s"]]
    assert run["steps_to_2x_adaptive"] == (reached[0]["timesteps"] if reached else None)
    fixed_costs = m["fixed_lqg"]["cost_after_100s_per_seed"]
    assert m["fixed_lqg"]["worst_episode_seed"] == [1000, 1001][int(np.argmax(fixed_costs))]
    assert len(run["final"]["cost_after_100s_per_seed"]) == 2
    oracle, fixed = m["oracle_lqg"], m["fixed_lqg"]
    assert 0 < oracle["cost_after_100s"] <= 1.05 * fixed["cost_after_100s"]
    with pytest.raises(ValueError):
        run_training("dqn", "none", 10, 1, tmp_path)
    with pytest.raises(ValueError, match="repeat"):
        run_training("ppo", "none", 10, 1, tmp_path, repeat=0)
    with pytest.raises(ValueError, match="reward"):
        run_training("ppo", "none", 10, 1, tmp_path, reward="sparse")


def test_training_does_not_depend_on_the_callers_torch_threads():
    """run_training trains inside _one_torch_thread: the same bits whatever the caller
    set (unpinned, 1 and 2 threads differ by about 3e-7 after two PPO updates here)."""
    torch = pytest.importorskip("torch")
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    before = torch.get_num_threads()
    params = []
    try:
        for threads in (2, 1):
            torch.set_num_threads(threads)
            with _one_torch_thread(torch):
                venv = DummyVecEnv([lambda: gym.make(env_id("docking"), task="slew")])
                venv.seed(0)
                model = PPO("MlpPolicy", venv, seed=0, n_steps=512, batch_size=128)
                model.learn(1024)
            assert torch.get_num_threads() == threads          # the caller's setting is back
            params.append(torch.cat([p.detach().flatten() for p in model.policy.parameters()]))
    finally:
        torch.set_num_threads(before)
    assert torch.equal(params[0], params[1])


def test_normalized_policy_holds_each_decision_for_repeat_steps():
    class Model:
        calls = 0

        def predict(self, obs, deterministic):
            self.calls += 1
            return np.full((1, 3), 0.1 * self.calls), None

    class Identity:
        def normalize_obs(self, obs):
            return obs

    policy = NormalizedPolicy(Model(), Identity(), "held", repeat=3)
    actions = [round(float(policy.act(np.zeros(13))[0]), 6) for _ in range(7)]
    assert actions == [0.1] * 3 + [0.2] * 3 + [0.3]
    policy.reset(seed=0)                         # a new episode decides at once
    assert round(float(policy.act(np.zeros(13))[0]), 6) == 0.4


@pytest.mark.slow       # 14 s; the optional TensorBoard output
def test_training_logs_monitor_and_evaluation_metrics_to_tensorboard(tmp_path):
    pytest.importorskip("stable_baselines3")
    event_accumulator = pytest.importorskip(
        "tensorboard.backend.event_processing.event_accumulator")
    # randomized docking with the oracle features: short episodes so Monitor closes some
    # one decision per env step: two rollouts of 2048; eval_every far below one rollout:
    # evaluated at the update boundary past it, never before the first update, and
    # every evaluation reaches TensorBoard at its env step
    m = run_training("ppo", "oracle", 4096, 1, tmp_path / "out", eval_every=1000, repeat=1,
                     progress=False, randomize=True, tensorboard=str(tmp_path / "tb"),
                     eval_seeds=(1000,))
    assert m["randomize"] and np.isfinite(m["final_vibration_rms_mm"])
    assert 0.0 <= m["runs"][0]["final"]["stable_share"] <= 1.0
    (run,) = (tmp_path / "tb").iterdir()
    acc = event_accumulator.EventAccumulator(str(run))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    assert {"eval/attitude_rms_deg", "eval/vibration_rms_mm", "eval/return",
            "eval/stable_share"} <= tags
    assert "time/fps" in tags
    curve = m["runs"][0]["curve"]
    assert [c["timesteps"] for c in curve] == [2048, 4096]
    logged = acc.Scalars("eval/cost_after_100s")
    assert [e.step for e in logged] == [c["timesteps"] for c in curve]
    np.testing.assert_allclose([e.value for e in logged],
                               [c["cost_after_100s"] for c in curve], rtol=1e-6)
    # the comparison table and figure read the run back
    from spacecraft_lab.plots import plot_rl_comparison
    from spacecraft_lab.reporting import rl_table

    table = rl_table([tmp_path / "out"])
    assert "| PPO | oracle | randomized docking, bounded reward | 4,096 | 1 |" in table
    assert "| fixed LQG |" in table and "| adaptive LQG, fast identifier |" in table
    assert "| oracle LQG | - | - | - | - |" in table and "| 1.00 |" in table
    assert "| zero torque |" in table
    worst = m["fixed_lqg"]
    assert f"| {worst['worst_episode_seed']}: {worst['cost_after_100s_worst']:.3g} |" in table
    fig = plot_rl_comparison(tmp_path / "cmp.png", [m])
    assert (tmp_path / "cmp.png").stat().st_size > 10_000
    # the figure says the algorithm, keeps its legend off the data, draws the LQGs as
    # reference lines under the agents (oracle, scheduled, adaptive, fixed: the run
    # scored all four), and at most five agent settings
    assert "PPO on randomized docking" in fig.get_suptitle()
    assert len(fig.legends) == 1 and all(ax.get_legend() is None for ax in fig.axes)
    for ax in fig.axes:
        agents = [ln for ln in ax.get_lines() if ln.get_marker() not in (None, "None", "")]
        # (an evaluation that crashed adds the marked "crashed" level, in C3)
        refs = [ln for ln in ax.get_lines() if ln not in agents and ln.get_color() != "C3"]
        assert len(agents) == 1 and len(refs) == 4
        assert min(a.get_zorder() for a in agents) > max(r.get_zorder() for r in refs)
    many = plot_rl_comparison(tmp_path / "many.png", [m] * 7)
    assert "the first 5 of 7 settings" in many.get_suptitle()
    assert sum(1 for ln in many.axes[0].get_lines() if ln.get_marker() != "None") == 5


def test_rl_table_pools_seeds_trained_in_separate_directories(tmp_path):
    from spacecraft_lab.reporting import pooled_training_runs, rl_table

    base = {"algo": "ppo", "features": "none", "scenario": "docking", "randomize": True,
            "timesteps": 1000, "repeat": 10, "reward": "bounded",
            "target_attitude_rms_deg": 2.0,
            **{k: {"attitude_rms_deg": 1.0, "vibration_rms_mm": 1.0, "return": 1.0,
                   "cost_after_100s": cost}
               for k, cost in (("oracle_lqg", 0.01), ("adaptive_lqg", 0.02),
                               ("fixed_lqg", 0.04), ("zero_torque", 1.0))}}

    def run(seed, rms):
        final = {"attitude_rms_deg": rms, "vibration_rms_mm": 1.0, "return": 2.0,
                 "cost_after_100s": 0.01 * rms}
        return {"seed": seed, "final": final, "curve": [], "steps_to_2x_adaptive": None}

    for name, features, seeds in (("a", "none", (0,)), ("b", "none", (1, 2)),
                                  ("c", "oracle", (0,))):
        (tmp_path / name).mkdir()
        m = {**base, "features": features, "runs": [run(s, 3.0 + s) for s in seeds]}
        (tmp_path / name / "metrics.json").write_text(json.dumps(m))
    dirs = [tmp_path / n for n in "abc"]
    pooled = pooled_training_runs(dirs)
    assert [(m["features"], len(m["runs"])) for m in pooled] == [("none", 3), ("oracle", 1)]
    table = rl_table(dirs)
    # cost (median [min, max] over seeds), / oracle, / fixed, then the attitude RMS
    assert ("| PPO | none | randomized docking, bounded reward | 1,000 | 3 "
            "| 0.0400 [0.0300, 0.0500] | 4.00 [3.00, 5.00] | 1.00 [0.75, 1.25] "
            "| 4.00 [3.00, 5.00] |") in table
    assert ("| PPO | oracle | randomized docking, bounded reward | 1,000 | 1 | 0.0300 | 3.00 "
            "| 0.75 | 3.00 |") in table
    assert "| oracle LQG | - | - | - | - | 0.0100 | 1.00 | 0.25 |" in table
    # ARS trains whole iterations of episodes of different lengths: seeds asked for the
    # same env steps train slightly different numbers and are still one setting; a
    # reward counted from another time is another setting
    for name, trained, start in (("d", 1040, 100.0), ("e", 1070, 100.0), ("f", 1040, 0.0)):
        (tmp_path / name).mkdir()
        m = {**base, "algo": "ars", "timesteps": trained, "timesteps_requested": 1000,
             "reward_from_s": start, "runs": [run(0, 3.0)]}
        (tmp_path / name / "metrics.json").write_text(json.dumps(m))
    pooled = pooled_training_runs([tmp_path / n for n in "def"])
    assert [(m.get("reward_from_s"), len(m["runs"])) for m in pooled] == [(100.0, 2), (0.0, 1)]
    assert "bounded reward from 100 s |" in rl_table([tmp_path / n for n in "def"])


def test_rl_table_gives_the_protocols_iqm_with_intervals(tmp_path):
    """Per setting, the agent's seeds x draws and the comparators' draws: IQM, median and
    mean with intervals, and the probability of beating the base and the adaptive LQG."""
    pytest.importorskip("rliable")
    from scipy import stats

    from spacecraft_lab.reporting import rl_protocol_report

    draws = 6
    comparators = {k: {"attitude_rms_deg": 1.0, "vibration_rms_mm": 1.0, "return": 1.0,
                       "cost_after_100s": c, "cost_after_100s_per_seed": [c] * draws}
                   for k, c in (("oracle_lqg", 0.01), ("adaptive_lqg", 0.02),
                                ("fixed_lqg", 0.04), ("zero_torque", 1.0))}
    base = {"algo": "ars", "features": "residual-fixed", "scenario": "family",
            "randomize": False, "timesteps": 1000, "repeat": 10, "reward": "cost",
            "target_cost_after_100s": 0.04, "base_comparator": "fixed_lqg", **comparators}

    def run(seed, cost):
        final = {"attitude_rms_deg": 1.0, "vibration_rms_mm": 1.0, "return": 2.0,
                 "cost_after_100s": cost, "cost_after_100s_per_seed": [cost] * draws}
        return {"seed": seed, "final": final, "curve": [], "steps_to_2x_adaptive": None}

    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "metrics.json").write_text(json.dumps(
        {**base, "runs": [run(0, 0.015), run(1, 0.016), run(2, 0.03)]}))
    text = rl_protocol_report([tmp_path / "a"])
    assert "### ARS residual-fixed on family, 1,000 env steps" in text
    # the IQM of the 3 seeds x 6 draws: the middle half of the 18 costs
    iqm = stats.trim_mean([0.015] * draws + [0.016] * draws + [0.03] * draws, 0.25)
    assert f"| agent | 3 | {iqm:.3g} [" in text
    assert "| fixed LQG | - | 0.04 [0.04, 0.04] |" in text
    # cheaper than its base on every draw and seed; than the adaptive LQG on 2 of 3 seeds
    assert "P(agent costs less than fixed LQG on a draw) = 1.00 [1.00, 1.00]" in text
    assert "P(agent costs less than adaptive LQG, fast identifier on a draw) = 0.67" in text
    assert "Below the protocol: 6 held-out draws" in text
    # files without the per-draw costs are named, not scored
    (tmp_path / "b").mkdir()
    old = {**base, "features": "none", "runs": [run(0, 0.02)]}
    del old["runs"][0]["final"]["cost_after_100s_per_seed"]
    (tmp_path / "b" / "metrics.json").write_text(json.dumps(old))
    assert "not scored by the protocol" in rl_protocol_report([tmp_path / "b"])


def test_evaluation_with_the_identifier_kept_starts_every_episode_with_a_model():
    from spacecraft_lab.training import EVAL_SEEDS, ZeroTorque, _evaluate

    class FirstObservation(ZeroTorque):
        """Zero torque that records the model flag of each episode's first observation."""

        def __init__(self) -> None:
            self.flags: list[float] = []
            self._first = True

        def reset(self, seed: int | None = None) -> None:
            self._first = True

        def act(self, obs, info=None):
            if self._first:
                self.flags.append(float(obs[-1]))
                self._first = False
            return np.full(3, 0.05, dtype=np.float32)

    kwargs = {"task": "slew", "max_episode_steps": 600}
    for features, expected in (("identified", 0.0), ("identified-kept", 1.0)):
        ctrl = FirstObservation()
        score = _evaluate(ctrl, "docking", features, kwargs, seeds=EVAL_SEEDS[:3])
        assert np.isfinite(score["attitude_rms_deg"])
        evaluated = ctrl.flags[-3:]                      # after the warm-up episode, if any
        assert evaluated == [expected] * 3, features
    assert len(ctrl.flags) == 3 + 1


def test_a_silent_residual_agent_scores_exactly_its_base_controller():
    from controllers import FixedLQG
    from spacecraft_lab.training import ZeroTorque, _evaluate

    # 110 s: the common cost is scored from 100 s
    kwargs = {"task": "slew", "randomize": True, "max_episode_steps": 1100}
    base = FixedLQG(gym.make(env_id("docking"), **kwargs).unwrapped)
    alone = _evaluate(base, "docking", "none", kwargs, seeds=(1000, 1001, 1002))
    residual = _evaluate(ZeroTorque(), "docking", "residual-fixed", kwargs,
                         seeds=(1000, 1001, 1002))
    assert residual == alone and np.isfinite(alone["cost_after_100s"])

    class FullResidual(ZeroTorque):
        def act(self, obs, info=None):
            return np.ones(3, dtype=np.float32)

    pushed = _evaluate(FullResidual(), "docking", "residual-fixed", kwargs)
    assert pushed["attitude_rms_deg"] != alone["attitude_rms_deg"]


def test_an_episode_that_leaves_the_bound_before_the_scored_window_costs_infinity():
    """No cost from 100 s exists for it: the evaluation counts it as a failure (inf),
    not as missing, so a median over episodes cannot hide it."""
    from spacecraft_lab.training import ZeroTorque, _evaluate

    class FullTorque(ZeroTorque):
        def act(self, obs, info=None):
            return np.ones(3, dtype=np.float32)

    kwargs = {"task": "slew", "max_episode_steps": 1100}
    score = _evaluate(FullTorque(), "docking", "none", kwargs, seeds=(1000, 1001))
    assert score["cost_after_100s"] == np.inf and score["cost_after_100s_mean"] == np.inf
    assert score["stable_share"] == 0.0


def test_the_comparators_score_the_same_on_a_process_pool():
    from spacecraft_lab.training import _score_comparators

    kwargs = {"task": "slew", "randomize": False, "reward": "bounded",
              "max_episode_steps": 1100}
    serial = _score_comparators("docking", kwargs, (1000, 1001), 1, False)
    pooled = _score_comparators("docking", kwargs, (1000, 1001), 2, False)
    assert list(pooled) == ["adaptive_lqg", "fixed_lqg", "oracle_lqg", "scheduled_lqg",
                            "zero_torque", "window_ceiling"]
    # the window ceiling bounds every comparator's cost from 100 s on every episode
    for key, row in serial.items():
        assert np.all(np.asarray(serial["window_ceiling"]["cost_after_100s_per_seed"])
                      <= np.asarray(row["cost_after_100s_per_seed"]) * 1.0001), key
    for key, row in serial.items():
        assert np.isfinite(row["cost_after_100s_per_seed"]).all()
        np.testing.assert_allclose(pooled[key]["cost_after_100s_per_seed"],
                                   row["cost_after_100s_per_seed"], rtol=1e-9)


def test_a_fresh_residual_flies_exactly_its_base():
    """The residual settings start at their base: the action mean's last layer is zero,
    so the deterministic residual is 0 and the env applies the base's action unchanged;
    exploration is small (log std -3), decisions every 0.2 s, the authority 0.5 N m."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from spacecraft_lab.training import (
        RESIDUAL_HYPERPARAMETERS,
        RESIDUAL_REPEAT,
        RESIDUAL_SCALE,
        _make_env,
        _start_at_the_base,
    )

    env = _make_env("family", "residual-scheduled", {"task": "slew", "reward": "cost"})
    model = PPO("MlpPolicy", env, seed=0, **RESIDUAL_HYPERPARAMETERS["ppo"])
    _start_at_the_base(model)
    obs, _ = env.reset(seed=3)
    for _ in range(50):
        action, _ = model.predict(obs, deterministic=True)
        assert np.all(action == 0)
        obs, _, _, _, info = env.step(action)
        assert np.all(info["residual_action"] == 0) and np.any(info["base_action"] != 0)
    std = model.policy.log_std.exp().detach().numpy()
    assert np.allclose(std, np.exp(-3.0))
    assert RESIDUAL_REPEAT == 2 and env.scale == RESIDUAL_SCALE == 0.05


def test_an_averaged_residual_sees_the_attitude_error_and_rate_its_base_reads_everything():
    """``residual-*-averaged``: the base reads the env's whole observation, the agent the
    attitude error and the rate in nominal units, each averaged over its decision; a
    zero action flies the base alone, and its authority is full torque."""
    from controllers import FixedLQG
    from spacecraft_lab.training import (
        ACTION_REPEAT,
        AVERAGED_RESIDUAL_SCALE,
        ZeroTorque,
        _evaluate,
        residual_scale,
    )

    kwargs = {"task": "slew", "reward": "cost", "max_episode_steps": 1100}
    env = _make_env("family", "residual-fixed-averaged", kwargs)
    assert env.observation_space.shape == (6,) and env.window == ACTION_REPEAT
    assert env.unwrapped.observation_layout.names[-1] == "attitude_error"
    raw = gym.make(env_id("family"), **kwargs, outputs=("attitude_error", "rate"))
    obs, _ = env.reset(seed=4)
    obs_raw, _ = raw.reset(seed=4)
    level = np.array([np.deg2rad(1.0)] * 3 + [np.deg2rad(0.1)] * 3)
    np.testing.assert_allclose(obs, obs_raw / level, rtol=1e-5)
    assert residual_scale("residual-fixed-averaged") == AVERAGED_RESIDUAL_SCALE == 1.0
    assert residual_scale("residual-fixed") == 0.05 and residual_scale("physical") is None
    seeds = (1000, 1001)
    base = _evaluate(FixedLQG, "family", "none", kwargs, seeds=seeds)
    silent = _evaluate(ZeroTorque(), "family", "residual-fixed-averaged", kwargs, seeds=seeds)
    np.testing.assert_allclose(silent["cost_after_100s_per_seed"],
                               base["cost_after_100s_per_seed"], rtol=1e-12)


def test_the_scheduled_averaged_residual_sees_its_state_times_the_parameters():
    """``residual-scheduled-averaged-privileged``: the agent's observation is the averaged
    attitude error and rate, then their products with the truth's rigid-gain channels
    (a linear policy on it is a gain-scheduled law); the parameter wrapper can be
    swapped (the RMA comparison's estimated and nominal vectors), and a setting without
    a parameter vector refuses one."""
    from controllers import PrivilegedFeatures
    from controllers.features import PHYSICAL_FEATURE_NAMES
    from spacecraft_lab.training import SCHEDULE_CHANNELS, ZeroTorque, _evaluate

    kwargs = {"task": "slew", "reward": "cost", "max_episode_steps": 1100}
    features = "residual-scheduled-averaged-privileged"
    plain = _make_env("family", "residual-scheduled-averaged", kwargs)
    appended = []

    def parameters(env, source="truth"):
        appended.append(PrivilegedFeatures(env, source=source))
        return appended[-1]

    env = _make_env("family", features, kwargs, parameters=parameters)
    assert env.observation_space.shape == (6 + 6 * len(SCHEDULE_CHANNELS),)
    action = np.zeros(3, dtype=np.float32)
    cols = [PHYSICAL_FEATURE_NAMES.index(name) for name in SCHEDULE_CHANNELS]
    for obs, x in ((env.reset(seed=5)[0], plain.reset(seed=5)[0]),
                   (env.step(action)[0], plain.step(action)[0])):
        gain = appended[0]._feats[cols]
        assert np.abs(gain).max() > 0.01                     # a draw off the nominal plant
        np.testing.assert_allclose(obs[:6], x, rtol=1e-5)
        np.testing.assert_allclose(obs[6:], np.outer(x, gain).ravel(), rtol=1e-4, atol=1e-6)
    nominal = _make_env("family", features, kwargs,
                        parameters=lambda e: parameters(e, "nominal"))
    obs = nominal.reset(seed=5)[0]
    assert np.abs(obs[6:]).max() == 0.0                      # the nominal gain is the origin
    with pytest.raises(ValueError, match="observe no parameter vector"):
        _make_env("family", "residual-scheduled-averaged", kwargs, parameters=parameters)
    seeds = (1000,)
    silent = _evaluate(ZeroTorque(), "family", features, kwargs, seeds=seeds)
    base = _evaluate(ZeroTorque(), "family", "residual-scheduled-averaged", kwargs, seeds=seeds)
    assert silent["cost_after_100s_per_seed"] == base["cost_after_100s_per_seed"]


def test_the_averaged_residual_with_deflections_sees_them_in_tenths_of_a_metre():
    """``residual-scheduled-averaged-deflection``: the averaged attitude error and rate in
    nominal units, then the tip deflections averaged the same way in units of
    ``AVERAGED_DEFLECTION_LEVEL`` (10 cm); a silent agent flies its base."""
    from spacecraft_lab.training import AVERAGED_DEFLECTION_LEVEL, ZeroTorque, _evaluate

    kwargs = {"task": "slew", "reward": "cost", "max_episode_steps": 1100}
    features = "residual-scheduled-averaged-deflection"
    env = _make_env("family", features, kwargs)
    plain = _make_env("family", "residual-scheduled-averaged", kwargs)
    raw = gym.make(env_id("family"), **kwargs, outputs=("deflection",))
    assert AVERAGED_DEFLECTION_LEVEL == 0.1
    assert env.observation_space.shape == (6 + raw.observation_space.shape[0],)
    action = np.zeros(3, dtype=np.float32)
    obs, x, y = env.reset(seed=5)[0], plain.reset(seed=5)[0], raw.reset(seed=5)[0]
    np.testing.assert_allclose(obs[:6], x, rtol=1e-5)
    np.testing.assert_allclose(obs[6:], y / AVERAGED_DEFLECTION_LEVEL, rtol=1e-5)
    # a decision later: the attitude error and rate are still the plain setting's
    np.testing.assert_allclose(env.step(action)[0][:6], plain.step(action)[0], rtol=1e-5)
    seeds = (1000,)
    silent = _evaluate(ZeroTorque(), "family", features, kwargs, seeds=seeds)
    base = _evaluate(ZeroTorque(), "family", "residual-scheduled-averaged", kwargs, seeds=seeds)
    assert silent["cost_after_100s_per_seed"] == base["cost_after_100s_per_seed"]


def test_the_averaged_residual_on_the_adaptive_lqg_flies_its_base_when_silent():
    """``residual-adaptive-averaged``: the averaged correction on the adaptive LQG of the
    agents (:func:`fast_adaptive_lqg`, its identifier learning in the loop); the agent sees
    the averaged attitude error and rate, and a silent agent flies that base exactly."""
    from spacecraft_lab.training import ZeroTorque, _evaluate, fast_adaptive_lqg

    kwargs = {"task": "slew", "reward": "cost", "max_episode_steps": 1100}
    features = "residual-adaptive-averaged"
    env = _make_env("family", features, kwargs)
    plain = _make_env("family", "residual-scheduled-averaged", kwargs)
    assert env.observation_space.shape == plain.observation_space.shape == (6,)
    np.testing.assert_allclose(env.reset(seed=5)[0], plain.reset(seed=5)[0], rtol=1e-5)
    seeds = (1000,)
    silent = _evaluate(ZeroTorque(), "family", features, kwargs, seeds=seeds)
    base = _evaluate(fast_adaptive_lqg, "family", "none", kwargs, seeds=seeds)
    np.testing.assert_allclose(silent["cost_after_100s_per_seed"],
                               base["cost_after_100s_per_seed"], rtol=1e-9)


def test_an_averaged_setting_decides_once_per_averaging_window(tmp_path):
    pytest.importorskip("sb3_contrib")
    for features in ("attitude-error-averaged", "residual-fixed-averaged"):
        with pytest.raises(ValueError, match="repeat must be 10, got 2"):
            run_training("ars", features, 2048, 1, tmp_path, scenario="family", repeat=2,
                         progress=False)


def test_rl_figure_under_a_cost_reward_shows_the_mean_episode_not_the_slew(tmp_path):
    """A cost reward's return is the whole episode's cost, which the slew dominates
    alike for every policy; the figure's second panel is then the cost from 100 s over
    the mean episode, with the LQGs' means as references."""
    from spacecraft_lab.plots import plot_rl_comparison

    score = {"cost_after_100s": 0.004, "cost_after_100s_mean": 0.009, "return": -25000.0}
    curve = [{"timesteps": t, "cost_after_100s": 0.004 + 1e-4 * i,
              "cost_after_100s_mean": 0.009 + 1e-3 * i, "return": -25000.0}
             for i, t in enumerate((100_000, 200_000))]
    run = {"algo": "ppo", "features": "residual-scheduled", "scenario": "family",
           "randomize": False, "reward": "cost", "runs": [{"curve": curve}],
           **{key: dict(score) for key in ("oracle_lqg", "scheduled_lqg", "adaptive_lqg",
                                           "fixed_lqg")}}
    fig = plot_rl_comparison(tmp_path / "cost.png", [run])
    right = fig.axes[1]
    assert right.get_ylabel() == "cost from 100 s, mean over episodes"
    assert right.get_yscale() == "log"
    agent = next(ln for ln in right.get_lines() if ln.get_marker() not in (None, "None", ""))
    np.testing.assert_allclose(agent.get_ydata(), [0.009, 0.010])
    references = [ln for ln in right.get_lines() if ln is not agent]
    assert len(references) == 4
    assert all(np.allclose(ln.get_ydata(), 0.009) for ln in references)


def test_rl_figure_draws_crashed_evaluations_on_a_marked_level(tmp_path):
    """An evaluation whose median episode left the attitude bound costs infinity; the
    figure draws it on a "crashed" level above every finite value (it used to vanish
    from the log axis and leave a panel of reference lines only)."""
    from spacecraft_lab.plots import plot_rl_comparison

    score = {"cost_after_100s": 0.004, "return": 2400.0}
    curve = [{"timesteps": t, "cost_after_100s": cost, "return": 500.0}
             for t, cost in ((25_000, float("inf")), (50_000, 30.0))]
    run = {"algo": "sac", "features": "none", "scenario": "docking", "randomize": True,
           "reward": "bounded", "runs": [{"curve": curve}],
           **{key: dict(score) for key in ("oracle_lqg", "adaptive_lqg", "fixed_lqg")}}
    fig = plot_rl_comparison(tmp_path / "crash.png", [run])
    left = fig.axes[0]
    agent = next(ln for ln in left.get_lines() if ln.get_marker() not in (None, "None", ""))
    np.testing.assert_allclose(agent.get_ydata(), [300.0, 30.0])     # 10x the largest finite
    assert any("crashed" in t.get_text() for t in left.texts)
    assert not any("crashed" in t.get_text() for t in fig.axes[1].texts)
    lo, hi = left.get_xlim()
    assert lo > 0 and hi > 50_000                                    # the agent's steps


@pytest.mark.slow        # 12 s of training (two env processes): kept out of the default run
def test_training_steps_several_envs_side_by_side_and_reports_its_throughput(tmp_path):
    """--envs 2: a SubprocVecEnv of two processes; PPO collects a rollout of n_steps
    decisions from each (the budget's 400 decisions: 200 each); metrics.json says how
    many envs and how fast training went."""
    pytest.importorskip("stable_baselines3")
    m = run_training("ppo", "none", 4000, 1, tmp_path, eval_every=10**9, progress=False,
                     eval_seeds=(1000,), envs=2, workers=1, log_std_init=-2.5)
    run = m["runs"][0]
    assert m["envs"] == 2
    # the exploration asked for is the one trained with, and recorded
    assert m["hyperparameters"]["policy_kwargs"]["log_std_init"] == -2.5
    assert run["env_steps"] == 4000 == m["timesteps"]
    assert (tmp_path / "monitor" / "ppo-none-seed0-env1.monitor.csv").exists()
    assert run["env_steps_per_s"] > 0
    assert (tmp_path / "ppo-none-seed0.zip").exists()


def test_training_refuses_bad_envs_and_exploration_settings(tmp_path):
    pytest.importorskip("stable_baselines3")
    with pytest.raises(ValueError, match="envs"):
        run_training("ppo", "none", 2048, 1, tmp_path, envs=0, progress=False)
    with pytest.raises(ValueError, match="log_std_init applies to PPO"):
        run_training("sac", "none", 2048, 1, tmp_path, log_std_init=-2.0, progress=False)
    with pytest.raises(ValueError, match=r"log_std_init must be in \[-10, 2\]"):
        run_training("ppo", "none", 2048, 1, tmp_path, log_std_init=float("nan"),
                     progress=False)


@pytest.mark.parametrize(("algo", "envs", "budget", "nearest"), [
    ("ppo", 1, 2048, "2,040, 2,050"), ("sac", 1, 5, "10"), ("ppo", 2, 4010, "4,000, 4,020")])
def test_a_budget_of_part_decisions_is_refused_naming_the_nearest(tmp_path, algo, envs, budget,
                                                                  nearest):
    pytest.importorskip("stable_baselines3")
    with pytest.raises(ValueError, match=f"nearest valid budgets are {nearest}$"):
        run_training(algo, "none", budget, 1, tmp_path, envs=envs, progress=False)
    assert not (tmp_path / "metrics.json").exists()


@pytest.mark.parametrize(("decisions", "envs", "rollout"), [
    (200, 1, (200, 50)), (4096, 1, (2048, 64)), (80_000, 1, (2000, 50)), (100, 2, (100, 50)),
    (30, 1, (30, 30)), (211, 1, (211, 64)), (6144, 3, (2048, 64))])
def test_ppo_rollout_makes_the_budget_whole_rollouts(decisions, envs, rollout):
    n_steps, batch = ppo_rollout(decisions, envs)
    assert (n_steps, batch) == rollout
    assert decisions % n_steps == 0
    assert (n_steps * envs) % batch == 0 or batch == PPO_MINIBATCH     # a prime rollout
    with pytest.raises(ValueError, match="must be >= 1"):
        ppo_rollout(0)


def test_an_unfinished_run_is_refused_by_the_tables(tmp_path):
    """What each evaluation writes while a run trains (``"complete": false``)."""
    m = {"algo": "ppo", "features": "none", "scenario": "docking", "timesteps": 0,
         "complete": False, "runs": [], "in_progress": {"seed": 0, "curve": []}}
    (tmp_path / "metrics.json").write_text(json.dumps(m))
    with pytest.raises(ValueError, match="an unfinished run"):
        load_training_metrics(tmp_path)


@pytest.mark.parametrize("features", FEATURES)
def test_every_training_setting_builds_an_env_whose_observations_fit_its_space(features):
    """Each --features setting's env passes its own space check after a reset and a step
    (the residual settings wrap the base law; -physical / -observed append channels)."""
    env = _make_env("family", features, {"task": "slew", "reward": "cost"})
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs), features
    obs, *_ = env.step(np.zeros(3, dtype=np.float32))
    assert env.observation_space.contains(obs), features
    env.close()


def test_a_base_relative_training_env_pays_a_silent_residual_nothing():
    """``relative_to_base``: the training env's reward is the residual's minus its base's
    on a twin of the same episode, so a zero residual (the base exactly) earns exactly 0
    at every step, on a family draw with sensor noise; the plain env's reward is not 0."""
    pytest.importorskip("stable_baselines3")
    from controllers import BaseRelativeReward
    from spacecraft_lab.training import RESIDUAL_REPEAT, _monitored_env

    kwargs = {"task": "slew", "randomize": False, "reward": "cost"}
    relative = _monitored_env("family", "residual-fixed", kwargs, RESIDUAL_REPEAT, True)
    plain = _monitored_env("family", "residual-fixed", kwargs, RESIDUAL_REPEAT)
    layer, found = relative, False
    while isinstance(layer, gym.Wrapper):
        found |= isinstance(layer, BaseRelativeReward)
        layer = layer.env
    assert found
    for env in (relative, plain):
        env.reset(seed=4)
    zero = np.zeros(3, dtype=np.float32)
    rewards = [(relative.step(zero)[1], plain.step(zero)[1]) for _ in range(40)]
    assert all(r == 0.0 for r, _ in rewards)
    assert all(p < 0.0 for _, p in rewards)


def test_training_relative_to_the_base_needs_a_residual_setting(tmp_path):
    pytest.importorskip("stable_baselines3")
    with pytest.raises(ValueError, match="relative_to_base needs a residual setting"):
        run_training("ppo", "oracle", 2048, 1, tmp_path, relative_to_base=True,
                     progress=False)


def test_rl_table_keeps_base_relative_runs_apart(tmp_path):
    """Equal settings but for the base's reward subtracted are two rows, named so."""
    from spacecraft_lab.reporting import pooled_training_runs, rl_table

    scores = {k: {"attitude_rms_deg": 1.0, "vibration_rms_mm": 1.0, "return": 1.0,
                  "cost_after_100s": cost}
              for k, cost in (("oracle_lqg", 0.01), ("adaptive_lqg", 0.02),
                              ("fixed_lqg", 0.04), ("zero_torque", 1.0))}
    final = {"attitude_rms_deg": 1.0, "vibration_rms_mm": 1.0, "return": 2.0,
             "cost_after_100s": 0.03}
    for name, relative in (("plain", False), ("relative", True)):
        (tmp_path / name).mkdir()
        m = {"algo": "ppo", "features": "residual-fixed", "scenario": "family",
             "randomize": False, "timesteps": 1000, "repeat": 2, "reward": "cost",
             "relative_to_base": relative, "target_cost_after_100s": 0.04, **scores,
             "runs": [{"seed": 0, "final": final, "curve": [], "steps_to_2x_adaptive": None}]}
        (tmp_path / name / "metrics.json").write_text(json.dumps(m))
    dirs = [tmp_path / "plain", tmp_path / "relative"]
    assert len(pooled_training_runs(dirs)) == 2
    table = rl_table(dirs)
    assert "| residual-fixed | family, cost reward |" in table
    assert "| residual-fixed | family, cost reward minus the base's |" in table


@pytest.mark.slow        # ~40 s: a residual and its twin trained for one rollout
def test_training_relative_to_the_base_records_it_and_the_base(tmp_path):
    pytest.importorskip("stable_baselines3")
    m = run_training("ppo", "residual-fixed", 4096, 1, tmp_path, scenario="family",
                     reward="cost", eval_every=10**9, progress=False, eval_seeds=(1000,),
                     workers=1, relative_to_base=True)
    assert m["relative_to_base"] is True and m["base_comparator"] == "fixed_lqg"
    # one rollout, one update: the saved agent is scored, next to its base's score
    run = m["runs"][0]
    assert run["env_steps"] == 4096 and len(run["curve"]) == 1
    assert np.isfinite(run["final"]["cost_after_100s"])
    assert np.isfinite(m["fixed_lqg"]["cost_after_100s"])


def _short_paired_ars(seeds_seen: list | None = None, seed: int = 0):
    """A paired ARS on 30-step docking episodes (attitude error and rate in nominal units),
    its env recording the seed of every reset."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from spacecraft_env import NominalUnits
    from spacecraft_lab.random_search import paired_ars

    class Recording(gym.Wrapper):
        def reset(self, *, seed=None, options=None):
            if seeds_seen is not None:
                seeds_seen.append(seed)
            return self.env.reset(seed=seed, options=options)

    def make():
        return Recording(NominalUnits(gym.make(
            env_id("docking"), task="slew", reward="cost", max_episode_steps=30,
            outputs=("attitude_error", "rate"))))

    venv = VecNormalize(DummyVecEnv([make]), norm_obs=False, norm_reward=False)
    return paired_ars()("LinearPolicy", venv, n_delta=4, n_top=2, seed=seed)


def test_paired_ars_flies_both_candidates_of_a_direction_on_the_same_episode():
    th = pytest.importorskip("torch")
    pytest.importorskip("sb3_contrib")
    seeds: list = []
    model = _short_paired_ars(seeds)
    model.learn(1)                                  # one iteration: 2 x 4 candidates
    # the first reset is learn's own (the model's seed); auto-resets at episode ends
    # pass None
    drawn = [s for s in seeds[1:] if s is not None]
    assert len(drawn) == 8 and drawn[:4] == drawn[4:] and len(set(drawn[:4])) == 4
    # identical + and - candidates on the same episode return the same: with each
    # pair's mean removed, nothing is left
    callback = model._init_callback(None)
    same = th.stack([model.weights] * 8)
    assert th.equal(model.evaluate_candidates(same, callback, None), th.zeros(8))
    # distinct candidates: each pair's two returns are opposite
    other = th.cat([same[:4] + 0.1, same[4:] - 0.1])
    returns = model.evaluate_candidates(other, callback, None)
    assert th.allclose(returns[:4], -returns[4:]) and returns.abs().max() > 0
    with pytest.raises(ValueError, match="async_eval"):
        model.learn(1, async_eval=object())


def test_paired_ars_is_seeded_and_saves_its_linear_policy(tmp_path):
    th = pytest.importorskip("torch")
    pytest.importorskip("sb3_contrib")
    from spacecraft_lab.training import algorithm_class

    # (each built right before it learns: SB3 seeds torch's global generator, from
    # which ARS draws its directions, when a model is built)
    first = _short_paired_ars(seed=3).learn(1)
    second = _short_paired_ars(seed=3).learn(1)
    assert th.equal(first.weights, second.weights) and first.weights.abs().max() > 0
    first.save(tmp_path / "ars.zip")
    loaded = algorithm_class("ars").load(tmp_path / "ars.zip", device="cpu")
    obs = np.array([[1.0, -2.0, 0.5, 3.0, 0.0, -1.0]], dtype=np.float32)
    assert np.array_equal(loaded.predict(obs)[0], first.predict(obs)[0])
    with pytest.raises(ValueError, match="algo must be one of"):
        algorithm_class("dqn")


def test_training_refuses_ars_on_several_envs(tmp_path):
    pytest.importorskip("sb3_contrib")
    with pytest.raises(ValueError, match="ARS flies its candidates"):
        run_training("ars", "attitude-error", 100, 1, tmp_path, envs=2, progress=False)


@pytest.mark.slow        # ~15 s: one ARS iteration of 16 whole episodes
def test_an_ars_agent_trains_saves_and_scores_as_recorded(tmp_path):
    pytest.importorskip("sb3_contrib")
    from spacecraft_lab.agents import load_agent
    from spacecraft_lab.training import _evaluate

    m = run_training("ars", "attitude-error", 1, 1, tmp_path, scenario="docking",
                     eval_every=10**9, progress=False, eval_seeds=(1000, 1001),
                     reward="cost")
    run = m["runs"][0]
    # one whole iteration (16 episodes, some cut short by leaving the attitude bound)
    # however few env steps are asked, and metrics.json says what was trained
    assert 16 * 10 <= run["env_steps"] <= 16 * 2500
    assert run["env_steps"] == m["timesteps"] and m["timesteps_requested"] == 1
    assert m["hyperparameters"] == {}                     # sb3-contrib's defaults
    policy, settings = load_agent(tmp_path / "ars-attitude-error-seed0.zip")
    saved = _evaluate(policy, "docking", "attitude-error", settings["env_kwargs"], (1000, 1001))
    assert saved["cost_after_100s_per_seed"] == run["final"]["cost_after_100s_per_seed"]


def test_training_on_the_scored_window_wraps_the_env_and_refuses_a_bad_start(tmp_path):
    from controllers import ScoredWindowReward
    from spacecraft_lab.training import _monitored_env

    env = _monitored_env("family", "attitude-error", {"task": "slew", "reward": "cost"}, 10,
                         reward_from_s=100.0)
    layer, found = env, None
    while found is None and hasattr(layer, "env"):
        found = layer if isinstance(layer, ScoredWindowReward) else None
        layer = layer.env
    assert found is not None and found.start_s == 100.0
    plain = _monitored_env("family", "attitude-error", {"task": "slew", "reward": "cost"}, 10)
    assert "ScoredWindowReward" not in repr(plain)
    for bad in (-1.0, float("nan"), True):
        with pytest.raises(ValueError, match="reward_from_s"):
            run_training("ppo", "none", 100, 1, tmp_path, reward_from_s=bad, progress=False)


def test_an_interrupted_run_leaves_its_curve(tmp_path, monkeypatch):
    """Each evaluation writes metrics.json and the learning curves: a run stopped after
    its first evaluation (at the update boundary past 1000 env steps) keeps that point."""
    pytest.importorskip("stable_baselines3")
    import spacecraft_lab.training as training

    real, calls = training._evaluate, []

    def evaluate_then_stop(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(training, "_evaluate", evaluate_then_stop)
    with pytest.raises(KeyboardInterrupt):
        run_training("ppo", "none", 4096, 1, tmp_path, eval_every=1000, repeat=1,
                     progress=False, eval_seeds=(1000,))
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["complete"] is False and m["runs"] == []
    assert [c["timesteps"] for c in m["in_progress"]["curve"]] == [2048]
    assert (tmp_path / "learning_curves.png").exists()
    with pytest.raises(ValueError, match="an unfinished run"):
        load_training_metrics(tmp_path)


def test_the_command_line_trains_on_every_core_by_default():
    from spacecraft_lab.cli import _training_envs, build_parser

    parser = build_parser()
    ppo = parser.parse_args(["train", "--algo", "ppo"])
    assert _training_envs(ppo) == max(1, min(os.cpu_count() or 1, 64))
    assert _training_envs(parser.parse_args(["train", "--algo", "ars"])) == 1
    assert _training_envs(parser.parse_args(["train", "--envs", "3"])) == 3
