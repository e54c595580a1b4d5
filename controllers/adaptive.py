"""Certainty-equivalence LQG on the identified model, re-designed every step.

Every control step k (docs/design/control.md):

1. ``x_{k|k}`` from the controller's own Kalman filter on the current
   identified ``(A, B, C)`` (``rigid_state="kalman"``, the default), with
   the sensors' specified noise and the applied torque in its time update:
   the filter the oracle LQG runs on the true model, run on the identified
   one. Its process noise (white torque through ``B``) is chosen online
   from the innovations (:class:`controllers.noise_intensity.ProcessNoiseBank`,
   ``noise_intensity=None``): 0.05 N m, what every fixed design's filter
   assumes, while the model does not predict well, down to none on a quiet
   plant flown on a model that fits it. The identifier's own filter (``"filter"``)
   is tuned for prediction and made the loop reject its gain 5-10x more
   often; reading attitude and rate from the sensors (``"measured"``, the
   former default) pushes the gyro noise through the rate gain (0.05-0.07
   N m of white torque per axis). Measurements: docs/design/control.md;
2. the gain designed on the current identified ``(A, B, C)``, with integral
   action on the attitude error (:class:`controllers.lqg.LQGLaw`): each
   model the identifier exports is solved exactly once and kept while the
   identifier holds it;
3. the gain's acceptance test (:class:`controllers.acceptance.GainAcceptance`:
   effective stiffness and damping on every axis against the robust fixed
   design's, stability with the integral, the model's recent prediction
   agreement, and the disk margin at the torque input of the loop with the
   model's Kalman predictor, evaluated every :data:`MARGIN_EVERY`
   samples; where it does not cover the identifier's band of the
   rigid-body gain, the loop on the model must be stable for real input
   gains across the band, 10 % wider, checked at four gains). A gain that
   fails does not fly: the robust fixed design
   (:class:`controllers.baselines.RobustLQG`), which runs alongside all
   the time, acts instead. Until the identifier has its first model (its
   warm-up) a gentle attitude PD flies instead (``warmup_controller``):
   the robust design's faster rigid-body loop flew the start's slew or
   attitude correction without damping the modes, and what it left
   ringing was most of what the loop cost after 100 s. A supervisor also
   takes the identified design off for :data:`SUPERVISOR_HOLD_S` when the measured envelope grows
   (:meth:`AdaptiveLQG._supervise`): a stale model can pass every test on
   itself;
4. identification in proportion to need: until the sensors show an attitude
   error or rate beyond their noise (:class:`controllers.excitation.MotionNeed`)
   the robust fallback flies with no excitation, since a model could improve
   nothing (held at rest the loop flies the robust design's torques, where the
   warm-up's excitation cost about 1000 times as much); then a designed
   excitation (:class:`controllers.excitation.BinaryExcitation`)
   is added only when information is needed (dual control): the warm-up's
   budget while the identifier warms up (at the identifier's
   ``warmup_amplitude`` if it states one, else 1 N m), and afterwards an
   amplitude that grows from 0 with the identifier's calibrated uncertainty
   of the rigid-body gain beyond what the design tolerates
   (``uncertainty_tolerance``), up to ``excitation_budget``, steered toward
   the torque directions the identifier knows least, for at most
   :data:`EXCITATION_WINDOW_S` after the warm-up or after a change the
   identifier detects. At steady state, with the gain known, there is none;
   it returns when the identifier's covariance grows after a detected
   change, for identifiers that run a change test
   (:data:`identifiers.CLOSED_LOOP_SETTINGS` does not); where the
   uncertainty stays above the tolerance (30 dB) it stops at the window's
   end instead of running at the budget for good;
5. the measurement and the torque actually applied after it (the env's
   ``info["torque"]``, which includes whatever a wrapper added to this
   controller's action) go to the identifier, at the start of the next step.

:attr:`AdaptiveLQG.stats` counts steps, steps flown by the fallback,
re-designs, gains rejected (by reason, "growing" for the supervisor's holds),
failed designs and non-finite observations, the steps (and fallback steps)
from :data:`controllers.harness.JUDGED_FROM_S` with the cause of each of those
fallback steps (``fallback_by_after_60s``, keys of :data:`FALLBACK_CAUSES`), the
faults it inferred (``faults``: :class:`controllers.gyro_bias.GyroBiasMonitor`'s and
:class:`controllers.actuator_monitor.ActuatorMonitor`'s, in the order declared),
the identifier's fits (``fits``: its ``fit_log``, each fit's latency, CPU time and
outcome, for identifiers that fit off the control path), and reports the
excitation's RMS torque.
"""

from __future__ import annotations

import logging
import warnings
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from controllers.acceptance import (
    REJECTION_REASONS,
    GainAcceptance,
    input_disk_margin,
    stable_under_input_gains,
)
from controllers.actuator_monitor import ActuatorMonitor
from controllers.base import PADDLE_ANGLE, Controller
from controllers.baselines import PD, RobustLQG, _LQGController, process_noise
from controllers.excitation import NEED_SIGMAS, BinaryExcitation, MotionNeed, warmup_excitation
from controllers.gyro_bias import GyroBiasMonitor
from controllers.harness import ENVELOPE_FLOOR, GROWTH_LIMIT, JUDGED_FROM_S
from controllers.loop_identifiers import closed_loop_identifier
from controllers.lqg import LQRWeights
from controllers.noise_intensity import ProcessNoiseBank
from controllers.riccati import check_iterations
from identifiers import OnlineIdentifier
from spacecraft_conventions import single_threaded_blas
from spacecraft_conventions.kept import KeptWhileEqual

