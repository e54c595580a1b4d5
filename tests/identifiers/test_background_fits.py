"""Fits off the control path (identifiers.core.background): a latency charged in samples,
the same models as a fit at once from the due sample on, and fits that fail."""

from __future__ import annotations

import time
import warnings

import gymnasium as gym
import numpy as np
import pytest

from controllers import AdaptiveLQG, run_episode, scheduled_identifier
from identifiers import FitTiming, IdentifierHealthWarning, cancel_fits, cancellation_point
from spacecraft_env import env_id


def _record(steps: int, seed: int = 0):
    """A paddle-rotation record under a random binary torque: inputs, outputs, angles."""
    env = gym.make(env_id("paddle_rotation"), max_episode_steps=steps)
    rng = np.random.default_rng(seed)
    _, info = env.reset(seed=seed)
    base = env.unwrapped
    u = 0.5 * rng.choice([-1.0, 1.0], size=(steps, 3))
    ys, angles = [], []
    for k in range(steps):
        angles.append(info["paddle_angle"])
        obs, _, _, _, info = env.step((u[k] / base.max_torque).astype(np.float32))
        ys.append(obs.astype(float))
    return env, u, np.array(ys), np.array(angles)


def test_fit_timing_validates_its_values():
    with pytest.raises(ValueError, match="latency_s must be a finite number"):
        FitTiming(latency_s=-1.0)
    with pytest.raises(ValueError, match="budget_s must be a finite number"):
        FitTiming(latency_s=1.0, budget_s=float("nan"))
    with pytest.raises(ValueError, match="timeout_s must be a finite number"):
        FitTiming(latency_s=1.0, timeout_s=0.0)
    assert not FitTiming().background and FitTiming(latency_s=0.0).background
    env = gym.make(env_id("paddle_rotation"))
    with pytest.raises(TypeError, match="fit_timing must be a FitTiming"):
        scheduled_identifier(env).fit_timing = 10.0


