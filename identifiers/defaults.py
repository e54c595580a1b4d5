"""The package's recommended online identifier, constructed in one place.

Everything that needs "the identifier we recommend" (the adaptive
controller, the RL features wrapper, the experiments) calls
:func:`default_identifier`. Its settings are the constructor defaults of
:class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier`, written once
there; :data:`DEFAULT_SETTINGS` lists them for display.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from identifiers.core.online import OnlineIdentifier
from identifiers.modal.rigid_flexible import RigidFlexibleIdentifier
from spacecraft_conventions import STANDARD_OUTPUTS, OutputLayout

__all__ = ["CLOSED_LOOP_SETTINGS", "DEFAULT_SETTINGS", "STRUCTURED_CLOSED_LOOP_SETTINGS",
           "default_identifier"]

#: Settings of the recommended identifier (read from the constructor's
#: defaults, which are the single source; docs/design/identification.md
#: gives the measurements behind them).
DEFAULT_SETTINGS: Mapping[str, Any] = MappingProxyType({
    name: param.default
    for name, param in inspect.signature(RigidFlexibleIdentifier).parameters.items()
    if param.kind is param.KEYWORD_ONLY and name not in ("input_scale", "output_scale")})

#: Overrides of :data:`DEFAULT_SETTINGS` for an identifier inside a feedback
#: loop that holds the spacecraft still (the adaptive LQG's): the Kalman
#: filter assumes 0.05 N m of unmodelled torque instead of 10 (the open-loop
#: value, 100 times the loop's torque after warm-up, made the filter follow
#: the sensor noise into the modal states) and the warm-up is 30 s. What the
#: quiet loop cannot support is switched off, so information accumulates:
#: no random-walk drift of the rigid gains (it made their reported
#: uncertainty grow without bound in a quiet loop: 0.14 -> 1.2 relative std
#: over 1000 s), no change test (on a constant plant it raised 3 false alarms
#: in 250 s, and the covariance it re-opened was refilled by closed-loop data
#: that pulled the gain 4-11x off), no re-search of the modes (each rebuild
#: replays quiet closed-loop data), and the modal couplings' random walk at
#: 1e-7 per sample, the open-loop default before 2026-11-29 (the present 1e-4
#: follows turning paddles in open-loop records but raised the fast adaptive
#: LQG's cost from 1.39x to 1.58x the oracle LQG's on paddle rotation, from
#: 1.46x to 1.76x on docking and from 1.52x to 1.85x on solar rotation, 10
#: seeds, paired medians).
#: docs/design/control.md gives the measurements.
CLOSED_LOOP_SETTINGS: Mapping[str, Any] = MappingProxyType({
    "process_torque": 0.05, "warmup": 300, "rigid_drift": 0.0, "detect_changes": False,
    "rediscover": None, "coupling_drift": 1e-7})


#: Overrides of :class:`identifiers.structured.structured_rpbsid.StructuredRPBSID`'s
#: defaults for the same quiet loop: the warm-up of the loop's excitation, 30 s
#: (at its open-loop 50 s the adaptive LQG on it cost 5.3x the oracle LQG on docking,
#: at 30 s 1.75x: 6 seeds, paired medians), the Kalman filter's unmodelled torque
#: and the change test as in :data:`CLOSED_LOOP_SETTINGS` (alone, the torque changed
#: nothing; the three together 1.77x). docs/results/control.md gives the table.
STRUCTURED_CLOSED_LOOP_SETTINGS: Mapping[str, Any] = MappingProxyType({
    "warmup": 300, "process_torque": 0.05, "detect_changes": False})


def default_identifier(layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22,
                       dt: float = 0.1, **options: Any) -> OnlineIdentifier:
    """The recommended online identifier for the spacecraft's outputs.

    Parameters
    ----------
    layout : OutputLayout
        Which sensor groups the identifier receives, in order (default: the
        environments' standard 10 outputs: attitude, rate, four tip
        deflections). Attitude and rate are required. Its nominal levels
        normalize the outputs; torques are normalized by 1 N m.
    n : int
        Model order (22: the rigid body and eight flexible modes).
    dt : float
        Sample time, s.
    **options
        Overrides of :data:`DEFAULT_SETTINGS`, i.e. any keyword of
        :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier` (e.g.
        ``prior=`` a nominal structural model's modes).

    Returns
    -------
    OnlineIdentifier
        A new :class:`identifiers.modal.rigid_flexible.RigidFlexibleIdentifier`.

    Examples
    --------
    >>> from identifiers import CLOSED_LOOP_SETTINGS, default_identifier
    >>> ident = default_identifier()
    >>> type(ident).__name__, ident.n, ident.dt, ident.warmup
    ('RigidFlexibleIdentifier', 22, 0.1, 500)
    >>> ident.model is None          # no model before the warm-up: 500 samples, 50 s
    True
    >>> default_identifier(**CLOSED_LOOP_SETTINGS).warmup
    300
    """
    return RigidFlexibleIdentifier(layout, n=n, dt=dt, **options)
