"""The RL evaluation protocol: aggregate costs with bootstrap intervals (Agarwal et al. 2021).

An agent is scored by the common quadratic cost from 100 s of each held-out draw
of the task family. Its figure over training seeds x held-out draws is given as
the interquartile mean (IQM: the mean of the middle 50 % of all runs' draws,
robust to a few outliers and more efficient than the median), the median (over
the draws, of each draw's mean over the seeds) and the mean, each with a 95 %
interval from the stratified bootstrap of the ``rliable`` library. It resamples
the training seeds within each draw and the draws themselves
(``task_bootstrap``): the held-out draws are a sample of the family, so the
interval covers the family's expectation, and a deterministic controller, the
same on every seed, still gets one. The probability of improvement of X over Y
is the share of (draw, seed pair) comparisons where X costs less, averaged over
the draws, with its interval; the performance profile is the share of runs and
draws at or below each cost.

A crash (the attitude bound left) costs infinity: it sorts above every finite
cost, so the IQM and the median stay finite while fewer than a quarter (a half)
of the runs crash, and the mean is infinite at once. Lower is better throughout.

The protocol asks for at least :data:`MIN_SEEDS` training seeds and
:data:`MIN_DRAWS` held-out draws; fewer are scored and flagged.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["CONFIDENCE", "IMPROVEMENT_REPS", "MIN_DRAWS", "MIN_SEEDS", "PROTOCOL_REPS",
           "STATISTICS",
           "improvement_probabilities", "interval_estimates", "performance_profiles",
           "protocol_table", "score_matrix"]

#: Bootstrap resamples per interval.
PROTOCOL_REPS = 2000
#: Resamples of a probability of improvement's interval: rliable's statistic runs a
#: Mann-Whitney test per draw, about 50 ms a resample for 50 draws.
IMPROVEMENT_REPS = 200
#: The intervals' coverage.
CONFIDENCE = 0.95
#: The protocol's least training seeds and held-out draws.
MIN_SEEDS, MIN_DRAWS = 5, 50
#: The aggregate statistics reported, in order.
STATISTICS = ("IQM", "median", "mean")


def score_matrix(costs: ArrayLike, draws: int | None = None) -> np.ndarray:
    """Costs as the protocol's ``(seeds, draws)`` matrix.

    Parameters
    ----------
    costs : array_like
        ``(draws,)`` (one training seed, or a deterministic controller) or
        ``(seeds, draws)``; finite costs >= 0, or +inf for a crash.
    draws : int, optional
        The number of draws expected.

    Returns
    -------
    ndarray
        ``(seeds, draws)``, float.

    Raises
    ------
    ValueError
        For another shape or number of draws, a NaN, or a negative cost.
    """
    matrix = np.asarray(costs, dtype=float)
    if matrix.ndim == 1:
        matrix = matrix[None, :]
    if matrix.ndim != 2 or matrix.size == 0:
        raise ValueError(f"costs must be (draws,) or (seeds, draws), got shape {matrix.shape}")
    if draws is not None and matrix.shape[1] != draws:
        raise ValueError(f"costs must cover the {draws} draws, got {matrix.shape[1]}")
    if np.isnan(matrix).any() or (matrix < 0).any():
        raise ValueError("costs must be >= 0 or +inf (a crash), not NaN or negative")
    return matrix


def _aggregates(scores: np.ndarray) -> np.ndarray:
    from rliable import metrics

    return np.array([metrics.aggregate_iqm(scores), metrics.aggregate_median(scores),
                     metrics.aggregate_mean(scores)])


def _matrices(costs: Mapping[str, ArrayLike]) -> dict[str, np.ndarray]:
    if not costs:
        raise ValueError("costs must name at least one controller or agent")
    matrices = {name: score_matrix(c) for name, c in costs.items()}
    draws = {m.shape[1] for m in matrices.values()}
    if len(draws) != 1:
        raise ValueError(f"every controller must be scored on the same draws, got "
                         f"{ {n: m.shape[1] for n, m in matrices.items()} }")
    return matrices


def _bootstrap(scores: dict[str, Any], func: Any, reps: int, seed: int) -> tuple[dict, dict]:
    from rliable import library

    if reps < 100:
        raise ValueError(f"reps must be >= 100, got {reps}")
    # rliable's stratified bootstrap draws its indices from numpy's global generator
    # whatever random_state it is given (arch's own draws take the RandomState, and
    # warn that its default will change): both seeded per name, so each interval is the
    # same whatever else is scored beside it, and the global state restored after
    points, intervals = {}, {}
    state = np.random.get_state()  # noqa: NPY002 (rliable reads the global generator)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "random_state is deprecated", FutureWarning)
            for name, value in scores.items():
                np.random.seed(seed)  # noqa: NPY002
                point, interval = library.get_interval_estimates(
                    {name: value}, func, task_bootstrap=True, reps=reps,
                    confidence_interval_size=CONFIDENCE,
                    random_state=np.random.RandomState(seed))
                points[name], intervals[name] = point[name], interval[name]
    finally:
        np.random.set_state(state)  # noqa: NPY002
    return points, intervals


def interval_estimates(costs: Mapping[str, ArrayLike], reps: int = PROTOCOL_REPS,
                       seed: int = 0) -> dict[str, dict[str, tuple[float, float, float]]]:
    """IQM, median and mean of each controller's costs with their 95 % intervals.

    Parameters
    ----------
    costs : mapping
        Name -> costs, ``(draws,)`` or ``(seeds, draws)`` (:func:`score_matrix`), all
        on the same draws.
    reps : int
        Bootstrap resamples (>= 100).
    seed : int
        Seeds the bootstrap.

    Returns
    -------
    dict
        Name -> statistic (:data:`STATISTICS`) -> ``(estimate, low, high)``.
    """
    matrices = _matrices(costs)
    with np.errstate(invalid="ignore"):
        points, intervals = _bootstrap(matrices, _aggregates, reps, seed)
    return {name: {stat: (float(points[name][i]), float(intervals[name][0, i]),
                          float(intervals[name][1, i]))
                   for i, stat in enumerate(STATISTICS)} for name in matrices}


def improvement_probabilities(costs: Mapping[str, ArrayLike], of: str, over: Sequence[str],
                              reps: int = IMPROVEMENT_REPS, seed: int = 0
                              ) -> dict[str, tuple[float, float, float]]:
    """The probability that ``of`` costs less than each of ``over`` on a draw.

    Parameters
    ----------
    costs : mapping
        As for :func:`interval_estimates`.
    of : str
        The controller or agent judged.
    over : sequence of str
        The ones it is compared with.
    reps, seed : int
        As for :func:`interval_estimates` (default :data:`IMPROVEMENT_REPS` resamples).

    Returns
    -------
    dict
        Name of ``over`` -> ``(probability, low, high)``: 0.5 is no better, 1 better on
        every draw.

    Raises
    ------
    KeyError
        For a name not in ``costs``.
    ValueError
        For two names scored over different numbers of seeds, both above one.
    """
    from rliable import metrics

    matrices = _matrices(costs)
    missing = [n for n in (of, *over) if n not in matrices]
    if missing:
        raise KeyError(f"no costs for {missing}; have {sorted(matrices)}")
    # rliable's probability is that X scores higher: lower cost is better, so negated. The
    # pair is stacked (seeds, draws, 2) so the bootstrap resamples the same draws for
    # both (paired) and the seeds of each independently; a deterministic controller's
    # one row is repeated to the other's seeds
    pairs = {}
    for name in over:
        x, y = -matrices[of], -matrices[name]
        if x.shape[0] != y.shape[0] and 1 not in (x.shape[0], y.shape[0]):
            raise ValueError(f"{of!r} and {name!r} have {x.shape[0]} and {y.shape[0]} seeds: "
                             "equal numbers, or one, are compared")
        seeds = max(x.shape[0], y.shape[0])
        pairs[name] = np.stack([np.repeat(x, seeds // x.shape[0], axis=0),
                                np.repeat(y, seeds // y.shape[0], axis=0)], axis=-1)
    points, intervals = _bootstrap(
        pairs, lambda s: np.array([metrics.probability_of_improvement(s[..., 0], s[..., 1])]),
        reps, seed)
    return {name: (float(points[name][0]), float(intervals[name][0, 0]),
                   float(intervals[name][1, 0])) for name in over}


def performance_profiles(costs: Mapping[str, ArrayLike], thresholds: ArrayLike,
                         reps: int = PROTOCOL_REPS, seed: int = 0
                         ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The share of runs and draws costing at most each threshold, with 95 % bands.

    Parameters
    ----------
    costs : mapping
        As for :func:`interval_estimates`.
    thresholds : array_like
        Costs at which the profile is taken, ``(k,)``, increasing.
    reps, seed : int
        As for :func:`interval_estimates`.

    Returns
    -------
    dict
        Name -> ``(share, low, high)``, each ``(k,)``.
    """
    taus = np.asarray(thresholds, dtype=float)
    if taus.ndim != 1 or taus.size == 0 or np.any(np.diff(taus) <= 0):
        raise ValueError("thresholds must be a non-empty increasing 1-D array")
    matrices = _matrices(costs)
    points, intervals = _bootstrap(
        matrices, lambda s: np.array([np.mean(s <= tau) for tau in taus]), reps, seed)
    return {name: (points[name], intervals[name][0], intervals[name][1])
            for name in matrices}


