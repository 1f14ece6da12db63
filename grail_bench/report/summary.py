"""Per-domain summaries in the manner of rliable, computed once from the main boards and drawn by every renderer.

For each domain, every canonical method (references such as the demonstrator excluded) is compared over the
(task, protocol, level) strata that all of them ran (common ground: a method run on more strata is not
aggregated over more work). A method lacking strata another ran is not dropped silently: the summary names
the strata it lacks (a gap in the data). When no stratum is shared by all, the largest set of methods sharing
a stratum is compared, and the methods it leaves out get a summary of their own with the methods they share
most with (:func:`comparison_groups`), so that every method is ranked somewhere. Per method:

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
from grail_bench.report.boards import Board
from grail_bench.report.escape import md
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
from grail_bench.task.observation import level_text

#: Thresholds of normalised F1 the performance profiles are drawn at.
TAUS = np.round(np.linspace(0.0, 1.0, 21), 2)

Stratum = tuple[str, str, float]  # (task as shown, protocol, level): :attr:`grail_bench.report.boards.BoardRow.stratum`


@dataclass
class DomainSummary:
    """One domain's comparison (see the module docstring).

    Attributes:
        domain: The domain.
        title: How the summary is headed: the domain, numbered when the domain has more than one.
        names: The methods compared (their labels).
        iqm: Per method, the IQM of F1 over the shared strata with its 95 % interval.
        mean: Per method, the plain mean over the same runs.
        best: The methods whose interval overlaps the best IQM's.
        poi: Per ordered pair ``(a, b)``, the probability that a run of ``a`` scores above one of ``b``.
        shared: The strata every compared method ran, sorted.
        all_strata: Per method, how many strata it ran in the domain.
        missing: Per compared method, the strata another method ran and it did not (empty when none).
        left_out: The domain's other methods, which share no stratum with all of these: per method, the title of
            the summary that compares it.
        recognizer: Per method, its recognizer's registered name.
    """

    domain: str
    title: str
    names: list[str]
    iqm: dict[str, Interval]
    mean: dict[str, float]
    best: set[str]
    poi: dict[tuple[str, str], Interval]
    shared: list[Stratum]
    all_strata: dict[str, int]
    missing: dict[str, list[Stratum]]
    left_out: dict[str, str]
    recognizer: dict[str, str]
    profile_strata: int = 0
    profiles: dict[str, tuple[list[float], list[float], list[float]]] = field(default_factory=dict)
    gaps: dict[str, Interval] = field(default_factory=dict)

    @property
    def strata(self) -> int:
        """How many strata the comparison covers."""
        return len(self.shared)

    @property
    def strata_text(self) -> list[str]:
        """The shared strata, per task and protocol (:func:`describe_strata`)."""
        return describe_strata(self.shared)

    @property
    def ranked_elsewhere(self) -> dict[str, list[str]]:
        """The methods left out, per title of the summary that ranks them."""
        out: dict[str, list[str]] = defaultdict(list)
        for name, title in self.left_out.items():
            out[title].append(name)
        return dict(out)

    @property
    def gaps_text(self) -> dict[str, str]:
        """Per method lacking strata, which ones (``MiniGrid-Optimal (prefix) at 10%, 20%``), for the reader."""
        return {n: "; ".join(describe_strata(m)) for n, m in self.missing.items() if m}


def describe_strata(strata: Sequence[Stratum]) -> list[str]:
    """``MiniGrid-Optimal (subset) at 10%, 20%, 30%`` per task and protocol; more than four levels read as a
    range, ``10%–100% (10 levels)``."""
    levels: dict[tuple[str, str], list[float]] = defaultdict(list)
    for name, protocol, level in strata:
        levels[(name, protocol)].append(level)
    out = []
    for (name, protocol), lv in sorted(levels.items()):
        lv = sorted(set(lv))
        at = (", ".join(level_text(x) for x in lv) if len(lv) <= 4
              else f"{level_text(lv[0])}–{level_text(lv[-1])} ({len(lv)} levels)")
        out.append(f"{name} ({protocol}) at {at}")
    return out


def common_strata(strata: dict[str, dict[Any, list[float]]],
                  among: set[str] | None = None) -> tuple[list[str], set, list[str]]:
    """The methods a domain summary compares, the strata they all ran, and the methods left out.

    Every compared method is aggregated over the same strata (common ground). The compared methods are the
    largest set that shares a stratum (with ``among``: that holds one of those methods); among sets as large, the
    one sharing the most tasks (a stratum's first field; more observation levels of the same tasks say less than
    more tasks do), then the most strata, then the first by name. A method run on few strata thus leaves itself
    out, never the methods it does not overlap.
    """
    ran: dict[Any, frozenset[str]] = defaultdict(frozenset)
    for name, per_stratum in strata.items():
        for stratum in per_stratum:
            ran[stratum] |= {name}
    if not ran:
        return [], set(), sorted(strata)

    def shared_by(group: frozenset[str]) -> set:
        return {k for k, names in ran.items() if group <= names}

    def tasks(group: frozenset[str]) -> int:
        return len({k[0] if isinstance(k, tuple) else k for k in shared_by(group)})

    candidates = {g for g in ran.values() if among is None or g & among}
    best = min(candidates, key=lambda g: (-len(g), -tasks(g), -len(shared_by(g)), sorted(g)))
    return sorted(best), shared_by(best), sorted(set(strata) - best)


def comparison_groups(strata: dict[str, dict[Any, list[float]]]) -> list[tuple[list[str], set]]:
    """The comparisons that rank every method of a domain: :func:`common_strata`'s, then, while methods are left
    out, the best set holding one of them (``[(methods, shared strata), ...]``, the first the largest)."""
    groups: list[tuple[list[str], set]] = []
    left = {n for n, per_stratum in strata.items() if per_stratum}
    while left:
        names, shared, _ = common_strata(strata, among=left if groups else None)
        groups.append((names, shared))
        left -= set(names)
    return groups


def domain_summaries(boards: Sequence[Board], reps: int = 2000, seed: int = 0,
                     improvement: bool = True) -> list[DomainSummary]:
    """Every domain's summary, from the main boards' method cells (variant boards and references ignored);
    without the probabilities of improvement (``poi`` empty) unless ``improvement`` (the terminal shows none)."""
    strata: dict[str, dict[str, dict[Stratum, list[float]]]] = defaultdict(lambda: defaultdict(dict))
    normal: dict[str, dict[str, dict[Stratum, list[float]]]] = defaultdict(lambda: defaultdict(dict))
    recognizer: dict[str, dict[str, str]] = defaultdict(dict)
    for board in boards:
        if board.kind != "canonical":
            continue
        methods = set(board.methods)
        for (row, label), record in board.cells.items():
            if label not in methods:
                continue
            strata[board.domain][label][row.stratum] = list(record.f1.values)
            recognizer[board.domain][label] = record.recognizer
            ceiling = board.ceilings.get(row)
            if ceiling is not None and normalised(0.0, ceiling.accuracy, ceiling.chance) is not None:
                normal[board.domain][label][row.stratum] = [normalised(v, ceiling.accuracy, ceiling.chance)
                                                            for v in record.f1.values]
    out = []
    for d in sorted(strata):
        groups = comparison_groups(strata[d])
        titles = [d if len(groups) == 1 else f"{d} ({k + 1} of {len(groups)})" for k in range(len(groups))]
        compared_in: dict[str, str] = {}  # each method's first summary
        for (names, _), title in zip(groups, titles):
            for n in names:
                compared_in.setdefault(n, title)
        for (names, shared), title in zip(groups, titles):
            left_out = {n: t for n, t in sorted(compared_in.items()) if n not in names}
            out.append(_summary(d, title, names, shared, left_out, strata[d], normal[d], recognizer[d], reps, seed,
                                improvement))
    return out


def _summary(domain: str, title: str, names: list[str], shared: set, left_out: dict[str, str],
             strata: dict[str, dict[Stratum, list[float]]], normal: dict[str, dict[Stratum, list[float]]],
             recognizer: dict[str, str], reps: int, seed: int, improvement: bool = True) -> DomainSummary:
    everything = set().union(*(set(strata[n]) for n in names)) if names else set()
    common = {n: {k: v for k, v in strata[n].items() if k in shared} for n in names}
    iqms = {n: stratified_bootstrap(common[n], pooled_iqm, reps=reps, seed=seed) for n in names}
    out = DomainSummary(
        domain=domain, title=title, names=names, iqm=iqms, mean={n: pooled_mean(common[n]) for n in names},
        best=tied_best(iqms),
        poi={(a, b): probability_of_improvement_ci(common[a], common[b], reps=reps, seed=seed)
             for a in names for b in names if a != b and improvement},
        shared=sorted(shared), all_strata={n: len(strata[n]) for n in [*names, *left_out]},
        missing={n: sorted(everything - set(strata[n])) for n in names}, left_out=left_out,
        recognizer=recognizer)
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
        lines += [f"## {md(s.title)} ({s.profile_strata} strata)", "",
                  "| method | optimality gap | " + " | ".join(f"share > {t:.2f}" for t in taus) + " |",
                  "|---|---|" + "---|" * len(taus)]
        for n in s.names:
            gap = s.gaps[n]
            point, low, high = s.profiles[n]
            cells = [f"{point[i]:.2f} [{low[i]:.2f}, {high[i]:.2f}]" for i in index]
            lines.append(f"| {md(n)} | {gap.point:.2f} [{gap.low:.2f}, {gap.high:.2f}] | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def profile_figure_data(summaries: Sequence[DomainSummary]) -> list[dict[str, Any]]:
    """What :func:`grail_bench.report.plots.profiles` draws: per summary with profiles, its title, curves and
    bands."""
    return [{"title": s.title, "strata": s.profile_strata, "taus": TAUS.tolist(), "curves": s.profiles}
            for s in summaries if s.profiles]
