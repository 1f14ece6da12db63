"""Per-domain summaries in the manner of rliable, computed once from the boards and drawn by the page and reports.

For each domain, every recognizer under its own scorer is compared over the
(task, protocol, level) strata that all of them ran (common ground: a
recognizer run on more strata is not aggregated over more work); a recognizer
sharing no stratum with the others is left out and named. Per recognizer:

* the interquartile mean of F1 over every seed of those strata, with a 95 %
  bootstrap interval stratified by stratum, and the plain mean;
* the probability of improvement between every pair;
* where the strata have Bayes ceilings, the **performance profile** (the share
  of runs whose normalised F1, ``(F1 - chance) / (ceiling - chance)``, exceeds
  each threshold) with stratified bootstrap bands, and the **optimality gap**
  (the mean shortfall of normalised F1 below the ceiling, 1) with its interval.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from grail_bench.harness.ceiling import normalised
from grail_bench.report.boards import Board, own_scorer_records, row_name
from grail_bench.stats.robust import (
    Interval,
    optimality_gap,
    performance_profile,
    pooled_iqm,
    pooled_mean,
    probability_of_improvement_ci,
    stratified_bootstrap,
    stratified_bootstrap_curve,
    tied_best,
)
from grail_bench.task import find_task

#: Thresholds of normalised F1 the performance profiles are drawn at.
TAUS = np.round(np.linspace(0.0, 1.0, 21), 2)


@dataclass
class DomainSummary:
    """One domain's comparison (see the module docstring)."""

    domain: str
    names: list[str]
    iqm: dict[str, Interval]
    mean: dict[str, float]
    best: set[str]
    poi: dict[tuple[str, str], Interval]
    strata: int
    all_strata: dict[str, int]
    left_out: list[str]
    recognizer: dict[str, str]
    profile_strata: int = 0
    profiles: dict[str, tuple[list[float], list[float], list[float]]] = field(default_factory=dict)
    gaps: dict[str, Interval] = field(default_factory=dict)


def common_strata(strata: dict[str, dict[tuple, list[float]]]) -> tuple[list[str], set[tuple], list[str]]:
    """The columns a domain summary compares, the strata they all ran, and the columns left out.

    Every compared column is aggregated over the same strata (common ground). If no stratum is shared by
    all, the column with the fewest strata is left out until one is.
    """
    names = sorted(strata, key=lambda n: (-len(strata[n]), n))
    left_out = []
    while names:
        shared = set.intersection(*(set(strata[n]) for n in names))
        if shared:
            return sorted(names), shared, sorted(left_out)
        left_out.append(names.pop())
    return [], set(), sorted(left_out)


def _domain(board: Board) -> str:
    task = find_task(board.rows[0][1])
    return task.domain if task else board.title


def domain_summaries(boards: Sequence[Board], reps: int = 2000, seed: int = 0) -> list[DomainSummary]:
    """Every domain's summary, from the boards' own-scorer cells."""
    strata: dict[str, dict[str, dict[tuple, list[float]]]] = defaultdict(lambda: defaultdict(dict))
    normal: dict[str, dict[str, dict[tuple, list[float]]]] = defaultdict(lambda: defaultdict(dict))
    recognizer: dict[str, dict[str, str]] = defaultdict(dict)
    for board in boards:
        domain = _domain(board)
        own = {id(r) for r in own_scorer_records(list(board.cells.values()))}
        for key, record in board.cells.items():
            if id(record) not in own:
                continue
            row, label = key[:5], key[5]
            stratum = (row_name(row), board.title, row[3])
            strata[domain][label][stratum] = list(record.f1_values)
            recognizer[domain][label] = record.recognizer
            ceiling = board.ceilings.get(row)
            if ceiling is not None and normalised(0.0, ceiling.accuracy, ceiling.chance) is not None:
                normal[domain][label][stratum] = [normalised(v, ceiling.accuracy, ceiling.chance)
                                                  for v in record.f1_values]
    return [_summary(d, strata[d], normal[d], recognizer[d], reps, seed) for d in sorted(strata)]


def _summary(domain: str, strata: dict[str, dict[tuple, list[float]]], normal: dict[str, dict[tuple, list[float]]],
             recognizer: dict[str, str], reps: int, seed: int) -> DomainSummary:
    names, shared, left_out = common_strata(strata)
    common = {n: {k: v for k, v in strata[n].items() if k in shared} for n in names}
    iqms = {n: stratified_bootstrap(common[n], pooled_iqm, reps=reps, seed=seed) for n in names}
    out = DomainSummary(
        domain=domain, names=names, iqm=iqms, mean={n: pooled_mean(common[n]) for n in names}, best=tied_best(iqms),
        poi={(a, b): probability_of_improvement_ci(common[a], common[b], reps=reps, seed=seed)
             for a in names for b in names if a != b},
        strata=len(shared), all_strata={n: len(strata[n]) for n in names}, left_out=left_out, recognizer=recognizer)
    with_ceiling = {n: normal[n] for n in names if n in normal}
    if len(with_ceiling) == len(names) and names:
        shared_normal = set.intersection(*(set(v) for v in with_ceiling.values())) & shared
        if shared_normal:
            out.profile_strata = len(shared_normal)
            for n in names:
                scores = {k: v for k, v in with_ceiling[n].items() if k in shared_normal}
                point, low, high = stratified_bootstrap_curve(scores, lambda s: performance_profile(s, TAUS),
                                                              reps=reps, seed=seed)
                out.profiles[n] = (point.tolist(), low.tolist(), high.tolist())
                out.gaps[n] = stratified_bootstrap(scores, optimality_gap, reps=reps, seed=seed)
    return out


def profiles_markdown(summaries: Sequence[DomainSummary]) -> str:
    """Optimality gaps and performance profiles as Markdown (domains whose strata have Bayes ceilings)."""
    lines = ["# Performance profiles and optimality gaps", "",
             "Per domain, each recognizer under its own scorer over the (task, protocol, level) strata every one",
             "of them ran that have a Bayes ceiling, on normalised F1 = (F1 - chance) / (ceiling - chance), every",
             "seed a run. Optimality gap: the mean shortfall below the ceiling (1), lower is better. Profile: the",
             "share of runs above each threshold. Intervals: 95 % stratified bootstrap (by stratum).", ""]
    shown = [s for s in summaries if s.profiles]
    if not shown:
        return "\n".join(lines + ["No domain has strata with Bayes ceilings in these runs.", ""])
    for s in shown:
        taus = [0.25, 0.5, 0.75, 0.9]
        index = [int(np.argmin(np.abs(TAUS - t))) for t in taus]
        lines += [f"## {s.domain} ({s.profile_strata} strata)", "",
                  "| recognizer | optimality gap | " + " | ".join(f"share > {t:.2f}" for t in taus) + " |",
                  "|---|---|" + "---|" * len(taus)]
        for n in s.names:
            gap = s.gaps[n]
            point, low, high = s.profiles[n]
            cells = [f"{point[i]:.2f} [{low[i]:.2f}, {high[i]:.2f}]" for i in index]
            lines.append(f"| {n} | {gap.point:.2f} [{gap.low:.2f}, {gap.high:.2f}] | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def profile_figure_data(summaries: Sequence[DomainSummary]) -> list[dict[str, Any]]:
    """What :func:`grail_bench.report.plots.profiles` draws: per domain with profiles, the curves and bands."""
    return [{"domain": s.domain, "strata": s.profile_strata, "taus": TAUS.tolist(), "curves": s.profiles}
            for s in summaries if s.profiles]
