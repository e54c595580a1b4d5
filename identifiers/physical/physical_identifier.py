"""The physical model, fitted once to the warm-up record, as a streaming identifier.

:class:`PhysicalFitIdentifier` records the first ``warmup`` samples, fits a
:class:`identifiers.physical.physical_model.PhysicalModel` to them by
output error (:func:`identifiers.physical.physical_fit.fit_physical_model`)
and from then on holds that model, with a Kalman filter on it for the
state. The model is physical by construction (symmetric positive definite
``J^-1``, passive collocated modes), and output error needs nothing but the
torques that acted, so closed-loop data do not bias it; but it does not
follow a plant that changes after the warm-up (docs/design/control.md,
"What the remaining gap is made of").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identifiers.core.checks import positive_float, positive_int
from identifiers.core.online import OnlineIdentifier
from identifiers.core.rigid_gain import RigidGainEstimate
from identifiers.physical.output_correction import OutputCorrection
from identifiers.physical.physical_fit import fit_physical_model
from identifiers.physical.physical_model import simulate
from spacecraft_conventions import NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["PhysicalFitIdentifier"]


class PhysicalFitIdentifier(OutputCorrection, OnlineIdentifier):
    """A physical rigid-flexible model fitted to the warm-up by output error, then held.

    Parameters
    ----------
    layout : OutputLayout
        The measured sensor groups, in the order of ``y`` (default: attitude,
        rate and four tip deflections). Attitude and rate are required.
    n_modes : int
        Modes of the fitted model (default 4: those below 0.2 Hz); the
        model order is ``6 + 2 n_modes``.
    dt : float
        Sample time, s.
    warmup : int
        Samples recorded before the fit (default 300: the adaptive loop's
        30 s of excitation).
    process_torque : float
        Unmodelled torque (N m per axis) the state's Kalman filter assumes
        (default 0.05, the baselines' value).
    grid_hz : sequence of float, optional
        Starting frequencies of the fit's mode search
        (see :func:`identifiers.physical.physical_fit.fit_physical_model`).
    input_scale, output_scale, max_abs
        See :class:`identifiers.core.online.OnlineIdentifier`; defaults:
        1 N m and the layout's nominal levels.

    Attributes
    ----------
    held_fit : PhysicalFit or None
        The fit, once the warm-up is over.

    Examples
    --------
    >>> import numpy as np
    >>> from identifiers import PhysicalFitIdentifier
    >>> ident = PhysicalFitIdentifier(warmup=100)
    >>> ident.model is None, ident.rigid_states
    (True, (slice(0, 3, None), slice(3, 6, None)))
    """

    def __init__(self, layout: OutputLayout = STANDARD_OUTPUTS, *, n_modes: int = 4,
                 dt: float = 0.1, warmup: int = 300, process_torque: float = 0.05,
                 grid_hz: Sequence[float] | None = None,
                 input_scale: ArrayLike | None = None, output_scale: ArrayLike | None = None,
                 max_abs: float = 1e6) -> None:
        if not isinstance(layout, OutputLayout):
            raise TypeError(f"layout must be an OutputLayout, got {type(layout).__name__}")
        self.layout = layout.sensors()
        missing = [g for g in ("attitude", "rate") if g not in self.layout.names]
        if missing:
            raise ValueError(f"the physical model needs the sensor groups {missing}; "
                             f"the layout holds {self.layout.names}")
        self.n_modes = positive_int("n_modes", n_modes)
        self.process_torque = positive_float("process_torque", process_torque)
        self.grid_hz = None if grid_hz is None else tuple(float(f) for f in grid_hz)
        super().__init__(6 + 2 * self.n_modes, 1, 1.0, dt=dt,
                         warmup=positive_int("warmup", warmup),
                         input_scale=(np.full(3, NOMINAL_TORQUE) if input_scale is None
                                      else input_scale),
                         output_scale=self.layout.scales() if output_scale is None
                         else output_scale, max_abs=max_abs)

    def _fit_record(self) -> bool:
        """Fit the physical model to the record (physical units), build the
        normalized model and start the state's filter over the record; False if the
        model is not finite."""
        su, sy = self._su, self._sy
        u = np.array([s[0] for s in self._record])
        y = np.array([s[1] for s in self._record])
        fit = fit_physical_model(u * su, y * sy, self.dt, self.layout, n_modes=self.n_modes,
                                 grid_hz=self.grid_hz)
        model = fit.model.discrete(self.dt, self.layout)
        a, b = model.A, model.B * su[None, :]
        c = model.C / sy[:, None]
        if not all(np.isfinite(m).all() for m in (a, b, c)):
            return False
        self.held_fit = fit
        self._mats = (a, b, c, np.zeros((c.shape[0], 3)), None)
        self._q = self._held_process_noise(b)
        # the filter's measurement noise: the fit's residual per output
        attitude, rate, q = simulate(fit.model, u * su, self.dt, fit.initial_state)
        fitted = np.zeros_like(y)
        for name, rows in self.layout:
            fitted[:, rows] = {"attitude": attitude, "rate": rate,
                               "deflection": q @ fit.model.tips.T}[name] / sy[rows]
        self._start_filter(fit.initial_state, u, y, fitted)
        return True

    # ------------------------------------------------------------ results
    @property
    def rigid_gain(self) -> RigidGainEstimate | None:
        """``J^-1`` (rad/s^2 per N m) with the fit's covariance; None before the fit."""
        if self.held_fit is None:
            return None
        return RigidGainEstimate(np.array(self.held_fit.model.gain), self.held_fit.gain_covariance)

    def __repr__(self) -> str:
        modes = [] if self.held_fit is None else [
            round(float(f), 4) for f in np.sort(self.held_fit.model.frequencies_hz)]
        return (f"{type(self).__name__}(n_modes={self.n_modes}, "
                f"fitted={self.held_fit is not None}, modes_hz={modes}, "
                f"samples={self.n_samples})")
