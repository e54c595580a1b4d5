"""The package's recommended online identifier, constructed in one place.

Everything that needs "the identifier we recommend" (the adaptive
controller, the RL features wrapper, the experiments) calls
:func:`default_identifier`, so its settings are written once.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from identifiers.base import OnlineIdentifier
from identifiers.moment_refit import MomentRefitRPBSID
from spacecraft_conventions import NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["DEFAULT_SETTINGS", "default_identifier"]

#: Settings of the recommended identifier (normalized by the nominal
#: sensor levels): a long memory (forgetting 0.9995, about 2000 samples)
#: with a Tikhonov floor on the VARX, a 50 s warm-up, and samples whose
#: one-step innovation exceeds 100 running RMS rejected as outliers; see
#: docs/design/identification.md for the measurements behind them.
DEFAULT_SETTINGS: dict[str, Any] = {"p": 15, "forgetting": 0.9995, "regularization": 0.001,
                                    "warmup": 500, "outlier_threshold": 100.0}


def default_identifier(layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22,
                       dt: float = 0.1, **options: Any) -> OnlineIdentifier:
    """The recommended online identifier for the spacecraft's outputs.

    Parameters
    ----------
    layout : OutputLayout
        Which sensor groups the identifier receives, in order (default: the
        environments' standard 10 outputs: attitude, rate, four tip
        deflections). Its nominal levels normalize the outputs; torques are
        normalized by :data:`~spacecraft_conventions.NOMINAL_TORQUE`.
    n : int
        Model order (22 for two modes per appendage).
    dt : float
        Sample time, s.
    **options
        Overrides of :data:`DEFAULT_SETTINGS` or any other keyword of the
        identifier class.

    Returns
    -------
    OnlineIdentifier
    """
    sensors = layout.sensors()
    settings: dict[str, Any] = {**DEFAULT_SETTINGS, "dt": dt,
                                "input_scale": np.full(3, NOMINAL_TORQUE),
                                "output_scale": sensors.scales(), **options}
    p = settings.pop("p")
    forgetting = settings.pop("forgetting")
    return MomentRefitRPBSID(n, p, forgetting, **settings)
