"""Gymnasium environment of the time-varying flexible spacecraft.

Attitude regulation or slew of the ETS-VIII rigid-flexible model under
3-axis torque, with noisy sensor outputs. See :class:`FlexibleSpacecraftEnv`.
"""

from __future__ import annotations

import difflib
import inspect
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from spacecraft_conventions import (
    AXES,
    LABEL_PREFIX,
    NOMINAL_SCALE,
    OBSERVATION_GROUPS,
    OUTPUT_GROUPS,
    RAD_PER_DEG,
    CostWeights,
    OutputLayout,
    output_cost_weights,
)
from spacecraft_env.dynamics import FlexibleSpacecraftModel
from spacecraft_env.family import PlantDraw, TaskFamily
from spacecraft_env.limits import PARAMETER_LIMITS, check_parameter
from spacecraft_env.parameters import SpacecraftParameters, ets8_parameters
from spacecraft_env.registration import MAX_EPISODE_STEPS
from spacecraft_env.rendering import SpacecraftRenderer
from spacecraft_env.scenarios import SCENARIOS, Scenario, make_scenario

__all__ = ["DEFAULT_SNR_DB", "REWARDS", "FlexibleSpacecraftEnv", "RewardWeights"]

#: Reward forms (the ``reward`` argument): the negative stage cost, or its
#: bounded survival form for learning agents, and its log-scaled form that resolves
#: precision near the target (``"log"``).
REWARDS = ("cost", "bounded", "log")

#: Default measurement SNR per channel, dB, relative to the channel's nominal level
#: (the paper's 40 dB: 0.01 deg of attitude, 0.001 deg/s of rate, 0.1 mm of deflection).
DEFAULT_SNR_DB = 40.0
#: Accepted range of ``snr_db``: from noise 100x the nominal level to 1e-15 of it.
SNR_RANGE_DB = (PARAMETER_LIMITS["snr_db"].low, PARAMETER_LIMITS["snr_db"].high)
#: Largest ``max_torque``, N m (large thrusters; reaction wheels give < 1 N m).
MAX_TORQUE_LIMIT = PARAMETER_LIMITS["max_torque"].high
#: Largest initial body rate per axis, deg/s (the model assumes slow rotation).
MAX_INITIAL_RATE_DEG_S = 10.0

#: Observation bounds per group (far outside the small-angle model's validity).
_BOUND = {"attitude": np.pi, "rate": np.pi, "deflection": 10.0,
          "attitude_error": 2 * np.pi, "reference": np.pi}


@dataclass(frozen=True)
class RewardWeights(CostWeights):
    """The stage cost the reward is built from, and the reward's two scales.

    The cost is the project's common quadratic stage cost
    (:class:`spacecraft_conventions.CostWeights`, the one the harness reports
    and every LQG minimizes): ``cost = attitude * |e / 1 deg|^2 + rate *
    |omega / 0.1 deg/s|^2 + deflection * |w / 1 cm|^2 + torque * |u / 1 N m|^2``
    with ``e`` the true attitude error (rad), ``omega`` the true body rates
    (rad/s) and ``w`` the true tip deflections (m) of the state the step
    produced, and ``u`` the torque applied during the step (N m, ``info["torque"]``).

    ``saturation`` is the cost at which the bounded reward
    (``reward="bounded"``: ``1 - min(cost / saturation, 1)``) reaches 0;
    the default, 300, is the cost of a 10 deg error on all three axes (the
    largest slew the slew task draws) with the default weights.
    ``precision`` is the cost the log-scaled reward resolves down to
    (``reward="log"``: ``1 - log(1 + cost / precision) / log(1 + saturation /
    precision)``, clipped at 0); the default, 3e-4, is a 0.01 deg error on
    all three axes, the attitude an LQG holds.

    Attributes
    ----------
    attitude, rate, deflection, torque : float
        The cost's weights (:class:`spacecraft_conventions.CostWeights`;
        defaults 1, 1, 0.1 and 0.3 per (N m)^2).
    saturation : float
        Cost at which the bounded reward reaches 0 (default 300); > 0.
    precision : float
        Cost the log-scaled reward resolves down to (default 3e-4); > 0.

    All are finite and >= 0 (``ValueError`` otherwise) and stored as floats.
    """

    saturation: float = 300.0
    precision: float = 3e-4

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.saturation == 0 or self.precision == 0:
            raise ValueError("reward weights saturation and precision must be > 0")

    @cached_property
    def _log_span(self) -> float:
        """``log(1 + saturation / precision)``: the log reward's scale (once per weights)."""
        return math.log1p(self.saturation / self.precision)

    def log_reward(self, cost: float) -> float:
        """``reward="log"`` for a stage cost: ``1 - log(1 + cost / precision) / log(1 +
        saturation / precision)``, clipped at 0.

        Returns
        -------
        float
            The reward, in [0, 1].
        """
        return max(1.0 - math.log1p(cost / self.precision) / self._log_span, 0.0)