__all__ = ["EXCITATION_WINDOW_S", "FALLBACK_CAUSES", "FALLBACK_WARNING_S", "AdaptiveLQG",
           "FallbackWarning", "ScheduleWarning"]

log = logging.getLogger(__name__)

#: Memory (samples) of the running prediction-agreement measure.
AGREEMENT_MEMORY = 100
#: Horizon (samples) of the prediction-agreement measure: 1 s.
AGREEMENT_HORIZON = 10
#: Excitation amplitude per axis (N m) after the warm-up for an identifier that
#: reports no uncertainty of its rigid-body gain.
PERMANENT_EXCITATION = 0.1
#: Seconds after the identifier's warm-up, and after each change it detects, during
#: which the dual excitation may run (:class:`AdaptiveLQG`, ``excitation_window_s``).
#: Where the uncertainty stays above the tolerance at the budget's amplitude (30 dB),
#: more time at that amplitude did not bring it under: bounding the excitation to
#: this window cost 0.64-0.91x over 10 seeds on the three slews at 30 dB, lower on
#: every seed, and changed nothing where the excitation ends by itself
#: (docs/design/control.md, "Excitation bounded in duration").
EXCITATION_WINDOW_S = 30.0
#: Samples between evaluations of the loop's disk margin (it costs about a
#: re-design's worth; the gain moves little in 1 s).
MARGIN_EVERY = 10
#: The supervisor's windows, s: the peaks of the measured attitude error and tip
#: deflections (in their nominal scales) over consecutive windows of this length.
SUPERVISOR_WINDOW_S = 10.0
#: Windows whose peaks the supervisor fits (100 s): a log-linear fit growing by more
#: than the harness's :data:`controllers.harness.GROWTH_LIMIT` per 100 s, with the
#: last peak above its envelope floor, takes the identified design off for
#: :data:`SUPERVISOR_HOLD_S`: the harness's fast-growth verdict, given by the
#: controller from its sensors while the loop is still small (the harness's slow,
#: significant growth, :data:`controllers.harness.SLOW_GROWTH_LIMIT`, is not watched:
#: over 100 s of noisy measurements it would need its own validation).
SUPERVISOR_WINDOWS = 10
SUPERVISOR_HOLD_S = 60.0
#: Seconds after :data:`controllers.harness.JUDGED_FROM_S` without a single step of the
#: identified design after which the loop warns (:class:`FallbackWarning`), once.
FALLBACK_WARNING_S = 60.0


#: Why the fallback flies a step (``stats["fallback_by_after_60s"]``): the acceptance
#: test's reason for the step's rejected gain (:data:`controllers.acceptance.REJECTION_REASONS`),
#: a re-design that failed ("failed design"), the supervisor's hold after a growing
#: envelope ("growing"), the bridge after a detected change ("bridge"), an accepted
#: gain waiting out the dwell time ("dwell"), no identified model yet ("no model"), no
#: usable state estimate on it ("no state"), or no motion beyond the sensors' noise yet
#: ("at rest": nothing for the identified design to improve, :class:`MotionNeed`).
FALLBACK_CAUSES = (*REJECTION_REASONS, "failed design", "growing", "bridge", "dwell",
                   "no model", "no state", "at rest")


class FallbackWarning(UserWarning):
    """The adaptive loop has flown only its fallback for a long time: the identified
    models were all rejected (the identifier may not suit the loop)."""


class ScheduleWarning(UserWarning):
    """The identifier is scheduled on the drive angle of turning appendages, and a step
    came without the angle (``info["paddle_angle"]``): without ``info`` (e.g. through
    SB3's ``predict``) the identifier keeps the last angle it was given (0 at first), as
    if the drive did not turn."""


