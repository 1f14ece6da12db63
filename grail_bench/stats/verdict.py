"""Verdicts from seeds: our mean against a reported value (placement, two-sided Welch test), and budget plateaus.

* :func:`place`: our mean inside, above or below the publication's 95 % interval;
* :func:`welch_verdict`: Welch's unequal-variance t-test of our per-seed values
  against the publication's mean and std over its ``n`` runs (two-sided,
  ``alpha = 0.05``): *consistent*, or significantly *higher* or *lower*.

A zero std on one side is fine (the other side's variance carries the test);
on both sides the means either agree exactly (consistent) or differ with
certainty. :func:`plateau` picks a default budget from a budget study: the
smallest budget whose mean F1 reaches the 95 % interval of the best one's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

ALPHA = 0.05
VERDICTS = ("consistent", "higher", "lower")


def place(mean: float, ci95: tuple[float, float] | None) -> str | None:
    """``"inside"``, ``"above"`` or ``"below"`` the interval ``ci95`` (None without one)."""
    if ci95 is None:
        return None
    low, high = ci95
    return "below" if mean < low - 1e-9 else "above" if mean > high + 1e-9 else "inside"


@dataclass(frozen=True)
class Verdict:
    """A Welch test of our values against a reported mean and std.

    Attributes:
        verdict: ``"consistent"``, ``"higher"`` or ``"lower"`` (ours against theirs, at :data:`ALPHA`).
        t: Welch's t statistic (ours minus theirs); infinite when both stds are 0 and the means differ.
        df: Welch-Satterthwaite degrees of freedom (NaN when both stds are 0).
        p: Two-sided p-value.
    """

    verdict: str
    t: float
    df: float
    p: float


def welch_verdict(values: Sequence[float], mean: float, std: float, n: int, alpha: float = ALPHA) -> Verdict:
    """Welch's two-sided t-test of ``values`` (our seeds) against a reported ``mean ± std`` over ``n`` runs.

    Raises:
        ValueError: With fewer than 2 values or runs, or a negative std.
    """
    x = np.asarray(values, dtype=float)
    if len(x) < 2 or n < 2:
        raise ValueError("a Welch test needs at least 2 values on each side")
    if std < 0:
        raise ValueError(f"a standard deviation cannot be negative, got {std}")
    ours_mean, ours_var = float(x.mean()), float(x.var(ddof=1))
    va, vb = ours_var / len(x), std * std / n
    diff = ours_mean - mean
    if va + vb == 0.0:
        if abs(diff) <= 1e-12:
            return Verdict("consistent", 0.0, math.nan, 1.0)
        return Verdict("higher" if diff > 0 else "lower", math.copysign(math.inf, diff), math.nan, 0.0)
    t = diff / math.sqrt(va + vb)
    df = (va + vb) ** 2 / ((va * va / (len(x) - 1) if va else 0.0) + (vb * vb / (n - 1) if vb else 0.0))
    from scipy import stats  # here: scipy.stats takes seconds to import, and only a reference's cells test

    p = float(2 * stats.t.sf(abs(t), df))
    verdict = "consistent" if p >= alpha else "higher" if t > 0 else "lower"
    return Verdict(verdict, float(t), float(df), p)


def plateau(points: Sequence[tuple[float, float, float]]) -> float:
    """The smallest budget on the plateau: whose mean is at least the lower 95 % bound of the best budget's.

    Args:
        points: ``(budget, mean, lower 95 % bound)`` per budget measured.

    Raises:
        ValueError: Without points.
    """
    if not points:
        raise ValueError("a plateau needs at least one budget")
    best = max(points, key=lambda p: (p[1], -p[0]))
    return min(budget for budget, mean, _ in points if mean >= best[2] - 1e-12)


def scaling_exponent(sizes: Sequence[float], costs: Sequence[float]) -> float:
    """The exponent ``b`` of ``cost ~ a * size**b``: the least-squares slope in log-log space.

    Raises:
        ValueError: With fewer than two distinct sizes or a non-positive value.
    """
    x, y = np.asarray(sizes, dtype=float), np.asarray(costs, dtype=float)
    if len(set(x.tolist())) < 2 or (x <= 0).any() or (y <= 0).any():
        raise ValueError("a scaling exponent needs two or more distinct sizes and positive costs")
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])