def _vector3(name: str, value: Any) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape == ():
        arr = np.full(3, float(arr))
    if arr.shape != (3,):
        raise ValueError(f"{name} must be a scalar or have shape (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _unknown_keywords(unknown: dict[str, Any]) -> str:
    """The message for keywords :class:`FlexibleSpacecraftEnv` does not take, each with
    the closest one it does take."""
    known = [p for p in inspect.signature(FlexibleSpacecraftEnv.__init__).parameters
             if p not in ("self", "unknown")]
    parts = []
    for name in unknown:
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.5)
        parts.append(f"{name!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    return (f"FlexibleSpacecraftEnv got unexpected keyword argument(s) {', '.join(parts)}; "
            f"it takes {', '.join(known)}")


class FlexibleSpacecraftEnv(gym.Env):
    """Attitude control of the time-varying ETS-VIII flexible spacecraft.

    The plant is the zero-order-hold sample of the rigid-flexible coupling
    model (:class:`spacecraft_env.dynamics.FlexibleSpacecraftModel`; exact,
    or for a turning paddle equal to the exact one to rounding) whose inertia
    and coupling follow a time-varying scenario (docking, solar paddle
    rotation).

    Action space
    ------------
    ``Box(-1, 1, (3,), float32)``, the torque normalized by ``max_torque``:

    | Index | Action      | Min | Max | Physical torque        |
    |-------|-------------|-----|-----|------------------------|
    | 0     | roll torque | -1  | 1   | ``action[0] * max_torque`` N m |
    | 1     | pitch torque| -1  | 1   | ``action[1] * max_torque`` N m |
    | 2     | yaw torque  | -1  | 1   | ``action[2] * max_torque`` N m |

    Out-of-range actions are clipped to [-1, 1] before scaling; NaN/inf, a wrong
    shape or a non-numeric dtype raise.

    Observation space
    -----------------
    ``Box(float32)`` stacking the requested ``outputs`` groups in the order given
    (``env.unwrapped.observation_labels`` names every entry):

    | Group              | Size             | Unit  | Noise std at 0 dB | Bound   |
    |--------------------|------------------|-------|-------------------|---------|
    | ``"attitude"``     | 3                | rad   | 1 deg             | +-pi    |
    | ``"rate"``         | 3                | rad/s | 0.1 deg/s         | +-pi    |
    | ``"deflection"``   | one per sensor (4) | m   | 1 cm              | +-10    |
    | ``"attitude_error"`` | 3 (measured attitude minus reference) | rad | the attitude's | +-2 pi |
    | ``"reference"``    | 3                | rad   | none              | +-pi    |

    The sensor noise is white and Gaussian with standard deviation
    ``scale * 10^(-snr_db / 20)``: at the paper's 40 dB, 0.01 deg, 0.001 deg/s and
    0.1 mm. Values are clipped to the bounds, which lie far outside the model's
    range.

    Reward
    ------
    | ``reward=``          | Per step                                | Range     | Off bounds |
    |----------------------|-----------------------------------------|-----------|------------|
    | ``"cost"`` (default) | ``-c``, ``c`` the quadratic stage cost  | (-inf, 0] | penalty (1) |
    | ``"bounded"``        | ``1 - min(c / s, 1)``                   | [0, 1]    | forfeit (2) |
    | ``"log"``            | ``1 - log(1 + c / q) / log(1 + s / q)`` | [0, 1]    | forfeit (2) |

    ``s`` is ``saturation`` and ``q`` ``precision`` of :class:`RewardWeights`.
    (1) the terminating step is charged every step left to the time limit, see
    Episode end; (2) no penalty, but every later reward is lost.

    The stage cost weighs the true attitude error, rates, deflections and torque
    (:class:`RewardWeights`); the controllers' returns are compared by it. The
    cost form spans six decades (a crash is charged up to about 1e6 times a
    typical stage cost), which swamps the return statistics a learning agent
    normalizes by; with the bounded form (and
    :class:`spacecraft_env.wrappers.ActionRepeat`) PPO learns the slew task
    where it did not with the cost (docs/results/rl.md). The log form keeps the
    bounded form's survival incentive but pays an error of 0.01 deg visibly more
    than one of 0.1 deg (the bounded form pays both 1 - 1e-5 and 1 - 1e-3).

    Episode end
    -----------
    | Signal         | When                                                        |
    |----------------|-------------------------------------------------------------|
    | ``terminated`` | a true attitude angle beyond ``max_attitude_deg`` (20 deg) |
    | ``truncated``  | the registered time limit only (2500 steps = 250 s)        |

    Beyond 20 deg the small-angle model's error passes 2 %.

    With ``reward="cost"`` the terminating step is charged every step left to the
    time limit at the stage cost of an attitude error at the bound on all three
    axes, so no policy that stays within the bound can do worse (with the removed
    ``-v0`` ids crashing paid: full torque until termination scored -2.0e5
    against -2.5e5 for zero torque on the slew task). Stepping after
    ``terminated`` follows Gymnasium's convention (as ``CartPole``): a warning,
    once; the simulation goes on, but every further step returns reward 0 and
    ``terminated=True``. ``step`` before the first ``reset`` raises
    :class:`gymnasium.error.ResetNeeded`.

    Starting state
    --------------
    | ``task=``                  | Initial attitude per axis             | Reference per axis  |
    |----------------------------|---------------------------------------|---------------------|
    | ``"regulation"`` (default) | uniform in +-``initial_attitude_deg`` | 0                   |
    | ``"slew"``                 | 0                                     | +-``slew_range_deg`` |

    Both draws are uniform.

    The initial rates and deflections are zero. ``reset(options=...)`` overrides
    with ``"initial_attitude"`` (rad, (3,)), ``"initial_rate"`` (rad/s, (3,)) and
    ``"reference_attitude"`` (rad, (3,)), and on the family env ``"plant"``.

    Info
    ----
    | Key                | Unit, shape     | Meaning                                      |
    |--------------------|-----------------|----------------------------------------------|
    | ``"time"``         | s               | time after the step                          |
    | ``"state"``        | float64, (n,)   | the true state                               |
    | ``"torque"``       | N m, (3,)       | the applied torque (1)                       |
    | ``"reference"``    | rad, (3,)       | the reference attitude                       |
    | ``"paddle_angle"`` | rad             | the solar-paddle drive encoder               |
    | ``"scenario"``     | dict, ``reset`` | the episode's scenario values (2)            |
    | ``"plant"``        | dict, ``reset`` | the family env's drawn plant (2)             |

    (1) after clipping, scaling, the actuator delay and the rate limit; (2)
    :meth:`Scenario.parameters` and :class:`spacecraft_env.family.PlantDraw`,
    so a randomized draw is on record; privileged: a policy must not read them.
    A real spacecraft reads its paddle drive's encoder, so ``"paddle_angle"`` is
    not privileged.

    Version history
    ---------------
    * v2 (after package 0.2.0): one cost. The reward is built from the project's
      common stage cost (:class:`spacecraft_conventions.CostWeights`, the cost
      the harness reports and every LQG minimizes): torque weighed 0.3 per
      (N m)^2 of the applied torque (v1: 0.01 per normalized action squared,
      3000x less at ``max_torque=10``), the outputs of the state the step
      produced (v1: of the state the action acted on), and
      ``RewardWeights.vibration`` renamed ``deflection``. ``reward="cost"`` is
      minus the harness's stage cost at every step. Dynamics, observations,
      the termination penalty and the bounded and log transforms are
      unchanged; the v1 ids are not registered any more.
    * v1 (package 0.1.0, updated in 0.2.0): leaving the attitude bound
      is charged every step left to the time limit (``reward="cost"``);
      ``reward="bounded"`` added; 0.2.0 adds ``reward="log"``,
      ``FlexibleSpacecraftFamily-v1`` (``scenario="family"``, a new plant
      every episode) and the ``"plant"`` info and reset option, and
      stepping after termination returns reward 0 (the penalty is
      charged once).
    * v0 (package 0.1.0 only): an episode that left the bound ended with
      no penalty, so crashing paid; not registered any more.

    Parameters
    ----------
    scenario : str or Scenario
        ``"constant"``, ``"docking"``, ``"solar_rotation"``,
        ``"paddle_rotation"``, ``"docking_solar_rotation"`` or ``"family"``
        (the adaptation task: a new plant of :class:`spacecraft_env.family.TaskFamily`
        every episode, see ``family``).
    family : TaskFamily, optional
        Draw the plant of every episode from this family (hub inertia, modal
        stiffness, actuator efficiency, docking, paddle angle and rate;
        :mod:`spacecraft_env.family`); the draw is in ``reset``'s
        ``info["plant"]`` and ``reset(options={"plant": {...}})`` sets it. The
        actuator efficiency scales the torque the plant receives;
        ``info["torque"]`` stays the commanded torque (what the spacecraft
        knows). ``scenario="family"`` selects :class:`TaskFamily`'s defaults.
    randomize : bool
        Draw a random scenario variant (docking times, masses and off-axis
        offsets; rotation rate) from ``self.np_random`` at every reset.
    n_modes : int
        Modes per appendage, 1..8 (ignored when ``params`` is given).
    params : SpacecraftParameters, optional
        Full parameter set (default: ETS-VIII).
    outputs : sequence of str, optional
        Observation groups, see above. Default: the three sensor groups, and
        on the slew task also ``"reference"``: the target is part of the
        task, so a policy (or a controller called through ``predict``) sees
        it in the observation, never only in ``info``.
    snr_db : float or None
        Measurement signal-to-noise ratio in dB relative to the nominal levels
        (paper: 40), in [-40, 300]; None is noiseless.
    max_torque : float
        Torque for a unit action, N m, in (0, 1e4] (default 10).
    dt : float
        Sample time, s.
    task : {"regulation", "slew"}
        How the reference and initial attitude are drawn at reset.
    initial_attitude_deg, slew_range_deg : float
        Ranges of the random initial attitude and slew reference, deg.
    disturbance_torque : float or (3,) array_like
        Constant external torque, N m.
    disturbance_std : float
        Standard deviation of a white external torque, N m.
    actuator_delay_steps : int
        Transport delay of the actuators, samples (default 0): the torque
        commanded at step k acts from step k + ``actuator_delay_steps``.
    torque_rate_limit : float or None
        Slew-rate limit of each actuator, N m/s (default None: unlimited):
        the applied torque moves toward the (delayed) command by at most
        ``torque_rate_limit * dt`` per step, as a reaction wheel's
        acceleration limit does.
    reward : {"cost", "bounded", "log"}
        Reward form, see above.
    reward_weights : RewardWeights, optional
    max_attitude_deg : float
        Termination bound on any attitude angle, deg.
    render_mode : {"human", "rgb_array"}, optional

    Examples
    --------
    Every scenario is a registered id (:data:`ENV_IDS`); keywords reach the
    constructor:

    >>> import gymnasium as gym
    >>> import numpy as np
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraftPaddleRotation-v2", task="slew")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.unwrapped.observation_labels[-3:]
    ((13,), ('ref_x', 'ref_y', 'ref_z'))
    >>> obs, reward, terminated, truncated, info = env.step(np.zeros(3, dtype=np.float32))
    >>> info["time"], info["torque"].tolist(), terminated, truncated
    (0.1, [0.0, 0.0, 0.0], False, False)
    >>> env.close()
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(self, scenario: str | Scenario = "constant", *, randomize: bool = False,
                 family: TaskFamily | None = None,
                 n_modes: int = 2, params: SpacecraftParameters | None = None,
                 outputs: Sequence[str] | None = None, snr_db: float | None = DEFAULT_SNR_DB,
                 max_torque: float = 10.0, dt: float = 0.1, task: str = "regulation",
                 initial_attitude_deg: float = 2.0, slew_range_deg: float = 10.0,
                 disturbance_torque: float | Sequence[float] = 0.0,
                 disturbance_std: float = 0.0, actuator_delay_steps: int = 0,
                 torque_rate_limit: float | None = None,
                 reward: str = "cost", reward_weights: RewardWeights | None = None,
                 max_attitude_deg: float = 20.0, render_mode: str | None = None,
                 **unknown: Any) -> None:
        super().__init__()
        if unknown:
            raise TypeError(_unknown_keywords(unknown))
        if isinstance(scenario, str) and scenario != "family" and scenario not in SCENARIOS:
            raise ValueError(f"unknown scenario {scenario!r}; expected one of "
                             f"{sorted([*SCENARIOS, 'family'])}")
        if params is None:
            params = ets8_parameters(n_modes)
        if isinstance(scenario, str) and scenario == "family":
            family = family or TaskFamily()
            scenario = "docking_solar_rotation"
        if family is not None and not isinstance(family, TaskFamily):
            raise TypeError(f"family must be a TaskFamily or None, got {type(family).__name__}")
        self.family = family
        self._base_params = params
        self.plant = PlantDraw() if family is not None else None
        self._base_scenario = make_scenario(scenario)
        if not isinstance(randomize, bool | np.bool_):
            raise TypeError(f"randomize must be True or False, got {randomize!r}")
        self.randomize = bool(randomize)
        self.model = FlexibleSpacecraftModel(params, self._base_scenario, OUTPUT_GROUPS, dt)
        if outputs is None:      # a policy must see the target it is asked to reach
            outputs = OUTPUT_GROUPS + (("reference",) if task == "slew" else ())
        if isinstance(outputs, str):
            outputs = (outputs,)
        outputs = tuple(outputs)
        bad = [o for o in outputs if o not in OBSERVATION_GROUPS]
        if bad or not outputs or len(set(outputs)) != len(outputs):
            raise ValueError(f"outputs must be distinct names from {OBSERVATION_GROUPS}, "
                             f"got {outputs}")
        self.outputs = outputs
        self.snr_db = None if snr_db is None else check_parameter("snr_db", snr_db)
        self.max_torque = check_parameter("max_torque", max_torque)
        if task not in ("regulation", "slew"):
            raise ValueError(f"task must be 'regulation' or 'slew', got {task!r}")
        self.task = task
        initial_attitude_deg = check_parameter("initial_attitude_deg", initial_attitude_deg)
        slew_range_deg = check_parameter("slew_range_deg", slew_range_deg)
        if not 0 < max_attitude_deg <= 90:
            raise ValueError(f"max_attitude_deg must be in (0, 90], got {max_attitude_deg}")
        drawn = initial_attitude_deg if task == "regulation" else slew_range_deg
        if drawn >= max_attitude_deg:
            raise ValueError(f"the {task} range ({drawn} deg) must stay below "
                             f"max_attitude_deg ({max_attitude_deg} deg)")
        self.initial_attitude = float(initial_attitude_deg) * RAD_PER_DEG
        self.slew_range = float(slew_range_deg) * RAD_PER_DEG
        self.max_attitude = float(max_attitude_deg) * RAD_PER_DEG
        self.disturbance_torque = _vector3("disturbance_torque", disturbance_torque)
        for value in self.disturbance_torque:
            check_parameter("disturbance_torque", value)
        self.disturbance_std = check_parameter("disturbance_std", disturbance_std)
        self.actuator_delay_steps = check_parameter("actuator_delay_steps", actuator_delay_steps)
        self.torque_rate_limit = (None if torque_rate_limit is None
                                  else check_parameter("torque_rate_limit", torque_rate_limit))
        if reward not in REWARDS:
            raise ValueError(f"reward must be one of {REWARDS}, got {reward!r}")
        self.reward = reward
        self.reward_weights = reward_weights or RewardWeights()
        if not isinstance(self.reward_weights, RewardWeights):
            raise TypeError("reward_weights must be a RewardWeights instance")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} "
                             f"or None, got {render_mode!r}")
        self.render_mode = render_mode
        self._build_spaces()
        self._x = np.zeros(self.model.n)
        self._set_reference(np.zeros(3))
        self._k = 0
        self._commands: deque = deque()
        self._torque = np.zeros(3)
        self._renderer = None
        #: The torque the wheels deliver for the commanded one (N m, (3,) -> (3,)), or
        #: None: all of it. Set by :class:`spacecraft_env.faults.FaultInjection`;
        #: ``info["torque"]`` and the cost keep the commanded torque.
        self.actuator_fault = None

    # ----------------------------------------------------------------- set-up
    def _build_spaces(self) -> None:
        m = self.model
        plant = m.output_layout                          # every plant output, canonical order
        # extended measurement vector: [y (plant outputs), attitude error (3), reference (3)]
        extended = OutputLayout((*plant.groups, ("attitude_error", 3), ("reference", 3)))
        self.observation_layout = OutputLayout.of(self.outputs, m.n_sensors)
        ext_labels = [*m.output_labels,
                      *(f"{LABEL_PREFIX[g]}_{axis}" for g in ("attitude_error", "reference")
                        for axis in AXES)]
        self._obs_index = np.concatenate([extended.indices(g) for g in self.outputs])
        # each observed entry is one plant output (row ``_obs_source``, the reference
        # rows read the constant 0 appended after the outputs) plus an offset: 0,
        # minus the reference (attitude error) or the reference; built without
        # concatenating the extended vector at every step
        n_out = plant.size
        source = np.r_[np.arange(n_out), np.arange(3), np.full(3, n_out)]
        self._obs_source = source[self._obs_index]
        self._y = np.zeros(n_out + 1)            # plant outputs, then the constant 0
        self._clean = np.zeros(n_out)            # noiseless outputs C x of the current state
        self._ref_terms = []                     # (sign, observation rows, their axes)
        for sign, group in ((-1.0, "attitude_error"), (1.0, "reference")):
            first = extended.indices(group)[0]
            rows = np.flatnonzero((self._obs_index >= first) & (self._obs_index < first + 3))
            self._ref_terms.append((sign, rows, self._obs_index[rows] - first))
        self.observation_labels = tuple(ext_labels[i] for i in self._obs_index)
        high = np.concatenate([np.full(size, _BOUND[g], dtype=np.float32)
                               for g, size in self.observation_layout.groups])
        self._obs_high = high.astype(float)
        self._obs_low = -self._obs_high
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        scale = plant.scales()
        self.noise_std = (np.zeros_like(scale) if self.snr_db is None
                          else scale * 10.0 ** (-self.snr_db / 20.0))
        self._cost_weights = output_cost_weights(plant, self.reward_weights)

    # ------------------------------------------------------------- properties
    @property
    def time(self) -> float:
        """Current time, s."""
        return self._k * self.model.dt

    @property
    def state(self) -> np.ndarray:
        """Copy of the true state x (float64, (n,))."""
        return self._x.copy()

    @property
    def reference(self) -> np.ndarray:
        """Copy of the reference attitude (rad, (3,))."""
        return self._ref.copy()

    @property
    def scenario(self) -> Scenario:
        """The scenario of the current episode (a random draw if ``randomize``)."""
        return self.model.scenario

    @property
    def actuator_gain(self) -> float:
        """Torque the plant receives per torque commanded: the task family's drawn
        actuator efficiency (:attr:`PlantDraw.actuator_gain`), 1 for the other
        scenarios. ``info["torque"]`` is the commanded torque; a controller that
        knows the true plant (the oracles) scales its input matrix by this."""
        return 1.0 if self.plant is None else float(self.plant.actuator_gain)

    def set_reference(self, reference: Sequence[float]) -> None:
        """Change the reference attitude (rad, (3,)) mid-episode."""
        ref = _vector3("reference", reference)
        if np.any(np.abs(ref) >= self.max_attitude):
            raise ValueError(f"reference must stay within +-{np.rad2deg(self.max_attitude)} deg")
        self._set_reference(ref)

    # ------------------------------------------------------------------- core
    def _set_reference(self, ref: np.ndarray) -> None:
        self._ref = ref
        offset = np.zeros(self._obs_index.size)
        for sign, rows, axes in self._ref_terms:
            offset[rows] = sign * ref[axes]
        self._obs_offset = offset
        self._ref_outputs = np.zeros(self._clean.size)     # the reference on the attitude rows
        self._ref_outputs[:3] = ref

    def _observe(self) -> np.ndarray:
        y = self._y
        outputs = y[:-1]                   # self._clean: C x, set by reset and step
        if self.snr_db is not None:
            np.add(self._clean, self.noise_std * self.np_random.standard_normal(outputs.shape[0]),
                   out=outputs)
        else:
            outputs[:] = self._clean
        obs = y[self._obs_source]
        obs += self._obs_offset
        np.minimum(obs, self._obs_high, out=obs)   # np.clip's dispatch costs more than the work
        np.maximum(obs, self._obs_low, out=obs)
        return obs.astype(np.float32)

    def _info(self) -> dict[str, Any]:
        t = self._k * self.model.dt
        return {"time": t, "state": self._x.copy(), "torque": self._torque.copy(),
                "reference": self._ref.copy(),
                "paddle_angle": float(self.model.scenario.paddle_angle(t))}

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        allowed = {"initial_attitude", "initial_rate", "reference_attitude"} | (
            {"plant"} if self.family is not None else set())
        unknown = set(options) - allowed
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; expected one of "
                             f"{sorted(allowed)}")
        rng = self.np_random
        if self.task == "regulation":
            psi0 = rng.uniform(-self.initial_attitude, self.initial_attitude, 3)
            ref = np.zeros(3)
        else:
            psi0 = np.zeros(3)
            ref = rng.uniform(-self.slew_range, self.slew_range, 3)
        if "initial_attitude" in options:
            psi0 = _vector3("initial_attitude", options["initial_attitude"])
        rate0 = _vector3("initial_rate", options.get("initial_rate", 0.0))
        if np.any(np.abs(rate0) > MAX_INITIAL_RATE_DEG_S * RAD_PER_DEG):
            raise ValueError(f"initial_rate must stay within +-{MAX_INITIAL_RATE_DEG_S:g} deg/s "
                             f"per axis (slow-rotation model), got {rate0.tolist()} rad/s")
        if "reference_attitude" in options:
            ref = _vector3("reference_attitude", options["reference_attitude"])
        if np.any(np.abs(psi0) >= self.max_attitude) or np.any(np.abs(ref) >= self.max_attitude):
            raise ValueError("initial and reference attitudes must stay within "
                             f"+-{np.rad2deg(self.max_attitude)} deg")
        if self.family is not None:
            plant = options.get("plant")
            self.plant = (self.family.draw(rng) if plant is None else
                          plant if isinstance(plant, PlantDraw) else PlantDraw.from_dict(plant))
            self.model = FlexibleSpacecraftModel(self.plant.parameters(self._base_params),
                                                 self.plant.scenario(), OUTPUT_GROUPS,
                                                 self.model.dt)
        elif self.randomize:
            self.model = self.model.with_scenario(self._base_scenario.randomized(rng))
        nd = self.model.n_dof
        self._x = np.zeros(self.model.n)
        self._x[:3] = psi0
        self._x[nd:nd + 3] = rate0
        self._set_reference(ref)
        self._k = 0
        self._terminated = False
        self._warned_after_end = False
        self._captures = self.model.capture_steps()
        self._torque = np.zeros(3)
        self._commands = deque([np.zeros(3)] * self.actuator_delay_steps)
        np.matmul(self.model.C, self._x, out=self._clean)
        obs = self._observe()
        if self.render_mode == "human":
            self.render()
        info = self._info()
        info["scenario"] = self.model.scenario.parameters()
        if self.plant is not None:
            info["plant"] = self.plant.as_dict()
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if "_captures" not in self.__dict__:
            raise gym.error.ResetNeeded("cannot call step() before reset(): call "
                                        "env.reset(seed=...) first")
        a = np.asarray(action)
        if a.dtype.kind not in "fiu":
            raise TypeError(f"action must be a real numeric array of shape (3,), got dtype "
                            f"{a.dtype}")
        if a.shape != (3,):
            raise ValueError(f"action must have shape (3,), got {a.shape}")
        # three numbers: Python's scalar checks and clip cost less than numpy's dispatch
        values = a.tolist()
        if not all(map(math.isfinite, values)):
            raise ValueError(f"action must be finite (no NaN or inf), got {values}")
        a = np.array([min(max(v, -1.0), 1.0) for v in values], dtype=float)
        torque = a * self.max_torque
        if self.actuator_delay_steps:
            self._commands.append(torque)
            torque = self._commands.popleft()
        if self.torque_rate_limit is not None:
            move = self.torque_rate_limit * self.model.dt
            torque = self._torque + np.clip(torque - self._torque, -move, move)
        self._torque = torque
        # a wheel's fault (FaultInjection) changes what is delivered, not what is reported
        delivered = torque if self.actuator_fault is None else self.actuator_fault(torque)
        total = self.actuator_gain * delivered + self.disturbance_torque
        if self.disturbance_std > 0:
            total = total + self.disturbance_std * self.np_random.standard_normal(3)
        x = self._x
        model = self.model
        if self._k in self._captures:      # a module that brings its own momentum docks
            x = model.capture(x, self._k * model.dt)
        ad, bd = model._discrete_ab(self._k * model.dt)
        self._x = ad @ x + bd @ total
        self._k += 1
        # the common stage cost (spacecraft_conventions.cost): the true outputs of the
        # state the step produced against the reference, and the torque applied; the
        # noiseless outputs are kept for the observation
        np.matmul(model.C, self._x, out=self._clean)
        err = self._clean - self._ref_outputs
        cost = err @ (self._cost_weights * err) + self.reward_weights.torque * (torque @ torque)
        if self._terminated:
            # Gymnasium's convention (as CartPole): stepping past the end is undefined;
            # warn once, keep simulating, pay nothing, charge no penalty again
            if not self._warned_after_end:
                self._warned_after_end = True
                gym.logger.warn("You are calling 'step()' even though this environment has "
                                "already returned terminated = True. You should always call "
                                "'reset()' once you receive 'terminated = True'; further "
                                "steps return reward 0 and terminated = True.")
            return self._observe(), 0.0, True, False, self._info()
        terminated = max(map(abs, self._x[:3].tolist())) > self.max_attitude
        self._terminated = terminated
        if self.reward == "bounded":
            reward = 1.0 - min(float(cost) / self.reward_weights.saturation, 1.0)
        elif self.reward == "log":
            reward = self.reward_weights.log_reward(float(cost))
        else:
            reward = -float(cost + self.termination_penalty()) if terminated else -float(cost)
        obs = self._observe()
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, False, self._info()

    def termination_penalty(self) -> float:
        """Cost charged when the attitude bound is left at the current step.

        Every step left to the time limit (``spec.max_episode_steps``, or the
        registered 2500 without a spec) at the stage cost of an attitude
        error of ``max_attitude_deg`` on all three axes: more than any policy
        that stays within the bound can lose by staying.

        Returns
        -------
        float
            The cost charged (dimensionless, the stage cost's units).
        """
        spec = getattr(self, "spec", None)
        limit = spec.max_episode_steps if spec is not None and spec.max_episode_steps \
            else MAX_EPISODE_STEPS
        at_bound = 3 * self.reward_weights.attitude * (
            self.max_attitude / NOMINAL_SCALE["attitude"]) ** 2
        return float(max(limit - self._k + 1, 1) * at_bound)

    # -------------------------------------------------------------- rendering
    def render(self) -> np.ndarray | None:
        """The current state drawn: the hub, the paddles and the reflectors, in two views.

        Returns
        -------
        (400, 720, 3) uint8 ndarray or None
            The frame with ``render_mode="rgb_array"``; None otherwise (shown in a
            window with "human").
        """
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode="
                            "'rgb_array' or 'human' to the constructor")
            return None
        if self._renderer is None:
            self._renderer = SpacecraftRenderer(self.model)
        frame = self._renderer.draw(self._x, self.time, self.model, self._ref)
        if self.render_mode == "rgb_array":
            return frame
        self._renderer.show(frame, self.metadata["render_fps"])
        return None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state