@njit(cache=True, nogil=True)
def _propagate(a: np.ndarray, b: np.ndarray, x0: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """``x_H`` of ``x_{k+1} = A x_k + B u_k`` from ``x0`` under the ``H`` rows of
    ``inputs``, compiled."""
    x = x0
    for k in range(inputs.shape[0]):
        x = a @ x + b @ inputs[k]
    return x


class AdaptiveLQG(_LQGController):
    """LQG re-designed every step on the model of an online identifier.

    Parameters
    ----------
    env : gymnasium.Env
        Environment the controller is built for (layout, torque scale).
    identifier : identifiers.OnlineIdentifier, optional
        Default: :func:`controllers.closed_loop_identifier`, i.e. the
        drive-scheduled physical fit (:func:`controllers.scheduled_identifier`)
        where the env's model describes its appendages and the env observes
        the tip deflections (every registered id with its default outputs),
        else the structured recursive identifier
        (:func:`controllers.fast_identifier`: :func:`identifiers.default_identifier`
        for the measured sensor groups with
        :data:`identifiers.CLOSED_LOOP_SETTINGS`; the default until 2026-11-28,
        about 0.5 s of computation per 250 s episode against the fit's 11-32 s).
    weights : LQRWeights
    excitation : BinaryExcitation, optional
        The signal: default the identifier's ``warmup_amplitude`` (N m per
        axis; 1 N m for an identifier without one) during its warm-up, then
        driven by the uncertainty (see step 4).
    uncertainty_tolerance : float
        Relative standard deviation of the identified rigid-body gain the
        design tolerates without excitation (default 0.1: a 2-sigma band of
        20 %, which the disk-margin test covers with margin 0.25).
    excitation_budget : float
        Largest excitation amplitude per axis after the warm-up, N m
        (default 0.1, 1 % of the actuator), reached at twice the tolerated
        uncertainty.
    excitation_window_s : float
        Seconds after the identifier's warm-up, and after each change it
        detects (its ``events``), during which that excitation may run
        (default :data:`EXCITATION_WINDOW_S`, 30); then it stops, whatever
        the uncertainty (the acceptance test still reads it). ``inf``: no
        bound, the behaviour before 2026-11-26. An identifier that reports
        no uncertainty gets a permanent small excitation either way.
    acceptance : GainAcceptance, optional
    fallback : Controller, optional
        Flies when no accepted gain exists once the identifier has a model
        (default :class:`RobustLQG`).
    warmup_controller : Controller, optional
        Flies until the identifier has its first model (its warm-up):
        default :class:`controllers.baselines.PD` at its default 0.05
        rad/s, a decade below the first flexible mode. The robust
        design in this role left the start's manoeuvre ringing in the modes:
        the same law handed the true model after the 30 s warm-up cost
        1.54x the oracle LQG from 100 s behind it and 0.73x behind the PD
        (constant plant at 120 deg, slew, 4 seeds), 4.73x against 1.77x on
        paddle-rotation regulation (docs/design/control.md). Pass the same
        object as ``fallback`` to keep one controller for both roles.
    bridge_s : float
        Seconds after a detected change during which the fallback flies
        (default 0: the acceptance test, which reads the identifier's
        uncertainty, decides).
    dwell_s : float
        Shortest time, s, between changes from the identified design to the
        fallback or back (default 10): in between, the last accepted gain (or
        the fallback) keeps flying. Without it a loop near the acceptance
        threshold switched every few samples and its two integrators left a
        limit cycle.
    iterations : int or None
        None (default): each new identified model's Riccati equation is
        solved exactly, once (a model the identifier holds keeps its design
        and its verdict); an integer: that many warm-started Riccati
        iterations per step, the behaviour before 2026-11-29
        (:class:`controllers.riccati.RiccatiTracker`).
    rigid_state : {"kalman", "filter", "measured"}
        Where the state comes from (see step 1 above): "kalman" (default)
        this controller's own Kalman filter on the identified model, with
        the process noise of ``noise_intensity``; "filter" the identifier's
        own filter (:meth:`identifiers.OnlineIdentifier.filtered_state`,
        tuned for prediction, not control); "measured" that filter with the
        attitude and rate states read from the sensors (needs an identifier
        with :attr:`identifiers.OnlineIdentifier.rigid_states`, else as
        "filter"), which feeds the sensor noise through the rate gain.
    need_sigmas : float or None
        Identification in proportion to need (:class:`controllers.excitation.MotionNeed`):
        until a sample shows an attitude error or rate beyond this many standard
        deviations of the sensor's specified noise (default :data:`NEED_SIGMAS`), the
        robust fallback flies, no excitation is added and no identified design flies
        (fallback cause "at rest"); a spacecraft held at rest is not shaken. None:
        identify from the first sample whatever the motion (the behaviour before
        2026-12-07).
    monitor_gyro : bool
        Run :class:`controllers.gyro_bias.GyroBiasMonitor` on the observations
        (default True): a gyro bias it declares is reported (a
        :class:`controllers.gyro_bias.FaultWarning`, ``stats["faults"]``) and
        subtracted from that gyro before the fallback, the identifier and the law
        see it; with no fault declared the readings pass untouched.
    monitor_actuators : bool
        Run :class:`controllers.actuator_monitor.ActuatorMonitor` (default True):
        a wheel that does not deliver its command (a bias, a stuck or weak wheel)
        is reported, and an axis whose wheel does not answer is reported lost
        (``stats["faults"]``, a :class:`controllers.gyro_bias.FaultWarning`); it
        reports only, the loop flies as without it.
    noise_intensity : float or None
        The white torque per axis, N m, the own Kalman filter assumes (``rigid_state=
        "kalman"``). None (default): chosen online from the innovations among
        :data:`controllers.noise_intensity.NOISE_LEVELS`
        (:class:`controllers.noise_intensity.ProcessNoiseBank`, :attr:`noise_bank`;
        the level in use at the end in ``stats["noise_intensity_Nm"]``); a number:
        that torque, fixed (0.05, :data:`controllers.baselines.PROCESS_NOISE`: the
        behaviour before 2026-12-07).

    Examples
    --------
    The warm-up controller (a gentle PD) flies while the identifier warms up
    (30 s in closed loop); from then on every step re-designs from its model
    and the design flies once the acceptance test passes (the robust fixed
    design stands in when it does not):

    >>> import gymnasium as gym
    >>> from controllers import AdaptiveLQG, run_episode
    >>> env = gym.make("spacecraft_env:FlexibleSpacecraft-v2")
    >>> ctrl = AdaptiveLQG(env)
    >>> type(ctrl.identifier).__name__           # closed_loop_identifier(env)
    'ScheduledPhysicalIdentifier'
    >>> traj = run_episode(env, ctrl, seed=0, max_steps=420)
    >>> ctrl.identifier.warmup, ctrl.identifier.model is not None
    (300, True)
    >>> stats = traj.controller_stats
    >>> stats["steps"], stats["fallback_steps"] >= ctrl.identifier.warmup
    (420, True)

    The fit ran off the control path; its model flew from 10 s after it fell due
    (:data:`controllers.LOOP_FIT_TIMING`), recorded with its CPU time:

    >>> fit = stats["fits"][0]
    >>> fit["action"], fit["sample"], fit["adopted"], fit["outcome"]
    ('first_fit', 300, 400, 'adopted')
    >>> env.close()
    """

    name = "adaptive LQG"

    def __init__(self, env: gym.Env, identifier: OnlineIdentifier | None = None,
                 weights: LQRWeights | None = None, excitation: BinaryExcitation | None = None,
                 acceptance: GainAcceptance | None = None, fallback: Controller | None = None,
                 bridge_s: float = 0.0, iterations: int | None = None,
                 rigid_state: str = "kalman", uncertainty_tolerance: float = 0.1,
                 excitation_budget: float = 0.1,
                 excitation_window_s: float = EXCITATION_WINDOW_S, dwell_s: float = 10.0,
                 warmup_controller: Controller | None = None,
                 need_sigmas: float | None = NEED_SIGMAS, monitor_gyro: bool = True,
                 monitor_actuators: bool = True,
                 noise_intensity: float | None = None) -> None:
        super().__init__(env, weights)
        if noise_intensity is not None and not (np.isfinite(noise_intensity)
                                                and noise_intensity >= 0):
            raise ValueError(f"noise_intensity must be None (chosen online) or a torque "
                             f">= 0 N m, got {noise_intensity}")
        self.noise_intensity = noise_intensity
        self.noise_bank = (ProcessNoiseBank(self.dt) if noise_intensity is None else None)
        self.gyro_monitor = GyroBiasMonitor(env) if monitor_gyro else None
        self.actuator_monitor = ActuatorMonitor(env) if monitor_actuators else None
        self.need = None if need_sigmas is None else MotionNeed(env, need_sigmas)
        if identifier is None:
            identifier = closed_loop_identifier(env)
        if rigid_state not in ("kalman", "filter", "measured"):
            raise ValueError(f"rigid_state must be 'kalman', 'filter' or 'measured', "
                             f"got {rigid_state!r}")
        self.rigid_state = rigid_state
        self.identifier = identifier
        self.excitation = excitation or warmup_excitation(identifier)
        for name, value in (("uncertainty_tolerance", uncertainty_tolerance),
                            ("excitation_budget", excitation_budget)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        self.uncertainty_tolerance = float(uncertainty_tolerance)
        self.excitation_budget = float(excitation_budget)
        if np.isnan(excitation_window_s) or excitation_window_s < 0:
            raise ValueError(f"excitation_window_s must be >= 0 (inf: no bound), got "
                             f"{excitation_window_s}")
        self.excitation_window_s = float(excitation_window_s)
        self.acceptance = acceptance or GainAcceptance()
        self.fallback = fallback or RobustLQG(env, self.weights)
        self.warmup_controller = warmup_controller or PD(env)
        if not (np.isfinite(bridge_s) and bridge_s >= 0):
            raise ValueError(f"bridge_s must be >= 0, got {bridge_s}")
        self.bridge_steps = round(bridge_s / self.dt)
        if not (np.isfinite(dwell_s) and dwell_s >= 0):
            raise ValueError(f"dwell_s must be >= 0, got {dwell_s}")
        self.dwell_steps = round(dwell_s / self.dt)
        self.law.iterations = check_iterations(iterations)
        layout = self.measured_layout
        self._att_rows = layout.indices("attitude")
        self._rate_rows = layout.indices("rate")
        self._defl_rows = (layout.indices("deflection") if "deflection" in layout.names
                           else np.zeros(0, dtype=int))
        self._scales = layout.scales()
        self._window_steps = max(1, round(SUPERVISOR_WINDOW_S / self.dt))
        self._hold_steps = round(SUPERVISOR_HOLD_S / self.dt)
        self._softest_reference = self._reference_design()
        self.reset()

    def _reference_design(self) -> tuple[float, float]:
        """Softest stiffness and damping of the fallback (the acceptance reference)."""
        fb = self.fallback
        if isinstance(fb, RobustLQG):
            return GainAcceptance.softest(fb.a, fb._c, fb.gain[:, :fb.a.shape[0]],
                                          np.arange(3), np.arange(3, 6))
        return (0.0, 0.0)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.identifier.reset()
        self.fallback.reset(seed)
        if self.warmup_controller is not self.fallback:
            self.warmup_controller.reset(seed)
        self.excitation.reset(seed)
        if self.need is not None:
            self.need.reset()
        if self.gyro_monitor is not None:
            self.gyro_monitor.reset()
        if self.actuator_monitor is not None:
            self.actuator_monitor.reset()
        if self.noise_bank is not None:
            self.noise_bank.reset()
        self.gain: np.ndarray | None = None
        self._k = 0
        self._bridge_until = 0
        self._events_seen = 0
        self._err2 = self._sig2 = 0.0
        self._margin: float | None = None
        self._margin_due = 0
        self._stable_over = 0.0
        #: per sensor group, the maps of :meth:`_measured_rigid` for the last model's C
        self._rigid_maps: KeptWhileEqual[list[tuple[np.ndarray, ...]]] = KeptWhileEqual()
        #: the process noise through the own filter's last model's B
        self._process_noise: KeptWhileEqual[np.ndarray] = KeptWhileEqual()
        self._past: deque = deque(maxlen=AGREEMENT_HORIZON)
        self._sample: tuple[np.ndarray | None, np.ndarray, float | None] | None = None
        self._uncertainty = float("inf")
        self._flying = False
        self._flying_gain: np.ndarray | None = None
        self._warm = False             # the identifier has had a model: the warm-up is over
        self._needed = self.need is None       # motion beyond the noise seen (MotionNeed)
        self._excite_until: float | None = None     # end of the dual excitation's window
        self._switched = -self.dwell_steps
        self._peaks: deque = deque(maxlen=SUPERVISOR_WINDOWS)
        self._peak = 0.0
        self._hold_until = 0
        self._fallback_warned = False
        self._schedule_warned = False
        self.last_excitation = np.zeros(3)
        self.stats: dict[str, Any] = {"steps": 0, "fallback_steps": 0, "redesigns": 0,
                                      "rejected": 0, "rejected_by": {}, "failed_designs": 0,
                                      "nonfinite_observations": 0, "excitation_rms_Nm": 0.0,
                                      "excited_steps": 0, "switches": 0,
                                      "steps_after_60s": 0, "fallback_steps_after_60s": 0,
                                      "fallback_by_after_60s": {}}
        # the identifier's fits (off the control path: when each fell due, when its
        # model flew, its CPU time and outcome), for identifiers that fit
        self.stats["fits"] = getattr(self.identifier, "fit_log", [])
        # the faults the loop inferred (kind, axis, onset, when declared, value)
        self.stats["faults"] = []
        self._reason: str | None = None

    # ------------------------------------------------------------ pieces
    def _agreement(self, y: np.ndarray, model: Any, x: np.ndarray | None) -> float:
        """The model's recent 1 s rate prediction error relative to persistence's.

        Every sample, the rates are predicted from the filtered state of
        :data:`AGREEMENT_HORIZON` samples ago, run through the current model
        with the torques applied since; persistence predicts the rates of
        back then. Both errors are running mean squares over
        :data:`AGREEMENT_MEMORY` samples. A one-step prediction would not do:
        the Kalman filter follows the sensors closely, so any model predicts
        one step as well as persistence.
        """
        rates = y[self._rate_rows]
        past = self._past
        if x is not None and np.isfinite(rates).all() and len(past) == AGREEMENT_HORIZON:
            y0 = past[0][1]
            xp = _propagate(np.ascontiguousarray(model.A), np.ascontiguousarray(model.B),
                            past[0][0], np.array([u for _, _, u in past]))
            e2 = float(np.sum((rates - model.C[self._rate_rows] @ xp) ** 2))
            d2 = float(np.sum((rates - y0) ** 2))
            # a non-finite term (a model that overflows over the horizon) never enters the
            # running sums: one NaN there would reject every later gain
            if np.isfinite(e2) and np.isfinite(d2):
                lam = 1.0 - 1.0 / AGREEMENT_MEMORY
                self._err2 = lam * self._err2 + (1 - lam) * e2
                self._sig2 = lam * self._sig2 + (1 - lam) * d2
        return self._err2 / self._sig2 if self._sig2 > 0 else np.inf

    def _measured_rigid(self, x: np.ndarray, y: np.ndarray, c: np.ndarray) -> np.ndarray:
        """``x`` with its attitude and rate states read from ``y`` (where finite):
        the least-squares solution of ``C_g[:, rigid] x_rigid = y_g - C_g[:, rest] x_rest``
        for each of the two sensor groups g."""
        slices = self.identifier.rigid_states
        if slices is None:
            return x
        def maps() -> list[tuple[np.ndarray, ...]]:
            # per sensor group: the pseudo-inverse of its rigid block and the
            # block of the other states; they change only with the model
            states = np.arange(x.size)
            out = []
            for rows, cols in zip((self._att_rows, self._rate_rows), slices, strict=True):
                rigid = states[cols]
                rest = np.setdiff1d(states, rigid)
                out.append((rows, rigid, rest, np.linalg.pinv(c[np.ix_(rows, rigid)]),
                            c[np.ix_(rows, rest)]))
            return out

        x = x.copy()
        for rows, cols, rest, inverse, others in self._rigid_maps.get((c,), maps):
            if np.isfinite(y[rows]).all():
                x[cols] = inverse @ (y[rows] - others @ x[rest])
        return x

    def _own_filter(self, model: Any, y: np.ndarray, info: dict[str, Any] | None
                    ) -> np.ndarray | None:
        """``x_{k|k}`` from this controller's own Kalman filter on the identified model,
        with the sensors' specified noise and the process noise of
        ``noise_intensity`` (the bank's choice, or the fixed torque)."""
        a, b, c = model.A, model.B, model.C
        if not (np.isfinite(a).all() and np.isfinite(b).all() and np.isfinite(c).all()):
            return None
        y = np.where(np.isfinite(y), y, np.nan)
        if self.noise_bank is not None:
            torque = self._applied_torque(info)
            x = self.noise_bank.step(a, b, c, self._noise_var, y, torque)
            self.stats["noise_intensity_Nm"] = self.noise_bank.level
            return x
        level = self.noise_intensity
        noise = self._process_noise.get((b,), lambda: process_noise(b, level))   # per model
        return self._filter(a, b, c, noise, self._noise_var, y, info)

    def _remember(self, x: np.ndarray | None, y: np.ndarray, torque: np.ndarray) -> None:
        """Keep (filtered state, rates, applied torque) of the last samples; a sample
        with a non-finite entry breaks the record (it restarts from the next good one)."""
        if (x is None or not np.isfinite(x).all() or not np.isfinite(torque).all()
                or not np.isfinite(y[self._rate_rows]).all()):
            self._past.clear()
            return
        self._past.append((x, y[self._rate_rows], torque))

    def _commit(self, info: dict[str, Any] | None) -> None:
        """The previous sample ``(u_{k-1}, y_{k-1})`` to the identifier and the
        agreement record, with the torque actually applied after it
        (:meth:`_applied_torque`: the env's report, so a wrapper that adds to
        our action, e.g. an agent's residual, does not mislead the identifier).
        Done at the start of step k, which is, for the identifier, the same
        sequence of operations as at the end of step k-1."""
        if self._sample is None:
            return
        (x, y, schedule), self._sample = self._sample, None
        torque = self._applied_torque(info)
        self._remember(x, y, torque)
        if schedule is not None and hasattr(self.identifier, "set_schedule"):
            self.identifier.set_schedule(schedule)
        # a non-finite measurement goes to the identifier too: it skips and counts it
        # and keeps its past window aligned in time
        self.identifier.update(torque, y)

    def _design(self, model: Any, agreement: float) -> np.ndarray | None:
        """A new accepted gain on ``model``, or None (counted by reason)."""
        a, b, c = model.A, model.B, model.C
        try:
            gain = self.law.design(a, b, c, c[self._att_rows])
        except (ValueError, np.linalg.LinAlgError) as exc:
            self.stats["failed_designs"] += 1
            self.law.tracker = None
            self._reason = "failed design"
            log.debug("redesign failed: %s", exc)
            return None
        reason = self.acceptance.check(a, b, c, gain, self._att_rows, self._rate_rows,
                                       self._softest_reference, agreement, self.dt)
        if reason is None:
            if self._margin is None or self._k >= self._margin_due:
                self._margin = input_disk_margin(a, b, c, model.K, gain, self._att_rows,
                                                 self.dt)
                self._margin_due = self._k + MARGIN_EVERY
                self._stable_over = 0.0
            reason = self.acceptance.check_margin(self._margin, self._uncertainty,
                                                  self._stable_over)
            if reason == "uncertain" and 2.0 * self._uncertainty < 1.0:
                # the disk margin does not cover the gain's band: is the loop stable
                # for real input gains across it? (checked with 10 % to spare, kept
                # until the margin is evaluated again; check_margin judges the result)
                wide = min(2.2 * self._uncertainty, 0.99)
                if stable_under_input_gains(a, b, c, model.K, gain, self._att_rows, self.dt,
                                            1.0 + wide * np.array([-1.0, -0.5, 0.5, 1.0])):
                    self._stable_over = wide
                    reason = self.acceptance.check_margin(self._margin, self._uncertainty,
                                                          wide)
        self._reason = reason
        if reason is not None:
            self.stats["rejected"] += 1
            self.stats["rejected_by"][reason] = self.stats["rejected_by"].get(reason, 0) + 1
            return None
        self.stats["redesigns"] += 1
        return gain

    def _transfer_integral(self, to_identified: bool) -> None:
        """Bumpless transfer: give the design taking over the integral torque the other
        was applying (``G_z z`` equal), so the disturbance it compensated stays
        compensated."""
        fb = self.fallback
        if not isinstance(fb, _LQGController) or self._flying_gain is None \
                or getattr(fb, "gain", None) is None:
            return
        own, other = self._flying_gain, fb.gain
        gz_own, gz_other = own[:, own.shape[1] - 3:], other[:, other.shape[1] - 3:]
        try:
            if to_identified:
                self.law.z = np.linalg.solve(gz_own, gz_other @ fb.law.z)
            else:
                fb.law.z = np.linalg.solve(gz_other, gz_own @ self.law.z)
        except np.linalg.LinAlgError:
            pass

    def _update_excitation(self) -> None:
        """The identifier's calibrated uncertainty of the rigid-body gain, and the
        excitation amplitude it calls for (0 when the design tolerates it)."""
        if not hasattr(self.identifier, "rigid_gain"):
            # an identifier that reports no uncertainty: a permanent small excitation
            self._uncertainty = 0.0
            self.excitation.amplitude = PERMANENT_EXCITATION
            return
        estimate = self.identifier.rigid_gain
        self._uncertainty = (float("inf") if estimate is None
                             else float(estimate.relative_std()))
        tol = self.uncertainty_tolerance
        excess = (self._uncertainty - tol) / tol if tol > 0 else float("inf")
        self.excitation.amplitude = self.excitation_budget * float(np.clip(excess, 0.0, 1.0))
        if estimate is None and getattr(self.identifier, "fit_pending", False):
            # the first fit runs on the warm-up's record: excitation now informs nothing
            self.excitation.amplitude = 0.0
        if self._excite_until is not None and self._k >= self._excite_until:
            self.excitation.amplitude = 0.0          # its window since the last change is over
        shape = getattr(self.identifier, "input_uncertainty", None)
        if callable(shape) and self._k % 50 == 0:
            self.excitation.shape(shape())

    def _fallback_cause(self, held: bool, bridging: bool, usable: bool, wanted: bool) -> str:
        """Why the fallback flies this step: a key of :data:`FALLBACK_CAUSES`."""
        if not self._needed:
            return "at rest"
        if held:
            return "growing"
        if bridging:
            return "bridge"
        if self._reason is not None:            # no model, a failed or a rejected design
            return self._reason
        if not usable:
            return "no state"
        # the design passed: it waits for the dwell time (or, once, for a first gain)
        return "dwell"

    def _warn_if_never_flown(self) -> None:
        """One :class:`FallbackWarning` when the identified design has not flown a single
        step in the :data:`FALLBACK_WARNING_S` seconds after the warm-up's judging start."""
        after = self.stats["steps_after_60s"]
        if (not self._fallback_warned and self._needed and after * self.dt >= FALLBACK_WARNING_S
                and self.stats["fallback_steps_after_60s"] == after):
            self._fallback_warned = True
            reasons = ", ".join(f"{reason} {count}" for reason, count in sorted(
                self.stats["rejected_by"].items(), key=lambda item: -item[1])) or "none"
            model = "no model yet" if self.identifier.model is None else "models rejected"
            # stacklevel 4: past this method, act and its single_threaded_blas wrapper,
            # to the code that called act
            warnings.warn(
                f"AdaptiveLQG has flown only its fallback from {JUDGED_FROM_S:g} s to "
                f"{self._k * self.dt:.0f} s ({type(self.identifier).__name__}: {model}; "
                f"rejections by reason: {reasons}); the identifier may not suit the loop "
                "(see stats['rejected_by'])", FallbackWarning, stacklevel=4)

    def _supervise(self, y: np.ndarray, ref: np.ndarray) -> None:
        """Take the identified design off when the measured envelope grows.

        The identified model can go stale while its gain still passes every
        test on that model (the paddles turn the modal couplings' signs over
        hundreds of seconds). The peaks of the measured attitude error and
        tip deflections (nominal scales) over :data:`SUPERVISOR_WINDOW_S`
        windows are watched while the identified design flies; when a
        log-linear fit of the last :data:`SUPERVISOR_WINDOWS` grows by more
        than :data:`controllers.harness.GROWTH_LIMIT` per 100 s and the
        last is above the harness's envelope floor, the fallback flies for
        :data:`SUPERVISOR_HOLD_S` (counted as a rejection "growing")."""
        level = np.abs(y[self._att_rows] - ref) / self._scales[self._att_rows]
        if self._defl_rows.size:
            level = np.concatenate([level, np.abs(y[self._defl_rows])
                                    / self._scales[self._defl_rows]])
        if np.isfinite(level).all():
            self._peak = max(self._peak, float(level.max()))
        if (self._k + 1) % self._window_steps:
            return
        self._peaks.append(self._peak if self._flying else np.nan)
        self._peak = 0.0
        peaks = np.array(self._peaks)
        if peaks.size < SUPERVISOR_WINDOWS or not np.all(peaks > 0) or \
                peaks[-1] <= ENVELOPE_FLOOR:
            return
        slope = np.polyfit(np.arange(peaks.size) * SUPERVISOR_WINDOW_S, np.log(peaks), 1)[0]
        if np.exp(100.0 * slope) > GROWTH_LIMIT:
            self._hold_until = self._k + self._hold_steps
            self._peaks.clear()
            self.stats["rejected_by"]["growing"] = self.stats["rejected_by"].get("growing", 0) + 1

    def _collect_faults(self) -> None:
        """``stats["faults"]``: every monitor's reports, in the order they were declared."""
        monitors = (self.gyro_monitor, self.actuator_monitor)
        found = [f for m in monitors if m is not None for f in m.faults]
        if len(found) != len(self.stats["faults"]):
            known = {(f["kind"], f["axis"]) for f in self.stats["faults"]}
            new = [f for f in found
                   if f["kind"] == "gyro bias" and (f["kind"], f["axis"]) not in known]
            if new:
                # the attitude walked while the bias went uncompensated: its walk back
                # is a transient the integrals must not charge on
                for law in (self.law, getattr(self.fallback, "law", None)):
                    if law is not None:
                        law.restart_settle()
                # the identifier has had the biased readings since the onset
                correct = getattr(self.identifier, "correct_outputs", None)
                for f in new if correct is not None else ():
                    offset = np.zeros(self._meas_obs.size)
                    offset[self._rate_rows[f["axis"]]] = f["value"]
                    correct(offset, round(f["onset_s"] / self.dt))
            self.stats["faults"] = sorted(found, key=lambda f: f["detected_s"])

    def _watch_events(self) -> None:
        events = getattr(self.identifier, "events", ())
        if len(events) > self._events_seen:
            self._events_seen = len(events)
            self._bridge_until = self._k + self.bridge_steps
            self._open_excitation_window()

    def _open_excitation_window(self) -> None:
        """The dual excitation may run for ``excitation_window_s`` from this step."""
        self._excite_until = self._k + self.excitation_window_s / self.dt

    # ------------------------------------------------------------ the step
    @single_threaded_blas
    def act(self, obs: ArrayLike, info: dict[str, Any] | None = None) -> np.ndarray:
        self.stats["steps"] += 1
        self._commit(info)
        obs = self._observation(obs)
        if self.actuator_monitor is not None:
            # reports only; on the raw readings (a gyro bias's compensation, converging
            # while its estimate does, would read as a torque) and the torque of the last
            # step: the env's report, else the loop's own (SB3's predict gives no info)
            self.actuator_monitor(obs, {"torque": self._applied_torque(info)})
        if self.gyro_monitor is not None:
            obs = self.gyro_monitor(obs)     # a declared gyro bias subtracted
        self._collect_faults()
        if not np.isfinite(obs).all():
            self.stats["nonfinite_observations"] += 1
        y = obs[self._meas_obs]
        ref = self._reference(info)
        was_needed = self._needed
        self._needed = self.need is None or self.need(obs, ref)
        fallback_action = self.fallback.act(obs, info)     # keeps its filter current
        model = self.identifier.model
        if not self._warm and model is not None:
            self._warm = True
            self._open_excitation_window()
        elif self._warm and self._needed and not was_needed:
            self._open_excitation_window()           # motion, after a model from rest
        if not self._warm and self.warmup_controller is not self.fallback:
            warmup_action = self.warmup_controller.act(obs, info)
            if self._needed:
                fallback_action = warmup_action      # at rest the robust design flies
        self._watch_events()
        x = None
        self._reason = "no model" if model is None else None
        if model is not None and np.isfinite(model.A).all():
            if self.rigid_state == "kalman":
                x = self._own_filter(model, y, info)
            else:
                x = self.identifier.filtered_state(y)
            if x is not None and self.rigid_state == "measured":
                x = self._measured_rigid(x, y, model.C)
            agreement = self._agreement(y, model, x)
            self.gain = self._design(model, agreement)
        bridging = self._k < self._bridge_until
        self._supervise(y, ref)
        held = self._k < self._hold_until
        usable = x is not None and np.isfinite(x).all()
        wanted = (self.gain is not None and usable and not bridging and not held
                  and self._needed)
        if wanted:
            self._flying_gain = self.gain
        # dwell time: the loop changes between the identified design and the fallback at
        # most once per dwell, so two integrators never take turns at every sample; the
        # supervisor's hold takes the identified design off at once
        if wanted != self._flying and (self._k - self._switched >= self.dwell_steps
                                       or (held and self._flying)):
            self._transfer_integral(to_identified=wanted)
            self._flying, self._switched = wanted, self._k
            self.stats["switches"] += 1
        fly = self._flying and usable and self._flying_gain is not None
        judged = self._k * self.dt >= JUDGED_FROM_S
        self.stats["steps_after_60s"] += judged
        if not fly:
            self.stats["fallback_steps"] += 1
            self.stats["fallback_steps_after_60s"] += judged
            if judged:
                cause = self._fallback_cause(held, bridging, usable, wanted)
                by = self.stats["fallback_by_after_60s"]
                by[cause] = by.get(cause, 0) + 1
            self._warn_if_never_flown()
            torque = fallback_action.astype(float) * self.max_torque
            if np.isfinite(obs[self._att]).all():
                self.law.integrate(obs[self._att] - ref, saturated=True)   # hold the integral
        else:
            x_ref = self.law.equilibrium(model.A, model.C[self._att_rows], ref)
            torque = self.law.torque(self._flying_gain, x, x_ref)
            if np.isfinite(obs[self._att]).all():
                self.law.integrate(obs[self._att] - ref,
                                   bool((np.abs(torque) > self.max_torque).any()))
        if self._k % 10 == 0:
            self._update_excitation()
        excitation = self.excitation(self._needed)
        self.last_excitation = excitation
        if np.any(excitation):
            self.stats["excited_steps"] += 1
        torque = torque + excitation
        action = self._to_action(torque)
        if isinstance(self.fallback, _LQGController):
            self.fallback.applied_action = action
        self.stats["excitation_rms_Nm"] = self.excitation.rms
        self._k += 1
        # to the identifier once the applied torque is known, with the drive angle
        # of this sample for an identifier scheduled on it
        schedule = None if info is None else info.get(PADDLE_ANGLE)
        if schedule is None and not self._schedule_warned and self._turning_schedule():
            self._schedule_warned = True
            warnings.warn(
                f"AdaptiveLQG's identifier ({type(self.identifier).__name__}) is scheduled "
                f"on the angle of the paddle drive, and this step carried none "
                f"(info['{PADDLE_ANGLE}'] missing: act() without info, or SB3's predict()): "
                f"it keeps the last angle it was given, as if the drive did not turn; "
                f"pass the env's info to act()", ScheduleWarning, stacklevel=3)
        self._sample = (x, y, None if schedule is None else float(schedule))
        return action

    def _turning_schedule(self) -> bool:
        """Whether the identifier follows a drive angle that turns some appendage."""
        return (hasattr(self.identifier, "set_schedule")
                and any(getattr(self.identifier, "turning", (True,))))
