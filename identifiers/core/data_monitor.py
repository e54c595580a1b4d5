"""What the data say about the sensors and the excitation, seen by a streaming identifier.

An estimator's internal state can be perfectly healthy while the data it
learns from have gone bad: a sensor that repeats its last value, one that
saturates, one whose noise rose a hundredfold, samples it must skip, or an
input that stopped exciting the plant while forgetting erases what was
learnt. None of these breaks the arithmetic, so the state checks of
:mod:`identifiers.core.health` cannot see them, and a model read from the
identifier goes stale without a word. :class:`DataMonitor` looks at the
normalized samples the identifier receives, one window of
:data:`WINDOW` samples at a time, and reports the faults it sees while they
last (``identifier.health.faults``; ``health.healthy`` is False meanwhile).

A fault is a property of the data, never of one sample:

``stuck``
    An output exactly constant (bit for bit) over a whole window while the
    input varied, after it had varied in an earlier window. A sensor that is
    read out frozen. (A plant at rest under zero input is *idle*, not stuck:
    the identifier passes such samples over before they reach the monitor.)
``clipped``
    An output at exactly its window's largest or smallest value on at least
    :data:`CLIPPED_SHARE` of the window's samples: a sensor at its range
    limit. Continuous dynamics, with or without noise, do not repeat an
    extreme value.
``noisier``
    An output whose median absolute second difference (a model-free noise
    level: smooth dynamics sampled ten times per period hardly change it)
    rose :data:`NOISE_RATIO` times above its median over the previous
    :data:`NOISE_HISTORY` windows, in a window the noise dominates (the level
    is at least :data:`NOISE_DOMINATED` times the window's spread). The
    baseline follows the data, so a sensor that stays noisier stops being
    reported after about half the history: the fault marks the jump.
``skipping``
    At least :data:`SKIP_SHARE` of the window's samples skipped (non-finite,
    beyond ``max_abs`` or outliers): the identifier is not learning.
``unexcited``
    An input constant (bit for bit) for longer than the estimator's memory,
    ``1 / (1 - forgetting)`` samples: what it learnt of the input response
    is being forgotten.

The per-sample cost is two row copies and a few counters; the window
statistics run once per window, vectorized over the channels.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

__all__ = ["CLIPPED_SHARE", "NOISE_DOMINATED", "NOISE_HISTORY", "NOISE_RATIO", "SKIP_SHARE",
           "WINDOW", "DataMonitor"]

#: Samples per window (5 s at dt = 0.1 s).
WINDOW = 50
#: Share of a window's samples at exactly one extreme value that marks a clipped output.
CLIPPED_SHARE = 0.1
#: Rise of the noise level (median absolute second difference) that marks a noisier output.
NOISE_RATIO = 10.0
#: Windows the noise baseline is the median over.
NOISE_HISTORY = 20
#: The noise level must be at least this share of the window's spread (standard deviation)
#: to count: a window the noise dominates, not one in which the dynamics started moving.
NOISE_DOMINATED = 0.25
#: Share of a window's samples skipped that marks an identifier that is not learning.
SKIP_SHARE = 0.5


class DataMonitor:
    """Window statistics of an identifier's normalized samples, and the faults they show.

    Parameters
    ----------
    n_inputs, n_outputs : int
        Sizes r and m of the samples.
    memory : float
        The estimator's memory in samples, ``1 / (1 - forgetting)`` (``inf``
        without forgetting): an input constant for longer is ``unexcited``.
    names : sequence of str, optional
        A label per output for the messages (default ``y[i]``).

    Attributes
    ----------
    faults : dict
        The faults seen in the last complete window, ``{key: message}``; the
        key is ``(kind, channel)`` with channel None for the whole sample.
    """

    def __init__(self, n_inputs: int, n_outputs: int, memory: float = np.inf,
                 names: Sequence[str] | None = None) -> None:
        self.names = tuple(names) if names is not None else tuple(
            f"y[{i}]" for i in range(n_outputs))
        if len(self.names) != n_outputs:
            raise ValueError(f"names must have {n_outputs} entries, got {len(self.names)}")
        self.memory = float(memory)
        self._u = np.zeros((WINDOW, n_inputs))
        self._y = np.zeros((WINDOW, n_outputs))
        self._i = 0
        self._samples = 0
        self._skipped = 0
        self._varied = np.zeros(n_outputs, dtype=bool)
        self._levels: deque[np.ndarray] = deque(maxlen=NOISE_HISTORY)
        self._constant_input = 0        # samples the input has been constant for
        self._last_u: np.ndarray | None = None
        self.faults: dict[tuple[str, int | None], str] = {}

    def observe(self, u: np.ndarray, y: np.ndarray, skipped: bool) -> bool:
        """Take one normalized sample (non-finite entries allowed); True when a window ended.

        Parameters
        ----------
        u : (r,) ndarray
            Input as received, normalized.
        y : (m,) ndarray
            Output as received, normalized.
        skipped : bool
            Whether the identifier skipped the sample.

        Returns
        -------
        bool
            True when this sample closed a window (which was then assessed).
        """
        i = self._i
        self._u[i] = u
        self._y[i] = y
        self._skipped += skipped
        self._i = i + 1
        self._samples += 1
        if self._i < WINDOW:
            return False
        self._i = 0
        self._assess()
        return True

    def _assess(self) -> None:
        faults: dict[tuple[str, int | None], str] = {}
        u, y = self._u, self._y
        end = self._samples

        if self._skipped >= SKIP_SHARE * WINDOW:
            faults["skipping", None] = (f"skipping: {self._skipped} of the last {WINDOW} samples "
                                        "could not be learned from (non-finite, beyond max_abs "
                                        "or outliers)")
        self._skipped = 0

        input_constant = bool(np.all(u == u[0]))
        if input_constant and self._last_u is not None and np.array_equal(u[0], self._last_u):
            self._constant_input += WINDOW
        else:
            self._constant_input = WINDOW if input_constant else 0
        self._last_u = u[-1].copy()
        if self._constant_input > self.memory:
            faults["unexcited", None] = (f"unexcited: the input has been constant for "
                                         f"{self._constant_input} samples, more than the "
                                         f"estimator's memory of {self.memory:.0f}: what it "
                                         "learnt of the input response is being forgotten")

        finite = np.isfinite(y)
        constant = np.all(y == y[0], axis=0)          # False where a value is NaN
        stuck = constant & self._varied & (not input_constant)
        hi = np.where(finite, y, -np.inf).max(axis=0)
        lo = np.where(finite, y, np.inf).min(axis=0)
        at_limit = np.maximum((y == hi).sum(axis=0), (y == lo).sum(axis=0))
        clipped = ~constant & (at_limit >= CLIPPED_SHARE * WINDOW)

        whole = finite.all(axis=0)
        level = np.full(y.shape[1], np.nan)
        spread = np.full(y.shape[1], np.nan)
        if whole.any():
            cols = y[:, whole]
            level[whole] = np.median(np.abs(cols[2:] - 2.0 * cols[1:-1] + cols[:-2]), axis=0)
            spread[whole] = cols.std(axis=0)
        history = np.sort(np.array(self._levels), axis=0) if self._levels else None
        if history is not None and len(history) >= 4:
            count = np.isfinite(history).sum(axis=0)     # NaN windows sort last
            baseline = history[np.maximum(count - 1, 0) // 2, np.arange(y.shape[1])]
            baseline = np.where(count >= 4, baseline, np.nan)
            with np.errstate(invalid="ignore"):
                noisier = ((level > NOISE_RATIO * baseline) & (baseline > 0)
                           & (level >= NOISE_DOMINATED * spread))
        else:
            baseline = np.full_like(level, np.nan)
            noisier = np.zeros(y.shape[1], dtype=bool)
        self._levels.append(level)
        self._varied |= ~constant & finite.all(axis=0)

        for j in np.flatnonzero(stuck):
            faults["stuck", int(j)] = (f"stuck: output {self.names[j]} repeated one value for "
                                       f"the last {WINDOW} samples (to sample {end}) while the "
                                       "input varied")
        for j in np.flatnonzero(clipped):
            faults["clipped", int(j)] = (f"clipped: output {self.names[j]} sat at its extreme "
                                         f"value on {at_limit[j]} of the last {WINDOW} samples "
                                         f"(to sample {end})")
        for j in np.flatnonzero(noisier):
            faults["noisier", int(j)] = (f"noisier: output {self.names[j]}'s noise level rose "
                                         f"{level[j] / baseline[j]:.0f}x above its recent "
                                         f"median (window to sample {end})")
        self.faults = faults
