"""Online identification that knows the rigid body: a rigid-flexible spacecraft model.

A recursive subspace identifier estimates everything, even what physics
already fixes, and on this plant it scatters the three double integrators
(a Jordan block at ``z = 1``) over ``1 +- 0.002``, which ruins every
long-horizon prediction. :class:`RigidFlexibleIdentifier` uses two facts:

1. **Known:** attitude integrates rate, and rate integrates torque through
   the inverse inertia: exact ZOH double integrators per axis with an
   unknown gain ``G = J(t)^-1``. The flexible modes are resonators whose
   frequencies are found from data (:mod:`identifiers.modal_discovery`) or
   given as a prior; their couplings are unknown gains. Given the
   frequencies, the model is *linear* in every unknown
   (:mod:`identifiers.modal_basis`), so one recursive least squares
   (:class:`~identifiers.rls.RecursiveLeastSquares`) on high-passed signals
   estimates ``G`` and the modal couplings together.
2. **Changes are abrupt:** a docking shows in the model's innovations. A
   CUSUM test (:mod:`identifiers.change_detection`) flags it; the RLS
   covariance is then inflated by the expected parameter jump and the
   initial-condition regressors restart, so the estimates re-converge on
   post-change data. Events are exposed in :attr:`events`.

Model exported at every sample (innovation form, order ``n``): the state is
``[psi (3); omega (3); one complex mode per resonator rank as 2 real
states]``; each resonator's couplings are factored into input and output
vectors by a complex SVD (exact for a non-classically damped mode, whose
residue is complex rank one), with input vectors of unit norm and their
phase aligned from one export to the next so the state keeps its meaning.
The state estimate is a time-varying Kalman filter
(:class:`~identifiers.kalman.KalmanPredictor`) on the current model; its
predictor gain is the model's ``K``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identifiers.base import OnlineIdentifier, _positive_float, _positive_int
from identifiers.change_detection import ChangeEvent, RegressionGLR
from identifiers.kalman import KalmanPredictor
from identifiers.modal_basis import HighPass, ModalFilterBank, Resonator
from identifiers.modal_discovery import discover_resonators, merge_resonators
from identifiers.rls import RecursiveLeastSquares
from spacecraft_conventions import NOMINAL_TORQUE, STANDARD_OUTPUTS, OutputLayout

__all__ = ["RigidFlexibleIdentifier"]


def _spend_rank(resonators: list[Resonator], budget: int) -> list[Resonator]:
    """Give unused modal capacity to the strongest resonators (up to rank 2 each).

    A discovered resonator may stand for two modes closer than the warm-up
    record resolves (the antenna pair at 0.0894 and 0.0900 Hz): a second
    rank lets the export represent both. Resonators are listed by frequency;
    the strongest are assumed to be the lowest-frequency ones here.
    """
    spare = budget - sum(r.rank for r in resonators)
    out = []
    for r in resonators:
        extra = min(spare, 2 - r.rank) if r.rank < 2 else 0
        spare -= max(extra, 0)
        out.append(Resonator(r.frequency_hz, r.damping, r.rank + max(extra, 0)))
    return out


def _highpass_noise_gain(rho: float) -> float:
    """Sum of the squared impulse response of ``((1 - z^-1) / (1 - rho z^-1))^2``."""
    hp = HighPass(1, rho)
    impulse = np.zeros(4000)
    impulse[0] = 1.0
    return float(sum(hp(np.array([x]))[0] ** 2 for x in impulse))


class RigidFlexibleIdentifier(OnlineIdentifier):
    """Online identifier with known rigid-body kinematics and estimated flexible modes.

    Parameters
    ----------
    layout : OutputLayout
        The measured sensor groups, in the order of ``y`` (default: the
        environments' standard attitude, rate and four tip deflections).
        Attitude and rate are required.
    n : int
        Model order: 6 rigid states plus two per flexible mode (default 22:
        eight modes). The order is fixed; capacity for which the data show no
        mode is exported as inert states (zero rows and columns).
    dt : float
        Sample time, s.
    forgetting : float
        Forgetting of the gain estimates (memory ``1 / (1 - forgetting)``
        samples; default 0.998: 50 s).
    warmup : int
        Samples collected before the modes are found and a model is given
        (default 500: 50 s at dt = 0.1 s).
    prior : sequence of Resonator, optional
        Flexible modes of a nominal structural model (frequencies, damping);
        near-coincident ones are merged. Default: found from the warm-up
        data by a batch PBSID.
    highpass : float
        Pole ``rho`` of the high-pass that removes constants and ramps.
    detect_changes : bool
        Run the change detector and react to its alarms.
    change_threshold : float
        Alarm level of the change test, a multiple of its degrees of freedom
        (see :class:`~identifiers.change_detection.RegressionGLR`).
    discount : float
        Factor by which the covariance of the gains grows at a detected
        change (old information discounted that much).
    process_torque : float
        Standard deviation (N m) of the unmodelled torque the Kalman filter
        assumes per axis.
    refresh : int
        Samples between exports of the minimal model (the Kalman filter
        runs every sample).
    outlier_threshold : float, optional
        Reject samples whose normalized innovation exceeds this on any
        channel (default 100).
    input_scale, output_scale : array_like, optional
        Normalization; default the nominal levels of ``layout`` and 1 N m.
    max_abs : float
        See :class:`~identifiers.base.OnlineIdentifier`.

    Attributes
    ----------
    resonators : tuple of Resonator
        The flexible modes in use (after warm-up).
    events : list of ChangeEvent
        Changes detected so far.
    """

    def __init__(self, layout: OutputLayout = STANDARD_OUTPUTS, *, n: int = 22,
                 dt: float = 0.1, forgetting: float = 0.998, warmup: int = 500,
                 prior: Sequence[Resonator] | None = None, highpass: float = 0.99,
                 detect_changes: bool = True, change_threshold: float = 6.0,
                 discount: float = 10.0, process_torque: float = 0.05, refresh: int = 10,
                 outlier_threshold: float | None = 100.0,
                 input_scale: ArrayLike | None = None, output_scale: ArrayLike | None = None,
                 max_abs: float = 1e6) -> None:
        if not isinstance(layout, OutputLayout):
            raise TypeError(f"layout must be an OutputLayout, got {type(layout).__name__}")
        self.layout = layout.sensors()
        missing = [g for g in ("attitude", "rate") if g not in self.layout]
        if missing:
            raise ValueError(f"the rigid-flexible identifier needs the sensor groups {missing}; "
                             f"the layout holds {self.layout.names}")
        n = _positive_int("n", n)
        if n < 6 or n % 2:
            raise ValueError(f"n must be an even order >= 6 (6 rigid states), got {n}")
        self.prior = None if prior is None else tuple(prior)
        if self.prior is not None and not all(isinstance(r, Resonator) for r in self.prior):
            raise TypeError("prior must be a sequence of Resonator")
        if not 0 <= highpass < 1:
            raise ValueError(f"highpass must be in [0, 1), got {highpass}")
        self.highpass = float(highpass)
        self.detect_changes = bool(detect_changes)
        self.change_threshold = _positive_float("change_threshold", change_threshold)
        self.discount = _positive_float("discount", discount)
        self.process_torque = _positive_float("process_torque", process_torque)
        self.refresh = _positive_int("refresh", refresh)
        self.outlier_threshold = (None if outlier_threshold is None
                                  else _positive_float("outlier_threshold", outlier_threshold))
        scales = (np.full(3, NOMINAL_TORQUE) if input_scale is None else input_scale,
                  self.layout.scales() if output_scale is None else output_scale)
        warmup = _positive_int("warmup", warmup)
        super().__init__(n, 2, forgetting, dt=dt, warmup=max(warmup, 100),
                         input_scale=scales[0], output_scale=scales[1], max_abs=max_abs)
        self._noise_gain = _highpass_noise_gain(self.highpass)

    # ------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        super().reset()
        self.resonators: tuple[Resonator, ...] = ()
        self._bank: ModalFilterBank | None = None
        self._buffer: list[tuple[np.ndarray, np.ndarray, bool, bool]] = []
        self._rls = self._kf = self._detector = None
        self._mats = None
        self._phases: dict[tuple[int, int], np.ndarray] = {}
        self._resvar: np.ndarray | None = None
        self._noise_var: np.ndarray | None = None
        self._last_innovation: np.ndarray | None = None
        self._real = True

    def _check_sizes(self, r: int, m: int) -> None:
        if r != 3:
            raise ValueError(f"u must hold the 3 body torques, got {r} inputs")
        if m != self.layout.size:
            raise ValueError(f"y must have {self.layout.size} entries as the layout "
                             f"{self.layout.names} says, got {m}")

    def _allocate(self, r: int, m: int) -> None:
        s = self.layout.scales() if self._user_scales[1] is None else self._user_scales[1]
        rate, att = self.layout.slice("rate"), self.layout.slice("attitude")
        self._ratio = float(np.mean(s[rate]) / np.mean(s[att]))

    def _process(self, u: np.ndarray, y: np.ndarray) -> None:
        # the base class replaces unusable samples by a stand-in and calls _step with
        # learn=False; remember whether this sample's y was real for the Kalman filter
        self._real = bool(np.all(np.isfinite(y)))
        super()._process(u, y)

    def _admissible(self, u: np.ndarray, y: np.ndarray) -> bool:
        kf = self._kf
        if self.outlier_threshold is None or kf is None or self._mats is None:
            return True
        c = self._mats[2]
        spread = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", c, kf.P, c) + self._r, 1e-30))
        if np.any(np.abs(y - c @ kf.x) > self.outlier_threshold * spread):
            self._real = False          # the base class counts it in n_outliers
            return False
        return True

    def _fill_output(self) -> np.ndarray:
        if self._kf is None or self._mats is None:
            return np.zeros(self.n_outputs)
        return self._mats[2] @ self._kf.x

    # ------------------------------------------------------------ streaming
    def _step(self, u: np.ndarray, y: np.ndarray, learn: bool) -> None:
        if self._bank is None:
            self._buffer.append((u, y, learn, self._real))
            if len(self._buffer) >= self.warmup:
                self._start()
            return
        self._sample(u, y, learn, self._real)

    def _start(self) -> None:
        """End of warm-up: find the modes, build the estimator, replay the buffer."""
        u = np.array([b[0] for b in self._buffer])
        y = np.array([b[1] for b in self._buffer])
        budget = (self.n - 6) // 2
        if self.prior is not None:
            resonators = merge_resonators([r.frequency_hz for r in self.prior],
                                          [r.damping for r in self.prior], budget=budget)
        else:
            cols = np.concatenate([self.layout.indices(g) for g in ("rate", "deflection")
                                   if g in self.layout])
            resonators = discover_resonators(u, y[:, cols], budget, self.dt) if budget else []
            resonators = _spend_rank(resonators, budget)
        self.resonators = tuple(resonators)
        self._bank = ModalFilterBank(self.resonators, self.dt, self._ratio)
        size = self._bank.size
        m = self.n_outputs
        self._hp_x = HighPass(size, self.highpass)
        self._hp_y = HighPass(m, self.highpass)
        # regressor scales: RMS of the high-passed warm-up regressors (unit-RMS columns)
        probe_bank = ModalFilterBank(self.resonators, self.dt, self._ratio)
        probe_hp = HighPass(size, self.highpass)
        rows = []
        for uk in u:
            rows.append(probe_hp(probe_bank.regressor()))
            probe_bank.step(uk)
        scale = np.sqrt(np.mean(np.array(rows) ** 2, axis=0))
        scale[self._bank.slices["free"]] = 1.0
        scale[self._bank.slices["step"]] = 1.0
        scale[self._bank.slices["ramp"]] = self.dt
        self._scale = np.where(scale > 0, scale, 1.0)
        # Tikhonov floors: the flexible couplings are many and weakly excited (noise
        # would be fitted there); the rigid gains and the initial-condition terms
        # are few, well excited, and a floor would bias them through their
        # collinearity during transients
        floor = np.full(size, 1e-4)
        floor[self._bank.slices["flexible"]] = 1.0
        self._rls = RecursiveLeastSquares(m, size, self.forgetting, 1e4, regularization=floor)
        self._kf = KalmanPredictor(self.n, initial_covariance=1.0)
        self._detector = RegressionGLR(threshold=self.change_threshold, dt=self.dt)
        self._r = np.full(m, 1e-4)
        buffer, self._buffer = self._buffer, []
        start_k = self._k - len(buffer) + 1
        for j, (uk, yk, learn, real) in enumerate(buffer):
            self._sample(uk, yk, learn, real, replay_k=start_k + j)

    def _sample(self, u: np.ndarray, y: np.ndarray, learn: bool, real: bool,
                replay_k: int | None = None) -> None:
        k = self._k if replay_k is None else replay_k
        bank = self._bank
        phi = self._hp_x(bank.regressor()) / self._scale
        y_f = self._hp_y(y)
        if self._mats is not None:
            a, b, c, _, _ = self._mats
            self._kf.update(a, b, c, self._process_noise(), self._r, u, y if real else None)
            innovation = self._kf.innovation
            if real and innovation is not None and np.all(np.isfinite(innovation)):
                self._measurement_noise(innovation)
        if learn and real:
            err = self._rls.update(phi, y_f)
            if (err is not None and self.detect_changes and replay_k is None
                    and self._resvar is not None):
                rate = self.layout.slice("rate")      # a change of inertia shows here
                event = self._detector.update(phi[bank.slices["rate"]], err[rate],
                                              self._resvar[rate], sample=k)
                if event is not None:
                    self._react(event)
            if err is not None:
                e2 = err**2
                self._resvar = e2 if self._resvar is None else 0.995 * self._resvar + 0.005 * e2
                if self._last_innovation is None:       # before the filter runs
                    self._r = np.maximum(self._resvar / self._noise_gain, 1e-12)
        bank.step(u)
        if (k + 1) % self.refresh == 0 or self._mats is None:
            self._export()

    def _measurement_noise(self, innovation: np.ndarray) -> None:
        """Sensor noise variance from the filter's innovations: white noise shows in
        their first difference (``E[(e_k - e_{k-1})^2] / 2 = R`` for white ``e``),
        slow model error barely does, so the filter keeps trusting the sensors
        where the model is wrong instead of mistaking model error for noise."""
        last = self._last_innovation
        self._last_innovation = innovation
        if last is None:
            return
        d2 = 0.5 * (innovation - last) ** 2
        self._noise_var = d2 if self._noise_var is None else 0.998 * self._noise_var + 0.002 * d2
        self._r = np.maximum(self._noise_var, 1e-12)

    def _process_noise(self) -> np.ndarray:
        """Unmodelled torque through B, plus an attitude random walk at half the noise."""
        b = self._mats[1]
        q = (self.process_torque / self._su.mean()) ** 2 * (b @ b.T)
        att = self.layout.slice("attitude")
        q[:3, :3] += np.diag(0.25 * self._r[att])
        return q

    def _react(self, event: ChangeEvent) -> None:
        """A detected change: discount the information gathered before it.

        The covariance is multiplied by ``discount`` (as if the old data had
        been forgotten that many times faster), which keeps its structure
        (the correlations between the rigid gains and the modal couplings)
        while letting the post-change data dominate; the Kalman filter's
        state uncertainty is doubled.
        """
        self._rls.set_covariance(self._rls.P * self.discount)
        self._kf.inflate(np.diag(np.abs(np.diag(self._kf.P))))

    # ------------------------------------------------------------ the model
    def _export(self) -> None:
        """Minimal innovation-form model from the current gains (normalized units)."""
        theta = self._rls.theta / self._scale
        bank = self._bank
        att, rate = self.layout.slice("attitude"), self.layout.slice("rate")
        m = self.n_outputs
        order = self.n           # fixed: capacity not used by a resonator stays inert (zero)
        a = np.zeros((order, order))
        b = np.zeros((order, 3))
        c = np.zeros((m, order))
        g = theta[rate, bank.slices["rate"]]                  # normalized inverse inertia
        dt, ratio = self.dt, self._ratio
        a[:3, :3] = np.eye(3)
        a[:3, 3:6] = dt * ratio * np.eye(3)
        a[3:6, 3:6] = np.eye(3)
        b[:3] = 0.5 * dt * dt * ratio * g
        b[3:6] = dt * g
        c[att, :3] = np.eye(3)
        c[rate, 3:6] = np.eye(3)
        modes_a, modes_b = bank.mode_matrices
        flexible = theta[:, bank.slices["flexible"]].reshape(m, len(self.resonators), 3, 2)
        j = 6
        for i, res in enumerate(self.resonators):
            vals, vecs = np.linalg.eig(modes_a[i])
            top = int(np.argmax(vals.imag))
            mu = vals[top]
            to_complex = vecs[:, top] * np.linalg.solve(vecs, modes_b[i])[top]
            chat = 2.0 * flexible[:, i] @ to_complex                   # (m, 3) complex
            left, sv, right = np.linalg.svd(chat, full_matrices=False)
            for rank in range(res.rank):
                c_vec, b_vec = left[:, rank] * sv[rank], right[rank].copy()
                ref = self._phases.get((i, rank))
                phase = b_vec[np.argmax(np.abs(b_vec))] if ref is None else np.vdot(ref, b_vec)
                phase = phase / abs(phase) if abs(phase) > 0 else 1.0
                b_vec, c_vec = b_vec / phase, c_vec * phase
                self._phases[(i, rank)] = b_vec
                a[j:j + 2, j:j + 2] = [[mu.real, -mu.imag], [mu.imag, mu.real]]
                b[j], b[j + 1] = b_vec.real, b_vec.imag
                c[:, j], c[:, j + 1] = c_vec.real, -c_vec.imag
                j += 2
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(c))):
            return
        self._mats = (a, b, c, np.zeros((m, 3)), None)

    def _matrices(self) -> tuple[np.ndarray, ...] | None:
        if self._mats is None:
            return None
        a, b, c, d, _ = self._mats
        gain = self._kf.gain if self._kf.gain is not None else np.zeros((a.shape[0], c.shape[0]))
        return a, b, c, d, gain

    def _current_state(self) -> np.ndarray | None:
        return None if self._mats is None else self._kf.x

    @property
    def events(self) -> list[ChangeEvent]:
        """Changes detected so far (empty before warm-up)."""
        return [] if self._detector is None else list(self._detector.events)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n={self.n}, forgetting={self.forgetting}, "
                f"modes={[round(r.frequency_hz, 4) for r in self.resonators]}, "
                f"samples={self.n_samples}, skipped={self.n_skipped}, events={len(self.events)})")
