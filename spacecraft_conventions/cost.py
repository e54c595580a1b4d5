"""The common quadratic stage cost, defined once.

Every number that says how well the spacecraft was controlled is this cost:
the environment's ``reward="cost"`` is its negative at every step (and the
bounded and log rewards are transforms of it), the harness's
``controllers.stage_costs`` splits it into its parts, and every LQG design
minimizes it (``controllers.LQRWeights`` extends these weights with the
design-only integral weight). ::

    c_k = attitude   * |(psi_{k+1} - ref) / 1 deg|^2
        + rate       * |omega_{k+1} / 0.1 deg/s|^2
        + deflection * |w_{k+1} / 1 cm|^2
        + torque     * |u_k / 1 N m|^2

with the *true* attitude ``psi``, body rates ``omega`` and tip deflections
``w`` of the state the step produced, the reference attitude ``ref`` and the
torque ``u_k`` the actuators applied during the step (N m, after the
actuator delay and rate limit; the nominal levels are those of
:mod:`spacecraft_conventions.sensors`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from spacecraft_conventions.outputs import OutputLayout

__all__ = ["COST_WEIGHTS", "CostWeights", "output_cost_weights"]


@dataclass(frozen=True)
class CostWeights:
    """Weights of the common quadratic stage cost (see the module's formula).

    Attributes
    ----------
    attitude : float
        Weight of the squared attitude error in units of 1 deg (default 1).
    rate : float
        Weight of the squared body rates in units of 0.1 deg/s (default 1).
    deflection : float
        Weight of each squared tip deflection in units of 1 cm (default 0.1).
    torque : float
        Weight of the squared applied torque per (N m)^2 (default 0.3: with the
        other defaults it gives a closed-loop attitude bandwidth of about 0.1 rad/s,
        below the first flexible mode).

    All are finite and >= 0 (``ValueError`` otherwise) and stored as floats.

    Examples
    --------
    >>> from spacecraft_conventions import COST_WEIGHTS, CostWeights
    >>> COST_WEIGHTS
    CostWeights(attitude=1.0, rate=1.0, deflection=0.1, torque=0.3)
    >>> CostWeights(torque=-1.0)
    Traceback (most recent call last):
    ...
    ValueError: cost weight torque must be finite and >= 0, got -1.0
    """

    attitude: float = 1.0
    rate: float = 1.0
    deflection: float = 0.1
    torque: float = 0.3

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.floating
                                                         | np.integer):
                raise TypeError(f"cost weight {field.name} must be a number, got {value!r}")
            value = float(value)
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"cost weight {field.name} must be finite and >= 0, "
                                 f"got {value}")
            object.__setattr__(self, field.name, value)

    @property
    def cost_weights(self) -> CostWeights:
        """The four weights of the stage cost alone (drops the fields a subclass adds)."""
        return CostWeights(self.attitude, self.rate, self.deflection, self.torque)


#: The cost every result of the project is judged by (the env's reward, the harness, the LQGs).
COST_WEIGHTS = CostWeights()


def output_cost_weights(layout: OutputLayout, weights: CostWeights = COST_WEIGHTS
                        ) -> np.ndarray:
    """Per-channel weights of the cost's output terms for the sensor groups of ``layout``.

    Parameters
    ----------
    layout : OutputLayout
        The output groups, in order; only its sensor groups (``"attitude"``,
        ``"rate"``, ``"deflection"``, via ``layout.sensors()``) are weighted.
    weights : CostWeights
        The per-group weights.

    Returns
    -------
    (m,) ndarray
        Each sensor channel's group weight divided by the square of the group's
        nominal level: per rad^2, per (rad/s)^2 and per m^2 for the three groups.
    """
    per_group = {"attitude": weights.attitude, "rate": weights.rate,
                 "deflection": weights.deflection}
    sensors = layout.sensors()
    w = np.concatenate([np.full(size, per_group[g]) for g, size in sensors.groups])
    return w / sensors.scales() ** 2
