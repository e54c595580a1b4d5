"""The package's recommended online identifier, constructed in one place.

Everything that needs "the identifier we recommend" (the adaptive
controller, the RL features wrapper, the experiments) calls
:func:`default_identifier`, so its settings are written once.
"""

from __future__ import annotations

from typing import Any

from identifiers.base import OnlineIdentifier
from identifiers.rigid_flexible import RigidFlexibleIdentifier
from spacecraft_conventions import STANDARD_OUTPUTS, OutputLayout

__all__ = ["DEFAULT_SETTINGS", "default_identifier"]

#: Settings of the recommended identifier, the rigid-flexible one: the
#: rigid body's kinematics known, its inverse inertia and the flexible
#: couplings estimated with a 50 s memory (forgetting 0.998), flexible
#: modes found from the first 50 s of data, changes detected and reacted
#: to; see docs/design/identification.md for the measurements behind them.
DEFAULT_SETTINGS: dict[str, Any] = {"forgetting": 0.998, "warmup": 500, "highpass": 0.99,
                                    "change_threshold": 6.0, "discount": 10.0,
                                    "outlier_threshold": 100.0}


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
        Overrides of :data:`DEFAULT_SETTINGS` or any other keyword of
        :class:`~identifiers.rigid_flexible.RigidFlexibleIdentifier` (e.g.
        ``prior=`` a nominal structural model's modes).

    Returns
    -------
    OnlineIdentifier
    """
    return RigidFlexibleIdentifier(layout, n=n, dt=dt, **{**DEFAULT_SETTINGS, **options})
