"""Conventions shared by every package of the project, each defined once.

The lowest layer: it imports nothing of the project, so the environment,
the identifiers and the controllers can all rely on it without depending
on each other.

* :mod:`spacecraft_conventions.units`: angle unit conversions.
* :mod:`spacecraft_conventions.sensors`: nominal signal level of each
  sensor group and of the torques (what ``snr_db``, the reward, the LQR
  weights and the identifiers' normalization are relative to).
* :mod:`spacecraft_conventions.cost`: the common quadratic stage cost's weights
  (:class:`CostWeights`), which the reward, the harness and the LQG designs share.
* :mod:`spacecraft_conventions.outputs`: the sensor groups, their order,
  their channel labels and :class:`OutputLayout`, which gives each group's
  rows of an output or observation vector by name.
* :mod:`spacecraft_conventions.processes`: pool workers that end with their
  driver, SIGTERM handled as Ctrl-C, and a driver's exit that joins nothing.
* :mod:`spacecraft_conventions.kept`: a value kept while the arrays it was
  computed from keep their bits (:class:`KeptWhileEqual`), for the per-model
  work of the identifiers' exports and the controllers' designs.
"""

from spacecraft_conventions.blas import single_threaded_blas
from spacecraft_conventions.cost import COST_WEIGHTS, CostWeights, output_cost_weights
from spacecraft_conventions.kept import KeptWhileEqual
from spacecraft_conventions.outputs import (
    AXES,
    AXIS_NAMES,
    LABEL_PREFIX,
    MEASURES,
    OBSERVATION_GROUPS,
    OUTPUT_GROUPS,
    STANDARD_OUTPUTS,
    TASK_GROUPS,
    OutputLayout,
    match_groups,
)
from spacecraft_conventions.processes import exit_now, exit_with_parent, sigterm_as_interrupt
from spacecraft_conventions.sensors import NOMINAL_SCALE, NOMINAL_TORQUE, nominal_scale
from spacecraft_conventions.units import DEG_PER_RAD, RAD_PER_DEG
from spacecraft_conventions.version import __version__

__all__ = [
    "AXES",
    "AXIS_NAMES",
    "COST_WEIGHTS",
    "DEG_PER_RAD",
    "LABEL_PREFIX",
    "MEASURES",
    "NOMINAL_SCALE",
    "NOMINAL_TORQUE",
    "OBSERVATION_GROUPS",
    "OUTPUT_GROUPS",
    "RAD_PER_DEG",
    "STANDARD_OUTPUTS",
    "TASK_GROUPS",
    "CostWeights",
    "KeptWhileEqual",
    "OutputLayout",
    "__version__",
    "exit_now",
    "exit_with_parent",
    "match_groups",
    "nominal_scale",
    "output_cost_weights",
    "sigterm_as_interrupt",
    "single_threaded_blas",
]
