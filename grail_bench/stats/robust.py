"""Robust statistics over few seeds, after rliable (Agarwal et al., NeurIPS 2021).

rliable itself does not install on this stack, so its estimators are written
here in numpy/scipy:

- the interquartile mean (IQM), the mean of the middle 50 % of the scores;
- stratified bootstrap confidence intervals: resample the runs of each task
  (stratum) with replacement, recompute the statistic, take percentiles;
- the probability of improvement ``P(X > Y)``: for each task, the chance that
  a run of X scores above a run of Y (ties count half), averaged over tasks.

Scores are given as ``{task: values}`` so tasks may have different numbers of
runs. Statistics work on the last axis, so a bootstrap evaluates all its
replicates in one call. Every bootstrap takes a seed: same seed, same interval.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable, Hashable, Mapping, Sequence

import numpy as np

from grail_bench.core.errors import UserError

Scores = Mapping[Hashable, Sequence[float]]
Statistic = Callable[[Mapping[Hashable, np.ndarray]], Any]  # arrays (..., runs) -> values (...)


@dataclass(frozen=True)
class Interval:
    """A point estimate and its confidence interval."""

    point: float
    low: float
    high: float

    def overlaps(self, other: Interval) -> bool:
        """Whether the two intervals share a point (the estimates are not told apart)."""
        return self.low <= other.high + 1e-12 and other.low <= self.high + 1e-12


def _check(scores: Scores) -> dict[str, np.ndarray]:
    arrays = {task: np.asarray(values, dtype=float).ravel() for task, values in scores.items()}
    if not arrays or any(a.size == 0 for a in arrays.values()):
        raise UserError("robust statistics need at least one score for every task")
    return arrays


def iqm(values: Sequence[float] | np.ndarray) -> Any:
    """Interquartile mean over the last axis: the mean left after trimming 25 % from each end.

    As scipy's ``trim_mean`` (which rliable uses), which trims ``floor(0.25 n)``
    scores from each end: with fewer than 4 scores it is the plain mean.
    """
    x = np.asarray(values, dtype=float)
    if x.size == 0:
        raise UserError("the IQM of no scores is undefined")
    # scipy's trim_mean, step for step (the same partition, so the same numbers), without its per-call
    # argument handling, which cost most of an aggregation over thousands of cells.
    n = x.shape[-1]
    low = int(0.25 * n)
    kept = np.partition(x, (low, n - low - 1), axis=-1)[..., low:n - low]
    out = np.mean(kept, axis=-1)
    return float(out) if np.ndim(out) == 0 else out


def pooled_iqm(scores: Mapping[Hashable, np.ndarray]) -> Any:
    """IQM of all runs of all tasks pooled together (rliable's aggregate IQM)."""
    return iqm(np.concatenate([np.asarray(v, dtype=float) for v in scores.values()], axis=-1))


def pooled_mean(scores: Mapping[Hashable, np.ndarray]) -> Any:
    """Mean of all runs of all tasks pooled together."""
    out = np.concatenate([np.asarray(v, dtype=float) for v in scores.values()], axis=-1).mean(axis=-1)
    return float(out) if np.ndim(out) == 0 else out


def stratified_bootstrap(scores: Scores, statistic: Statistic, *, reps: int = 2000,
                         confidence: float = 0.95, seed: int = 0) -> Interval:
    """Percentile interval of ``statistic`` under a bootstrap stratified by task.

    Each replicate draws, within every task, as many runs as it has, with
    replacement. With one task this is the ordinary percentile bootstrap.

    Args:
        scores: ``{task: per-run scores}``.
        statistic: Maps such a mapping to a number, over the last axis of
            its arrays (e.g. :func:`pooled_iqm`).
        reps: Bootstrap replicates.
        confidence: Two-sided coverage, e.g. 0.95.
        seed: Seed of the resampling.
    """
    if not 0 < confidence < 1:
        raise UserError(f"confidence must lie in (0, 1), got {confidence}")
    if reps < 1:
        raise UserError(f"reps must be positive, got {reps}")
    arrays = _check(scores)
    draws = bootstrap_draws(seed, reps, tuple(a.size for a in arrays.values()))
    replicates = np.asarray(statistic({task: a[d] for (task, a), d in zip(arrays.items(), draws)}))
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(replicates, [tail, 100 - tail])
    return Interval(float(statistic(arrays)), float(low), float(high))


@lru_cache(maxsize=256)
def bootstrap_draws(seed: int, reps: int, sizes: tuple[int, ...]) -> tuple[np.ndarray, ...]:
    """The resampled indices of a stratified bootstrap, per stratum in order: they depend only on the seed, the
    replicates and the strata's sizes, so thousands of cells of ten seeds each draw them once (read only)."""
    rng = np.random.default_rng(seed)
    out = tuple(rng.integers(0, n, size=(reps, n)) for n in sizes)
    for d in out:
        d.flags.writeable = False
    return out


def _improvement(x: np.ndarray, y: np.ndarray) -> Any:
    """P(a run of x scores above a run of y) over the last axis, ties counting half (Mann-Whitney U / (n m))."""
    n, m = x.shape[-1], y.shape[-1]
    if n * m <= 400:  # few runs: every pair compared is the faster
        diff = x[..., :, None] - y[..., None, :]
        return ((diff > 0).sum(axis=(-2, -1)) + 0.5 * (diff == 0).sum(axis=(-2, -1))) / (n * m)
    lead = np.broadcast_shapes(x.shape[:-1], y.shape[:-1])
    x, y = np.broadcast_to(x, lead + (n,)), np.broadcast_to(y, lead + (m,))
    # Many runs: from the x runs' average ranks among all runs (the U statistic), the same count exactly (ranks
    # are halves) without an (n, m) array of differences per replicate.
    from scipy.stats import rankdata  # here: scipy.stats takes seconds to import, and few runs never need it

    ranks = rankdata(np.concatenate([x, y], axis=-1), axis=-1)
    return (ranks[..., :n].sum(axis=-1) - n * (n + 1) / 2) / (n * m)


def probability_of_improvement(x: Scores, y: Scores) -> float:
    """``P(X > Y)`` averaged over the tasks both have runs on.

    Raises:
        UserError: When X and Y share no task.
    """
    xs, ys = _check(x), _check(y)
    common = sorted(set(xs) & set(ys))
    if not common:
        raise UserError("probability of improvement needs tasks both recognizers ran")
    return float(np.mean([_improvement(xs[t], ys[t]) for t in common]))


def probability_of_improvement_ci(x: Scores, y: Scores, *, reps: int = 2000, confidence: float = 0.95,
                                  seed: int = 0) -> Interval:
    """:func:`probability_of_improvement` with a bootstrap interval stratified by task, over both sets of runs."""
    xs, ys = _check(x), _check(y)
    common = sorted(set(xs) & set(ys))
    if not common:
        raise UserError("probability of improvement needs tasks both recognizers ran")
    joint = {("x", t): xs[t] for t in common} | {("y", t): ys[t] for t in common}

    def statistic(s: Mapping[Hashable, np.ndarray]) -> Any:
        return np.mean([_improvement(s[("x", t)], s[("y", t)]) for t in common], axis=0)

    return stratified_bootstrap(joint, statistic, reps=reps, confidence=confidence, seed=seed)


def tied_best(intervals: Mapping[str, Interval]) -> set[str]:
    """The names whose interval overlaps the interval of the best point estimate.

    One name when the best stands clear of every other; several when the data
    cannot order them. Empty for no intervals.
    """
    if not intervals:
        return set()
    best = max(intervals.values(), key=lambda i: i.point)
    return {name for name, i in intervals.items() if i.overlaps(best)}


def performance_profile(scores: Mapping[Hashable, np.ndarray], taus: np.ndarray) -> Any:
    """rliable's run-score performance profile: the share of all runs scoring above each threshold ``tau``.

    Works over the last axis like the other statistics (so a bootstrap evaluates every replicate at once):
    arrays ``(..., runs)`` give ``(..., len(taus))``.
    """
    pooled = np.concatenate([np.asarray(v, dtype=float) for v in scores.values()], axis=-1)
    return (pooled[..., None, :] > np.asarray(taus)[:, None]).mean(axis=-1)


def optimality_gap(scores: Mapping[Hashable, np.ndarray], gamma: float = 1.0) -> Any:
    """rliable's optimality gap: the mean shortfall of the runs below ``gamma`` (scores above it count 0)."""
    pooled = np.concatenate([np.asarray(v, dtype=float) for v in scores.values()], axis=-1)
    out = np.maximum(gamma - pooled, 0.0).mean(axis=-1)
    return float(out) if np.ndim(out) == 0 else out


def stratified_bootstrap_curve(scores: Scores, statistic: Statistic, *, reps: int = 2000, confidence: float = 0.95,
                               seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`stratified_bootstrap` of a vector statistic (e.g. :func:`performance_profile`): point, low, high."""
    arrays = _check(scores)
    draws = bootstrap_draws(seed, reps, tuple(a.size for a in arrays.values()))
    replicates = np.asarray(statistic({task: a[d] for (task, a), d in zip(arrays.items(), draws)}))  # (reps, n)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(replicates, [tail, 100 - tail], axis=0)
    return np.asarray(statistic(arrays), dtype=float), low, high