def _cell(estimate: tuple[float, float, float], fmt: str = ".3g") -> str:
    point, low, high = estimate
    if not np.isfinite(point):
        return "inf (crashes)"
    return f"{point:{fmt}} [{low:{fmt}}, {high:{fmt}}]"


def protocol_table(estimates: Mapping[str, Mapping[str, tuple[float, float, float]]],
                   improvements: Mapping[str, tuple[float, float, float]] | None = None,
                   of: str | None = None, seeds: Mapping[str, int] | None = None,
                   draws: int | None = None) -> str:
    """The protocol's markdown table: one row per controller or agent.

    Parameters
    ----------
    estimates : mapping
        :func:`interval_estimates`' result.
    improvements : mapping, optional
        :func:`improvement_probabilities`' result for ``of``.
    of : str, optional
        The row those probabilities belong to.
    seeds : mapping, optional
        Name -> training seeds behind its row (flagged below :data:`MIN_SEEDS`).
    draws : int, optional
        The held-out draws (flagged below :data:`MIN_DRAWS`).

    Returns
    -------
    str
        The table, then a line per probability of improvement and the protocol's flags.
    """
    lines = ["| controller | seeds | IQM [95 % CI] | median [95 % CI] | mean [95 % CI] |",
             "|---|---|---|---|---|"]
    for name, stats in estimates.items():
        n = "-" if seeds is None or name not in seeds else str(seeds[name])
        lines.append(f"| {name} | {n} | " + " | ".join(_cell(stats[s]) for s in STATISTICS)
                     + " |")
    text = "\n".join(lines) + "\n"
    if improvements:
        text += "\n" + "\n".join(
            f"P({of} costs less than {name} on a draw) = {_cell(p, '.2f')}"
            for name, p in improvements.items()) + "\n"
    flags = []
    if draws is not None and draws < MIN_DRAWS:
        flags.append(f"{draws} held-out draws (the protocol asks for >= {MIN_DRAWS})")
    few = [name for name, n in (seeds or {}).items() if n < MIN_SEEDS]
    if few:
        flags.append(f"fewer than {MIN_SEEDS} training seeds: {', '.join(few)}")
    if flags:
        text += "\nBelow the protocol: " + "; ".join(flags) + ".\n"
    return text
