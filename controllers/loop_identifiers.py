"""The identifiers an adaptive loop flies, built for an environment.

:class:`controllers.AdaptiveLQG` needs an online identifier of the plant it
controls. Two are offered, each built from what a designer knows of the
spacecraft without knowing its parameters (the sensors it carries, which
appendages the paddle drive turns, which sensor sits on which appendage):

* :func:`scheduled_identifier`, the default where the environment's model
  describes its appendages: the hub plus one mode per appendage fitted by
  output error to the warm-up and again on the loop's later data, the
  paddles' inertia and couplings turned with the drive's encoder
  (:class:`identifiers.ScheduledPhysicalIdentifier`), its fits run off the
  control path with a charged latency (:data:`LOOP_FIT_TIMING`).
* :func:`fast_identifier`: the structured recursive identifier
  (:func:`identifiers.default_identifier` with
  :data:`identifiers.CLOSED_LOOP_SETTINGS`), about 0.5 s per 250 s episode,
  1.2-5.7x the oracle LQG on the same conditions.

A third is the source paper's family of algorithms:
:func:`structured_identifier`, the recursive PBSID with an exact rigid block
(:class:`identifiers.StructuredRPBSID` with
:data:`identifiers.STRUCTURED_CLOSED_LOOP_SETTINGS`); its loop costs more than
the other two's (docs/results/control.md).

:func:`closed_loop_identifier` picks the default for an environment.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from identifiers import (
    CLOSED_LOOP_SETTINGS,
    STRUCTURED_CLOSED_LOOP_SETTINGS,
    FitTiming,
    OnlineIdentifier,
    ScheduledPhysicalIdentifier,
    StructuredRPBSID,
    default_identifier,
)

__all__ = ["LOOP_FIT_TIMING", "closed_loop_identifier", "fast_identifier",
           "scheduled_identifier", "structured_identifier"]

#: When the scheduled fit's models reach the loop: each fit runs on a worker thread and its
#: model is used from 10 s (100 samples) after the fit fell due, the held model (or, before
#: the first, the warm-up controller) flying meanwhile. A fixed charge, so results are the
#: same on every machine; on this project's 2-core machine the warm-up fit takes 1-6 s of
#: CPU and a refit 0.5-2 s (``python benchmarks/bench_loop_compute.py``).
LOOP_FIT_TIMING = FitTiming(latency_s=10.0)

#: What a model must say of its appendages for the scheduled fit.
_APPENDAGES = ("appendage_turns", "sensor_appendage", "drive_axis")


def _model(env: gym.Env) -> tuple[Any, Any]:
    """The unwrapped env and its model."""
    base = env.unwrapped if isinstance(env, gym.Env) else env
    model = getattr(base, "model", None)
    if model is None or not hasattr(base, "observation_layout"):
        raise TypeError(f"env must be a flexible-spacecraft environment (with a model and an "
                        f"observation layout), got {type(base).__name__}")
    return base, model


def _on_env_sensors(build: Any, settings: Any, env: gym.Env,
                    options: dict[str, Any]) -> Any:
    """``build(sensors, n=, dt=, **settings)`` on ``env``'s observed sensors, its model's
    order and sample time, ``options`` overriding ``settings``."""
    base, model = _model(env)
    return build(base.observation_layout.sensors(), n=model.n, dt=model.dt,
                 **{**settings, **options})


def _not_schedulable(base: Any, model: Any) -> list[str]:
    """What the scheduled fit needs and ``base`` lacks: the model's description of its
    appendages, and the tip deflections among the observed sensors (empty: nothing)."""
    missing = [f"model.{name}" for name in _APPENDAGES if not hasattr(model, name)]
    if "deflection" not in base.observation_layout.sensors().names:
        missing.append("deflection sensors")
    return missing


def scheduled_identifier(env: gym.Env, *, fit_timing: FitTiming = LOOP_FIT_TIMING,
                         **options: Any) -> ScheduledPhysicalIdentifier:
    """The drive-scheduled physical fit for ``env``.

    Parameters
    ----------
    env : gymnasium.Env
        A flexible-spacecraft environment (wrappers allowed) whose model
        describes its appendages (``appendage_turns``, ``sensor_appendage``,
        ``drive_axis``).
    fit_timing : identifiers.FitTiming
        When each fit's model reaches the loop (default :data:`LOOP_FIT_TIMING`:
        off the control path, 10 s after the fit falls due; ``FitTiming()``: at
        once, the simulation waiting for it).
    **options
        Other keywords of :class:`identifiers.ScheduledPhysicalIdentifier`
        (e.g. ``accumulate=False`` to hold the warm-up's fit).

    Returns
    -------
    identifiers.ScheduledPhysicalIdentifier
        Fed the env's sensors, its appendages' layout and the drive's axis;
        the sample time is the model's.

    Raises
    ------
    TypeError
        If ``env`` is not a flexible-spacecraft environment.
    ValueError
        If its model does not describe its appendages, or the env does not
        observe attitude, rate and the tip deflections.

    Examples
    --------
    >>> import gymnasium as gym
    >>> from controllers import scheduled_identifier
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraftPaddleRotation-v2")
    >>> ident = scheduled_identifier(env)
    >>> type(ident).__name__, ident.warmup, ident.warmup_amplitude
    ('ScheduledPhysicalIdentifier', 300, 0.5)
    """
    base, model = _model(env)
    missing = _not_schedulable(base, model)
    if missing:
        raise ValueError(f"the scheduled fit needs the model's description of its "
                         f"appendages and the tip deflections; the env has no "
                         f"{', '.join(missing)}")
    identifier = ScheduledPhysicalIdentifier(
        base.observation_layout.sensors(), turning=model.appendage_turns,
        sensor_appendage=model.sensor_appendage, drive_axis=model.drive_axis, dt=model.dt,
        **options)
    identifier.fit_timing = fit_timing
    return identifier


def fast_identifier(env: gym.Env, **options: Any) -> OnlineIdentifier:
    """The structured recursive identifier with the closed-loop settings, for ``env``.

    Parameters
    ----------
    env : gymnasium.Env
        A flexible-spacecraft environment (wrappers allowed).
    **options
        Overrides of :data:`identifiers.CLOSED_LOOP_SETTINGS` and the other
        keywords of :func:`identifiers.default_identifier`.

    Returns
    -------
    OnlineIdentifier
        A :class:`identifiers.RigidFlexibleIdentifier` of the model's order
        and sample time on the env's sensors.

    Raises
    ------
    TypeError
        If ``env`` is not a flexible-spacecraft environment.

    Examples
    --------
    >>> import gymnasium as gym
    >>> from controllers import fast_identifier
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2")
    >>> ident = fast_identifier(env)
    >>> type(ident).__name__, ident.n, ident.warmup
    ('RigidFlexibleIdentifier', 22, 300)
    """
    return _on_env_sensors(default_identifier, CLOSED_LOOP_SETTINGS, env, options)


def structured_identifier(env: gym.Env, **options: Any) -> StructuredRPBSID:
    """The structure-aware recursive PBSID with the closed-loop settings, for ``env``.

    Parameters
    ----------
    env : gymnasium.Env
        A flexible-spacecraft environment (wrappers allowed) observing the
        attitude and rate (and, for the default flexible part, the tip
        deflections).
    **options
        Overrides of :data:`identifiers.STRUCTURED_CLOSED_LOOP_SETTINGS` and the
        other keywords of :class:`identifiers.StructuredRPBSID`.

    Returns
    -------
    StructuredRPBSID
        Of the model's order and sample time on the env's sensors.

    Raises
    ------
    TypeError
        If ``env`` is not a flexible-spacecraft environment.

    Examples
    --------
    >>> import gymnasium as gym
    >>> from controllers import structured_identifier
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraftDocking-v2")
    >>> ident = structured_identifier(env)
    >>> type(ident).__name__, ident.n, ident.warmup, ident.flexible
    ('StructuredRPBSID', 16, 300, 'classical')
    """
    return _on_env_sensors(StructuredRPBSID, STRUCTURED_CLOSED_LOOP_SETTINGS, env, options)


def closed_loop_identifier(env: gym.Env) -> OnlineIdentifier:
    """The identifier :class:`controllers.AdaptiveLQG` flies on ``env`` by default.

    Parameters
    ----------
    env : gymnasium.Env
        A flexible-spacecraft environment (wrappers allowed).

    Returns
    -------
    OnlineIdentifier
        :func:`scheduled_identifier` where the env's model describes its
        appendages (every registered environment's does) and the env
        observes the tip deflections the fit needs (the default outputs
        do), else :func:`fast_identifier`.

    Raises
    ------
    TypeError
        If ``env`` is not a flexible-spacecraft environment.

    Examples
    --------
    >>> import gymnasium as gym
    >>> from controllers import closed_loop_identifier
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraftSolarRotation-v2")
    >>> type(closed_loop_identifier(env)).__name__
    'ScheduledPhysicalIdentifier'
    """
    base, model = _model(env)
    return fast_identifier(env) if _not_schedulable(base, model) else scheduled_identifier(env)
