"""Per-configuration tables beside the boards: runs and timings, the scorer ablation, calibration.

Each is computed once from the offline records, as frozen rows (:class:`TimingRow`, :class:`AblationRow`,
:class:`CalibrationRow`, a budget study's :class:`BudgetCurve`), and drawn by the terminal, Markdown and web
renderers. Configurations are named as the leaderboard names them (:func:`grail_bench.report.configs.configuration`).
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.boards import domain_of
from grail_bench.report.configs import configuration
from grail_bench.stats.metrics import expected_calibration_error
from grail_bench.task import find_task


@dataclass(frozen=True)
class TimingRow:
    """One configuration on one task: its runs, timings and ranking metrics (means over levels and protocols).

    Attributes:
        task: The task ID.
        column: The configuration's label (``BC-GRAIL``, ``GAIL-GRAIL · total_timesteps 20 000``).
        recognizer: The recognizer's registered name.
        seeds: Seeds of its first record.
        fit_seconds_per_goal: Training seconds per goal.
        score_us_per_observation: Microseconds to score one observation against every goal.
        tie_rate: Share of observations whose best score tied.
        top2, mean_rank: Top-2 accuracy and the true goal's mean rank (None where a record lacks them).
        set_precision, set_recall, set_spread: Of the set-valued answer (None where a record lacks them).
        reached: ``"reached/rolled out"`` of its goal fits' greedy rollouts (None without diagnostics).
    """

    task: str
    column: str
    recognizer: str
    seeds: int
    fit_seconds_per_goal: float
    score_us_per_observation: float
    tie_rate: float
    top2: float | None
    mean_rank: float | None
    set_precision: float | None
    set_recall: float | None
    set_spread: float | None
    reached: str | None


def timing_rows(records: Sequence[OfflineRecord],
                fits: dict[tuple[str, str, str], Any] | None = None) -> list[TimingRow]:
    """Per task and configuration: seeds, training seconds per goal, the means over levels of the scoring µs per
    observation, tie rate, top-2 accuracy and mean rank (``None`` when a level lacks them), and the share of its
    goal fits whose greedy rollout reached the goal (``None`` without stored diagnostics)."""
    groups: dict[tuple, list[OfflineRecord]] = defaultdict(list)
    for r in records:
        groups[(r.task, r.recognizer, r.scorer, r.config_hash)].append(r)
    out = []
    for same in groups.values():
        first = same[0]
        out.append(TimingRow(
            task=first.task, column=configuration(first).label, recognizer=first.recognizer, seeds=first.n_seeds,
            fit_seconds_per_goal=first.fit_seconds_per_goal,
            score_us_per_observation=sum(x.score_us_per_observation for x in same) / len(same),
            tie_rate=sum(x.tie_rate for x in same) / len(same),
            top2=_level_mean([x.top2_mean for x in same]), mean_rank=_level_mean([x.mean_rank_mean for x in same]),
            set_precision=_level_mean([x.set_precision_mean for x in same]),
            set_recall=_level_mean([x.set_recall_mean for x in same]),
            set_spread=_level_mean([x.set_spread_mean for x in same]),
            reached=_reached((fits or {}).get((first.task, first.recognizer, first.config_hash)))))
    return out


def _reached(summary: Any) -> str | None:
    """``"reached/rolled out"`` of a fit summary (None without one)."""
    if summary is None or not sum(summary.rolled_out):
        return None
    return f"{sum(summary.reached)}/{sum(summary.rolled_out)}"


def _level_mean(values: list[float | None]) -> float | None:
    return None if any(v is None for v in values) else sum(values) / len(values)


@dataclass(frozen=True)
class AblationRow:
    """One recognizer under one scorer on one task and protocol.

    Attributes:
        task: ``task ID (protocol)``: protocols are compared apart.
        recognizer, scorer: What was run.
        f1: Per observability level, ``(mean, std)`` of F1 over seeds.
        score_us: Mean microseconds to score one observation (over levels).
        f1_overall: Mean F1 over the levels.
        brier, nll: Means over levels of the posterior's Brier score and NLL (None without a posterior).
        ece: Expected calibration error of every level's reliability bins pooled (None without them).
    """

    task: str
    recognizer: str
    scorer: str
    f1: dict[float, tuple[float, float]]
    score_us: float
    f1_overall: float
    brier: float | None = None
    nll: float | None = None
    ece: float | None = None


def ablation_rows(records: Sequence[OfflineRecord]) -> list[AblationRow]:
    """Per task and protocol, recognizer and scorer: F1 at each level, mean scoring time and calibration.

    Only recognizers run with more than one scorer on a task are included
    (the paper's Figures 4 and 5).
    """
    scorers = defaultdict(set)
    for r in records:
        scorers[(r.task, r.protocol, r.recognizer)].add(r.scorer)
    groups: dict[tuple[str, str, str], list[OfflineRecord]] = defaultdict(list)
    for r in records:
        if len(scorers[(r.task, r.protocol, r.recognizer)]) >= 2:
            groups[(f"{r.task} ({r.protocol})", r.recognizer, r.scorer)].append(r)
    out = []
    for (task, recognizer, scorer), group in sorted(groups.items()):
        f1 = {r.observability: (r.f1.mean, r.f1.std) for r in group}
        posterior = [r for r in group if r.brier_mean is not None]
        bins = [r.reliability for r in group if r.reliability is not None]
        out.append(AblationRow(
            task, recognizer, scorer, f1,
            score_us=sum(r.score_us_per_observation for r in group) / len(group),
            f1_overall=sum(m for m, _ in f1.values()) / len(f1),
            brier=sum(r.brier_mean for r in posterior) / len(posterior) if posterior else None,
            nll=sum(r.nll_mean for r in posterior) / len(posterior) if posterior else None,
            ece=expected_calibration_error(np.sum(bins, axis=0).tolist()) if bins else None))
    return out


@dataclass(frozen=True)
class CalibrationRow:
    """One recognizer/scorer with a posterior on one domain, every observation of every task, level and seed
    pooled.

    Attributes:
        domain: The tasks' domain.
        column: ``recognizer/scorer``.
        records: How many records were pooled.
        brier, nll: Mean Brier score and NLL (None where a record lacks them).
        ece: Expected calibration error of the pooled bins (None without predictions).
        bins: Reliability bins, ``[count, summed confidence, correct count]`` per confidence bin.
    """

    domain: str
    column: str
    records: int
    brier: float | None
    nll: float | None
    ece: float | None
    bins: list[list[float]]


def calibration_rows(records: Sequence[OfflineRecord]) -> list[CalibrationRow]:
    """Per domain and recognizer/scorer with a posterior (``loglik``): Brier score, NLL and the ECE and
    reliability bins of every observation of every seed, task and level pooled."""
    groups: dict[tuple[str, str], list[OfflineRecord]] = defaultdict(list)
    for r in records:
        if r.reliability is not None:
            task = find_task(r.task)
            groups[(task.domain if task else domain_of(r.task), f"{r.recognizer}/{r.scorer}")].append(r)
    out = []
    for (domain, label), group in sorted(groups.items()):
        bins = np.sum([r.reliability for r in group], axis=0).tolist()
        out.append(CalibrationRow(domain, label, len(group), _level_mean([r.brier_mean for r in group]),
                                  _level_mean([r.nll_mean for r in group]), expected_calibration_error(bins), bins))
    return out


@dataclass(frozen=True)
class BudgetPoint:
    """One studied value of a budget curve: F1 over seeds (mean and 95 % bootstrap interval, inside [0, 1]) and
    the fit's seconds per goal."""

    value: Any
    n_seeds: int
    f1_mean: float
    f1_ci95_low: float
    f1_ci95_high: float
    fit_seconds_per_goal: float


@dataclass(frozen=True)
class BudgetCurve:
    """One recognizer's budget (or scaling) study on one task, protocol and level.

    Attributes:
        section: The profile section.
        param: The studied parameter (``n_goals`` for a scaling study).
        task: The task (a scaling study: the range of its tasks).
        recognizer, protocol, observability: What the points are of.
        points: The studied values, in increasing order.
        scaling: Whether it is a scaling study (then ``exponent``, else ``plateau``).
        plateau: The smallest value whose mean F1 reaches the best value's interval
            (:func:`grail_bench.stats.verdict.plateau`); None while fewer than two values have rows.
        exponent: The fit-cost exponent against the goal count (None with a single goal count).
    """

    section: str
    param: str
    task: str
    recognizer: str
    protocol: str
    observability: float
    points: tuple[BudgetPoint, ...]
    scaling: bool = False
    plateau: Any = None
    exponent: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """As ``budgets.json`` holds it: flat JSON-able data, with the plateau of a budget study or the exponent
        of a scaling study."""
        data = dataclasses.asdict(self)
        del data["scaling"], data["plateau" if self.scaling else "exponent"]
        return data
