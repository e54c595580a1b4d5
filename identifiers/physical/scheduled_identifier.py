"""The drive-scheduled physical model, fitted to the warm-up, as a streaming identifier.

:class:`ScheduledPhysicalIdentifier` records the first ``warmup`` samples with
the drive angle of each (:meth:`ScheduledPhysicalIdentifier.set_schedule`),
fits a :class:`identifiers.physical.scheduled_model.ScheduledPhysicalModel` to
them by output error (:func:`identifiers.physical.scheduled_fit.fit_scheduled_model`) and from
then on exports that model evaluated at the latest angle, with a Kalman filter
on it for the state. The drive's rotation is followed through the angle. By
default (``accumulate``) the fit is redone, from the held model, each time the
record has doubled (60 s, 120 s, then every 120 s on the last 120 s): the
data the loop gathers, and the angles the drive reaches, enter the model. A
change of the plant itself (a docking) is looked for by a test on the filter's
innovations (``refit_on_change``): after an alarm the model is fitted again to
the ``warmup`` samples after it, starting from the model it replaces, and the
refit replaces it where it explains those samples clearly better.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.checks import positive_float, positive_int
from identifiers.core.model_sequence import ModelSequence
from identifiers.core.online import OnlineIdentifier
from identifiers.core.rigid_gain import RigidGainEstimate
from identifiers.physical.output_correction import OutputCorrection
from identifiers.physical.scheduled_fit import fit_scheduled_model
from identifiers.physical.scheduled_information import (
    held_misfit,
    predicted_gain_covariance,
)
from identifiers.physical.scheduled_simulation import simulate_scheduled
from spacecraft_conventions import NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["EXPORT_RESOLUTION", "SCREEN_MARGIN", "ScheduledPhysicalIdentifier"]

#: Drive travel (rad) after which the exported model is discretized again at the
#: latest angle (0.5 deg: 1.4 s of the paddle-rotation scenario's 0.36 deg/s). The
#: true rigid-body gain moves 0.28-0.30 % per degree of that drive and the whole
#: input matrix 1.3 %, so the exported model lags the angle by at most 0.15 % in
#: gain, against the fit's own 1-2 % error; the adaptive loop costs the same as at
#: 0.1 deg (paired over 10 seeds, at 1 deg: median ratio 1.000 on paddle rotation,
#: solar rotation and the task family, each seed within 0.955-1.012), and each
#: export re-opens the controller's per-model work (the Riccati iteration's
#: target, the acceptance test's and the law's kept matrices): its median step
#: is 0.84-0.86x that at 0.1 deg, measured by its ratio to a DARE (docs/benchmarks.md).
EXPORT_RESOLUTION = np.deg2rad(0.5)

#: An accumulating refit is skipped (``screen_refits``) only where the predicted
#: relative standard deviation of its gain exceeds the held fit's by this factor: the
#: prediction was 0.4-2.1x the refit's own on the 69 closed-loop refits measured, the
#: refits the guard kept out 3-66x the held value, those it kept 0.2-0.93x (docs/design/control.md).
SCREEN_MARGIN = 2.0


class ScheduledPhysicalIdentifier(OutputCorrection, OnlineIdentifier):
    """Hub-plus-appendage model scheduled on a drive angle, fitted to the warm-up and
    again as the record grows (``accumulate``) or changes.

    Call :meth:`set_schedule` with the drive angle at a sample before the
    :meth:`update` that carries it (``controllers.AdaptiveLQG`` does, from the
    env's ``info["paddle_angle"]``). Without it the angle stays at its last
    value (0 at first): the model of a drive that does not turn.

    Parameters
    ----------
    layout : OutputLayout
        The measured sensor groups in the order of ``y``: attitude, rate and
        deflection, all three required (default: the environments' layout).
    turning : sequence of bool, optional
        One flag per appendage (one mode each): whether the drive carries it.
        Default: as many appendages as deflection sensors, none turning. The
        environments give theirs as ``env.unwrapped.model.appendage_turns``.
    sensor_appendage : sequence of int, optional
        The appendage of each deflection sensor (default: sensor i on
        appendage i; the environments': ``env.unwrapped.model.sensor_appendage``).
    drive_axis : (3,) array_like
        The drive's axis in the body frame (default: pitch, the environments'
        ``spacecraft_env.DRIVE_AXIS``).
    dt : float
        Sample time, s.
    warmup : int
        Samples recorded before the fit (default 300: the adaptive loop's 30 s).
    warmup_amplitude : float
        Torque per axis, N m, that the warm-up's excitation should have
        (``controllers.AdaptiveLQG`` gives its default excitation this
        amplitude). Default 0.5: the output-error fit and its refits on the
        loop's later data do as well as behind 1 N m at 30 dB, and the lightly
        damped modes ring less into the time after the warm-up (closed-loop
        cost about 0.5x that behind 1 N m on the regulation tasks, 0.8-1.0x
        on the slews; docs/results/control.md).
    schedule_resolution : float
        The exported model is re-discretized when the angle has moved this
        far (rad) since it last was (default :data:`EXPORT_RESOLUTION`, 0.5 deg).
    process_torque : float
        Unmodelled torque (N m per axis) the state's Kalman filter assumes.
    refit_on_change : bool
        Watch the filter's innovations for a change (CUSUM), fit again to the
        ``warmup`` samples after an alarm from the held model, and keep that refit
        only where it explains them clearly better than the held model refined on
        its whole record (every alarm in :attr:`events`). Default True: open loop
        it follows both dockings from 40 dB to noise-free; in the closed loop the
        test has not fired (docs/results/identification.md, docs/design/control.md).
    accumulate : bool
        Let the information accumulate (default True): fit again, the held
        model refined first, to the last ``max_record`` samples each time as
        many samples have come since the last fit as it used (60 s, 120 s,
        then every ``max_record`` samples). A refit whose rigid-body gain is
        less certain than the held fit's (a record without the warm-up's
        excitation) is kept out (``n_refits_kept_out``). False holds the
        warm-up's fit, which the drive then carries to angles it never saw.
    max_record : int
        Samples the accumulating refits keep (default 1200: 120 s), at least
        ``warmup``.
    screen_refits : bool
        Before an accumulating refit, judge the record at the held parameters
        (:func:`identifiers.physical.scheduled_information.predicted_gain_covariance`:
        one Jacobian, 0.05-0.25 s) and skip the refit where the gain it predicts
        is more than :data:`SCREEN_MARGIN` times less certain than the held
        fit's, a refit the guard would keep out (``n_refits_skipped``).
        Default True: on the closed-loop refits measured (docs/design/control.md)
        it skipped only refits the guard kept out, which took 1-31 s each.
    refit_restarts : bool
        Refine the equation-error starts (``fit_options``' ``filter_constants``)
        at every accumulating refit too, as at the first fit and after a
        detected change. Default False: an accumulating refit refines the held
        model alone (fitted to the first part of the same record, so already in
        its basin), about 4x faster at the same closed-loop cost
        (docs/results/control.md).
    fit_options : dict, optional
        Keywords for :func:`identifiers.physical.scheduled_fit.fit_scheduled_model`
        (``filter_constants``, ``good_enough``, ``start_nfev``, ``max_nfev``,
        ``disturbance``, ``disturbance_threshold``), e.g. fewer starts for speed;
        default: its defaults (a constant disturbance torque fitted with the
        model where the record tells it from zero, and added to the torques the
        state's filter propagates).
    input_scale, output_scale, max_abs
        See :class:`identifiers.core.online.OnlineIdentifier`.

    Attributes
    ----------
    held_fit : ScheduledFit or None
        The fit, once the warm-up is over.
    angle : float
        The latest drive angle, rad.

    Examples
    --------
    >>> from identifiers import ScheduledPhysicalIdentifier
    >>> ident = ScheduledPhysicalIdentifier(turning=(True, True, False, False))
    >>> ident.set_schedule(0.5)
    >>> ident.model is None, ident.angle
    (True, 0.5)
    """

    #: Alarms are confirmed by a refit against ``_held_misfit`` (:class:`WarmupFit`).
    judges_changes = True
    _CONTEXT = ("angle",)

    def __init__(self, layout: OutputLayout = STANDARD_OUTPUTS, *,
                 turning: Sequence[bool] | None = None,
                 sensor_appendage: Sequence[int] | None = None,
                 drive_axis: ArrayLike = (0.0, 1.0, 0.0), dt: float = 0.1,
                 warmup: int = 300, warmup_amplitude: float = 0.5,
                 schedule_resolution: float = EXPORT_RESOLUTION,
                 process_torque: float = 0.05, refit_on_change: bool = True,
                 accumulate: bool = True, max_record: int = 1200,
                 screen_refits: bool = True, refit_restarts: bool = False,
                 fit_options: dict | None = None,
                 input_scale: ArrayLike | None = None,
                 output_scale: ArrayLike | None = None, max_abs: float = 1e6) -> None:
        if not isinstance(layout, OutputLayout):
            raise TypeError(f"layout must be an OutputLayout, got {type(layout).__name__}")
        self.layout = layout.sensors()
        if set(self.layout.names) != {"attitude", "rate", "deflection"}:
            raise ValueError(f"the scheduled model needs attitude, rate and deflection; "
                             f"the layout holds {self.layout.names}")
        n_tip = self.layout.indices("deflection").size
        self.turning = tuple(bool(t) for t in (turning if turning is not None
                                               else [False] * n_tip))
        self.sensor_appendage = tuple(int(k) for k in (sensor_appendage if sensor_appendage
                                                       is not None else range(n_tip)))
        if len(self.sensor_appendage) != n_tip or \
                set(self.sensor_appendage) != set(range(len(self.turning))):
            raise ValueError(f"sensor_appendage must give each of the {n_tip} deflection "
                             f"sensors one of the {len(self.turning)} appendages, each "
                             f"appendage at least one sensor; got {self.sensor_appendage}")
        axis = np.asarray(drive_axis, dtype=float)
        if axis.shape != (3,) or not np.isfinite(axis).all() or not np.any(axis):
            raise ValueError(f"drive_axis must be a finite non-zero 3-vector, got {drive_axis}")
        self.drive_axis = tuple(float(v) for v in axis / np.linalg.norm(axis))
        self.schedule_resolution = positive_float("schedule_resolution", schedule_resolution)
        self.warmup_amplitude = positive_float("warmup_amplitude", warmup_amplitude)
        self.process_torque = positive_float("process_torque", process_torque)
        for name, flag in (("refit_on_change", refit_on_change), ("accumulate", accumulate),
                           ("screen_refits", screen_refits),
                           ("refit_restarts", refit_restarts)):
            if not isinstance(flag, bool | np.bool_):
                raise TypeError(f"{name} must be a bool, got {flag!r}")
            setattr(self, name, bool(flag))
        self.max_record = positive_int("max_record", max_record)
        if self.max_record < positive_int("warmup", warmup):
            raise ValueError(f"max_record must be at least warmup ({warmup} samples), got "
                             f"{max_record}")
        allowed = {"filter_constants", "good_enough", "start_nfev", "max_nfev", "disturbance",
                   "disturbance_threshold"}
        self.fit_options = dict(fit_options or {})
        if not set(self.fit_options) <= allowed:
            raise ValueError(f"fit_options may hold {sorted(allowed)}, got "
                             f"{sorted(set(self.fit_options) - allowed)}")
        super().__init__(6 + 2 * len(self.turning), 1, 1.0, dt=dt,
                         warmup=positive_int("warmup", warmup),
                         input_scale=(np.full(3, NOMINAL_TORQUE) if input_scale is None
                                      else input_scale),
                         output_scale=self.layout.scales() if output_scale is None
                         else output_scale, max_abs=max_abs)

    def reset(self) -> None:
        super().reset()
        self.angle = 0.0
        self._mats_angle = np.nan
        self._gain_at: tuple[float, np.ndarray] | None = None
        self._gain_now: tuple[tuple[float, float], RigidGainEstimate] | None = None

    def set_schedule(self, angle: float) -> None:
        """The drive angle (rad) at the sample the next :meth:`update` carries; the
        exported model follows it.

        Raises
        ------
        ValueError
            For a non-finite angle.
        """
        angle = float(angle)
        if not np.isfinite(angle):
            raise ValueError(f"the drive angle must be finite, got {angle}")
        self.angle = angle

    def fit(self, U: ArrayLike, Y: ArrayLike,
            schedule: ArrayLike | None = None) -> ModelSequence:
        """Feed a whole record; return the model after each sample.

        Parameters
        ----------
        U : (N, 3) array_like
            Torques, N m.
        Y : (N, m) array_like
            Outputs in the order of ``layout``.
        schedule : (N,) array_like, optional
            The drive angle (rad) at each sample, set (:meth:`set_schedule`)
            before that sample's :meth:`update`. Default: the angle held at
            :attr:`angle`.

        Returns
        -------
        ModelSequence
            As :meth:`identifiers.OnlineIdentifier.fit`.

        Raises
        ------
        ValueError
            If ``schedule`` is not ``N`` finite angles.
        """
        if schedule is None:
            return super().fit(U, Y)
        angles = np.asarray(schedule, dtype=float)
        n = np.shape(U)[0] if np.ndim(U) else 0
        if angles.shape != (n,) or not np.isfinite(angles).all():
            raise ValueError(f"schedule must hold one finite drive angle (rad) per sample of U, "
                             f"shape ({n},); got shape {angles.shape}")
        self._fit_angles = iter(angles)
        try:
            return super().fit(U, Y)
        finally:
            self._fit_angles = None

    def update(self, u: ArrayLike, y: ArrayLike) -> None:
        angles = self.__dict__.get("_fit_angles")
        if angles is not None:            # a scheduled fit: this sample's angle first
            self.set_schedule(next(angles))
        super().update(u, y)

    update.__doc__ = OnlineIdentifier.update.__doc__

    # ------------------------------------------------------------ streaming
    def _record_item(self, u: np.ndarray, y: np.ndarray) -> tuple:
        return (u.copy(), y.copy(), self.angle)

    def _follow(self) -> None:
        if abs(self.angle - self._mats_angle) > self.schedule_resolution:
            self._discretize(self.angle)      # on failure the last model is kept

    def _discretize(self, angle: float) -> bool:
        """Normalized ``(A, B, C)`` of the fitted model at ``angle``; False if not finite."""
        su, sy = self._su, self._sy
        try:
            model = self.held_fit.model.discrete(angle, self.dt, self.layout)
        except (np.linalg.LinAlgError, ValueError):
            return False
        a, b, c = model.A, model.B * su[None, :], model.C / sy[:, None]
        if not all(np.isfinite(m).all() for m in (a, b, c)):
            return False
        self._mats = (a, b, c, np.zeros((c.shape[0], 3)), None)
        self._mats_angle = angle
        self._q = self._held_process_noise(b)
        return True

    def _record_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The record's torques, outputs (physical units) and drive angles."""
        u = np.array([s[0] for s in self._record]) * self._su
        y = np.array([s[1] for s in self._record]) * self._sy
        return u, y, np.array([s[2] for s in self._record])

    def _refit_worthwhile(self, held_std: float) -> bool:
        """False where the record, judged at the held parameters, predicts a rigid-body
        gain more than :data:`SCREEN_MARGIN` times less certain than the held fit's
        (``screen_refits``)."""
        if not self.screen_refits or self.refit_start is None or not np.isfinite(held_std):
            return True
        u, y, angle = self._record_arrays()
        try:
            cov = predicted_gain_covariance(self.held_fit, u, y, angle, self.dt, self.layout,
                                            self.refit_start)
        except (np.linalg.LinAlgError, ValueError):
            return True
        predicted = RigidGainEstimate(self.held_fit.model.gain(float(angle[-1])), cov)
        return predicted.relative_std() <= SCREEN_MARGIN * held_std

    def _held_misfit(self) -> float | None:
        """The held model's misfit of the refit's record (``held_misfit``, from there)."""
        if self.refit_start is None or not np.isfinite(self.refit_start).all():
            return None
        u, y, angle = self._record_arrays()
        try:
            return held_misfit(self.held_fit, u, y, angle, self.dt, self.layout,
                               self.refit_start)
        except (np.linalg.LinAlgError, ValueError):
            return None

    def _fit_record(self) -> bool:
        """Fit the model to the record (physical units), then start the state's filter
        over the record; False if no fit or no finite model came out."""
        su, sy = self._su, self._sy
        u, y, angle = self._record_arrays()
        initial = None if self.refit_start is None else \
            (self.held_fit.model, self.refit_start, self.held_fit.disturbance_torque)
        options = self.fit_options
        if initial is not None and self.accumulating_refit and not self.refit_restarts:
            options = {**options, "filter_constants": ()}     # the held model alone
        try:
            fit = fit_scheduled_model(u, y, angle, self.dt, self.layout, self.turning,
                                      sensor_appendage=self.sensor_appendage,
                                      drive_axis=self.drive_axis, initial=initial,
                                      **options)
        except np.linalg.LinAlgError:
            return False
        held = self.held_fit
        self.held_fit = fit
        if not self._discretize(float(angle[-1])):
            self.held_fit = held
            return False
        self._gain_at = self._gain_now = None
        states = simulate_scheduled(fit.model, u + fit.disturbance_torque, angle, self.dt,
                                    fit.initial_state)
        fitted = states @ fit.model.output_matrix(self.layout).T / sy
        self._start_filter(fit.initial_state, u / su, y / sy, fitted)
        return True

    def _filter_input(self, u: np.ndarray) -> np.ndarray:
        """The torques plus the fit's constant disturbance (normalized)."""
        return u + self.held_fit.disturbance_torque / self._su

    # ------------------------------------------------------------ results
    @property
    def rigid_gain(self) -> RigidGainEstimate | None:
        """``J(a)^-1`` (rad/s^2 per N m) at the latest drive angle (:attr:`angle`), with
        the fit's covariance at the angle of the exported model (within
        ``schedule_resolution`` of it: over that travel the gain moves by up to 0.15 %,
        which a band 0.5-2 % wide must not omit, the covariance far less); None before
        the fit."""
        if self.held_fit is None:
            return None
        if self._gain_at is None or self._gain_at[0] != self._mats_angle:
            angle = self._mats_angle
            self._gain_at = (angle, self.held_fit.gain_covariance(angle))
        if self._gain_now is None or self._gain_now[0] != (self.angle, self._mats_angle):
            self._gain_now = ((self.angle, self._mats_angle),
                              RigidGainEstimate(self.held_fit.model.gain(self.angle),
                                                self._gain_at[1]))
        return self._gain_now[1]

    def __repr__(self) -> str:
        modes = [] if self.held_fit is None else [
            round(float(f), 4) for f in self.held_fit.model.frequencies_hz]
        return (f"{type(self).__name__}(turning={self.turning}, "
                f"fitted={self.held_fit is not None}, modes_hz={modes}, "
                f"angle={self.angle:.4g}, samples={self.n_samples})")