def test_a_background_fit_is_the_fit_at_once_from_its_due_sample_on():
    """On a record, the identifier whose fit runs off the caller's thread with a 5 s
    latency has no model until 5 s after the fit fell due, and from then on the same
    model and state as the identifier that fitted at once (its filter caught up)."""
    env, u, y, angles = _record(400)
    now = scheduled_identifier(env, fit_timing=FitTiming())
    later = scheduled_identifier(env, fit_timing=FitTiming(latency_s=5.0))
    for k in range(400):
        for ident in (now, later):
            ident.set_schedule(angles[k])
            ident.update(u[k], y[k])
        assert later.angle == now.angle          # the caller's angle survives a take-over
        if k + 1 == 300:
            assert now.model is not None and later.model is None and later.fit_pending
        if 300 <= k + 1 < 350:
            assert later.model is None
        if k + 1 >= 351:
            assert not later.fit_pending
            np.testing.assert_allclose(later.model.A, now.model.A, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(later.state, now.state, rtol=1e-10, atol=1e-14)
    entry = later.fit_log[0]
    assert (entry["action"], entry["sample"], entry["due"], entry["adopted"],
            entry["outcome"]) == ("first_fit", 300, 350, 350, "adopted")
    assert entry["latency_s"] == pytest.approx(5.0) and entry["cpu_s"] > 0
    assert now.fit_log[0]["latency_s"] == 0.0
    env.close()


def test_a_measured_charge_taken_late_catches_up_on_every_sample():
    """A fit charged its own CPU time and taken over after its due sample (the caller
    outran it): the samples past the due one are replayed too, so the identifier holds
    the fit-at-once identifier's model and state."""
    env, u, y, angles = _record(460)
    now = scheduled_identifier(env, fit_timing=FitTiming())
    later = scheduled_identifier(env, fit_timing=FitTiming(measured=True))
    for k in range(450):
        for ident in (now, later):
            ident.set_schedule(angles[k])
            ident.update(u[k], y[k])
    later._job.future.result(timeout=120)          # the fit done, its charge known
    assert later._job.due < later.n_samples        # taken later than its due sample
    for k in range(450, 460):
        for ident in (now, later):
            ident.set_schedule(angles[k])
            ident.update(u[k], y[k])
    assert not later.fit_pending and later.fit_log[0]["outcome"] == "adopted"
    np.testing.assert_allclose(later.model.A, now.model.A, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(later.state, now.state, rtol=1e-10, atol=1e-14)
    env.close()


def test_the_loop_with_background_fits_is_deterministic():
    """The charge is in samples: two runs give the same trajectory, and the model
    flies from the charged sample on (the fit's record in the controller's stats)."""
    env = gym.make(env_id("paddle_rotation"), max_episode_steps=430)
    runs = [run_episode(env, AdaptiveLQG(env), seed=5) for _ in range(2)]
    np.testing.assert_array_equal(runs[0].torque, runs[1].torque)
    fits = runs[0].controller_stats["fits"]
    assert [(f["sample"], f["adopted"], f["outcome"]) for f in fits] == [(300, 400, "adopted")]
    env.close()


def _raising() -> bool:
    raise np.linalg.LinAlgError("a fit that raises")


def _hanging() -> bool:
    while True:                           # until cancelled
        cancellation_point()
        time.sleep(0.01)


@pytest.mark.parametrize(("fit", "timing", "outcome"), [
    (_raising, FitTiming(latency_s=2.0), "failed"),
    (None, FitTiming(latency_s=2.0, budget_s=1e-9), "over budget"),
    (_hanging, FitTiming(latency_s=2.0, timeout_s=0.2), "timed out"),
])
def test_a_fit_that_fails_leaves_the_loop_flying_and_says_so(fit, timing, outcome):
    """A fit that raises, exceeds its CPU budget or never returns in time: the episode
    goes on (the warm-up controller flies, the fit is tried again half a warm-up later),
    the outcome is in the fit log and a warning names it."""
    env = gym.make(env_id("paddle_rotation"), max_episode_steps=500)
    ident = scheduled_identifier(env, fit_timing=timing)
    if fit is not None:
        ident._fit_record = fit                 # the fork runs this one
    ctrl = AdaptiveLQG(env, identifier=ident)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        traj = run_episode(env, ctrl, seed=0)
    assert len(traj.time) == 500 and not traj.terminated
    assert np.isfinite(traj.states).all()
    log = traj.controller_stats["fits"]
    assert log[0]["outcome"] == outcome and log[0]["adopted"] is None
    assert log[1]["sample"] == 470               # retried half a warm-up later
    assert ident.model is None
    assert any(issubclass(w.category, IdentifierHealthWarning) and outcome in str(w.message)
               and "held model flies on" in str(w.message) for w in caught)
    env.close()


def test_a_fit_nobody_wants_is_cancelled():
    """A reset (a new episode) or cancel_fits stops a fit running in the background."""
    env = gym.make(env_id("paddle_rotation"), max_episode_steps=320)
    ident = scheduled_identifier(env, fit_timing=FitTiming(latency_s=2.0))
    ident._fit_record = _hanging
    run_episode(env, AdaptiveLQG(env, identifier=ident), seed=0)
    assert ident.fit_pending
    ident.reset()
    assert not ident.fit_pending
    assert cancel_fits(timeout=5.0) in (0, 1)          # the reset's fit, ending
    assert cancel_fits(timeout=0.1) == 0
    env.close()


def test_no_finished_fit_stays_referenced():
    """Across episodes of one controller, each fit taken over releases what referenced it
    (its identifier's finalizer, which would otherwise keep the fork and its record)."""
    import weakref

    from identifiers.core.fit_jobs import FitJob

    def fits_referenced() -> int:
        return sum(getattr(info.func, "__self__", None).__class__ is FitJob
                   for info in weakref.finalize._registry.values())

    env = gym.make(env_id("paddle_rotation"), max_episode_steps=430)
    ctrl = AdaptiveLQG(env)
    for seed in (0, 1):
        run_episode(env, ctrl, seed=seed)
        assert not ctrl.identifier.fit_pending and fits_referenced() == 0
    env.close()
