"""The GRAIL paper's headline claims, each checked against the stored runs with a 95 % interval and a verdict.

:data:`CLAIMS` lists what the paper (AAMAS 2026) claims in its abstract, introduction, results and conclusion,
each with where it says so, the strata it is about (tasks and observed shares, as in the paper's grid) and the
range of F1 (or of F1 gain) it claims. :func:`headline_claims` measures every claim for every configuration it
concerns: the canonical configuration of each method the claim names, and every named variant of them present
in the records (another scorer, ``off_support stay``, ``occupancy``, ...); archived configurations never.
Only runs under each task's default observation protocol and at its default parameters count, as in the paper,
on the demonstrations the task generates (not runs on a dataset's, ``run --demos``).

**The measurement.** Within a stratum (task, observed share), a claim about F1 uses the per-seed F1 values; a
claim about a gain "over GRAQL" (or DRACO) uses the paired per-seed differences, configuration minus the
baseline's canonical configuration, over the seeds both ran. The estimate combines the strata's means with
equal weight: their mean, their largest (for "up to"), or the mean of one group of tasks minus that of another
(for "most in"). Its 95 % interval is a percentile bootstrap stratified by stratum
(:func:`grail_bench.stats.robust.stratified_bootstrap`), seeded, so the same records give the same table.

**The verdict.** Each claim reads as a range ``[low, high]`` of the measured quantity (a threshold is a range
open above). The claim **holds** when the whole 95 % interval lies inside the range, **does not hold** when
the interval lies wholly outside it, and holds **partly** when the interval straddles an end of the range.
It is **not measured** when the records lack a stratum the claim needs (or, for a gain, the baseline's runs
there, or seeds both ran).

**Readings of vague words** ("near perfect", "competitive", "up to about 0.4") are operational ranges chosen
from the paper's own text; :data:`READINGS` gives each with its reason, and the Markdown shows them.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Hashable, Literal, Mapping, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.escape import md
from grail_bench.report.configs import configuration
from grail_bench.stats.robust import stratified_bootstrap
from grail_bench.task import find_task, variant

GRAIL = ("BC-GRAIL", "GAIL-GRAIL", "AIRL-GRAIL")
VERDICTS = ("holds", "partly", "does not hold", "not measured")

Statistic = Literal["mean", "max", "contrast"]

_MINIGRID_BIASED = ("GRAIL/MiniGrid-Biased-v0",)
_MINIGRID_SUBOPTIMAL = ("GRAIL/MiniGrid-Suboptimal-v1", "GRAIL/MiniGrid-Suboptimal-4Goals-v1",
                        "GRAIL/MiniGrid-Suboptimal-6Goals-v1")
_MINIGRID_OPTIMAL = ("GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Optimal-4Goals-v0",
                     "GRAIL/MiniGrid-Optimal-6Goals-v0")
_PANDA_NOISY = ("GRAIL/PandaReach-Gaussian-0.1-v0", "GRAIL/PandaReach-Gaussian-0.3-v0",
                "GRAIL/PandaReach-Uniform-0.1-v0", "GRAIL/PandaReach-Uniform-0.3-v0")
_PANDA_OPTIMAL = ("GRAIL/PandaReach-Optimal-v0",)


@dataclass(frozen=True)
class Claim:
    """One headline claim of the paper and how it is measured.

    Attributes:
        claim: The claim as the paper makes it, short.
        source: Where the paper says it.
        subjects: Published names of the methods it is about (``BC-GRAIL``, ``GRAQL``).
        tasks: The task IDs of its strata.
        levels: The observed shares of its strata (every task at every level).
        low, high: The claimed range of the measured quantity (``math.inf`` for a threshold).
        strict: Whether ``low`` itself is outside the range ("more than 0.5").
        reading: The range as a sentence, with the reading of any vague word.
        measured: What is measured, short.
        baseline: Published name of the method a gain is over (None: the claim is about F1 itself).
        statistic: How strata means combine: ``mean``; ``max`` over strata ("up to"); ``contrast``, the mean
            over :attr:`contrast` tasks minus the mean over the others ("most in").
        contrast: The tasks of the first group of a ``contrast``.
    """

    claim: str
    source: str
    subjects: tuple[str, ...]
    tasks: tuple[str, ...]
    levels: tuple[float, ...]
    low: float
    high: float
    reading: str
    measured: str
    baseline: str | None = None
    statistic: Statistic = "mean"
    contrast: tuple[str, ...] = ()
    strict: bool = False

    @property
    def strata(self) -> list[tuple[str, float]]:
        """Every (task, observed share) the claim is about."""
        return [(task, level) for task in self.tasks for level in self.levels]


#: The paper's headline claims, in the order the paper makes them.
CLAIMS: tuple[Claim, ...] = (
    Claim("Every GRAIL variant reaches near-perfect F1 under systematically biased behaviour",
          "Abstract; Introduction; §5.1, Fig. 4", GRAIL, _MINIGRID_BIASED, (0.2, 0.3, 0.4), 0.9, 1.0,
          "near perfect: F1 >= 0.9", "mean F1, MiniGrid biased (2 goals) x 20/30/40 %"),
    Claim("GRAQL stays at 0.3-0.5 F1 under systematically biased behaviour",
          "Introduction; §5.1", ("GRAQL",), _MINIGRID_BIASED, (0.2, 0.3, 0.4), 0.3, 0.5,
          "F1 in [0.3, 0.5]", "mean F1, MiniGrid biased (2 goals) x 20/30/40 %"),
    Claim("GRAIL raises F1 by more than 0.5 over GRAQL under systematically biased behaviour",
          "Abstract", GRAIL, _MINIGRID_BIASED, (0.2, 0.3, 0.4), 0.5, math.inf,
          "gain > 0.5", "mean paired F1 gain over GRAQL, MiniGrid biased (2 goals) x 20/30/40 %", "GRAQL",
          strict=True),
    Claim("GRAIL gains about 0.1-0.3 F1 over GRAQL under suboptimal behaviour",
          "Abstract; Introduction; §5.2, Table 3", GRAIL, _MINIGRID_SUBOPTIMAL, (0.1, 0.2, 0.3), 0.1, 0.3,
          "gain in [0.1, 0.3]", "mean paired F1 gain over GRAQL, MiniGrid suboptimal 2/4/6 goals x 10/20/30 %",
          "GRAQL"),
    Claim("The suboptimal gains over GRAQL are 0.1-0.3 in the harder 4- and 6-goal settings",
          "Introduction; §5.2, Table 3", GRAIL, _MINIGRID_SUBOPTIMAL[1:], (0.1, 0.2, 0.3), 0.1, 0.3,
          "gain in [0.1, 0.3]", "mean paired F1 gain over GRAQL, MiniGrid suboptimal 4/6 goals x 10/20/30 %",
          "GRAQL"),
    Claim("The suboptimal gains over GRAQL are largest in the multi-goal settings",
          "Introduction; §5.2, Table 3", GRAIL, _MINIGRID_SUBOPTIMAL, (0.1, 0.2, 0.3), 0.0, math.inf,
          "gain on 4/6 goals minus gain on 2 goals > 0",
          "mean paired gain over GRAQL on 4/6 goals minus on 2 goals, x 10/20/30 %", "GRAQL", "contrast",
          _MINIGRID_SUBOPTIMAL[1:], strict=True),
    Claim("GRAIL improves F1 by up to about 0.4 over DRACO under noisy demonstrations",
          "Abstract; Introduction; §5.2, Fig. 5", GRAIL, _PANDA_NOISY, (0.02,), 0.3, 0.5,
          "up to about 0.4: the largest gain in [0.3, 0.5]",
          "largest paired F1 gain over DRACO, PandaReach Gaussian/uniform 0.1/0.3 at 2 %", "DRACO", "max"),
    Claim("GRAIL remains competitive with GRAQL under optimal behaviour",
          "Abstract; §5.3, Table 4", GRAIL, _MINIGRID_OPTIMAL, (0.1, 0.2, 0.3), -0.05, math.inf,
          "competitive: gain >= -0.05", "mean paired F1 gain over GRAQL, MiniGrid optimal 2/4/6 goals x 10/20/30 %",
          "GRAQL"),
    Claim("GRAIL matches or only slightly trails DRACO under clean optimal demonstrations",
          "Abstract; Introduction", GRAIL, _PANDA_OPTIMAL, (0.02,), -0.05, math.inf,
          "competitive: gain >= -0.05", "paired F1 gain over DRACO, PandaReach optimal at 2 %", "DRACO"),
    Claim("Every GRAIL variant surpasses DRACO under optimal demonstrations",
          "§5.3, Fig. 5", GRAIL, _PANDA_OPTIMAL, (0.02,), 0.0, math.inf,
          "gain > 0", "paired F1 gain over DRACO, PandaReach optimal at 2 %", "DRACO", strict=True),
)


#: How the paper's vague words are read, and why (shown under the table).
READINGS: tuple[tuple[str, str], ...] = (
    ("near perfect", "F1 >= 0.9; the paper reports 1.00 for every GRAIL variant (Fig. 4) and calls 0.3-0.5 "
     "effectively at chance, and 0.9 leaves room for about one wrong prediction in ten observations"),
    ("competitive, matching or only slightly underperforming", "a mean gain of at least -0.05 F1 over the "
     "baseline; §5.3 says GRAIL has caught up with GRAQL at 20 % observed, where its GAIL and AIRL variants "
     "trail GRAQL by at most 0.05 (Table 4)"),
    ("approximately 0.1-0.3", "the range [0.1, 0.3] as printed"),
    ("up to about 0.4", "the largest gain over the noisy conditions in [0.3, 0.5], the precision with which a "
     "gain is read off the paper's Fig. 5"),
)


@dataclass(frozen=True)
class ClaimResult:
    """One claim measured for one configuration.

    Attributes:
        claim: The claim as the paper makes it, short.
        source: Where the paper says it (section / table).
        configuration: The configuration measured, as the leaderboard labels it (``GAIL-GRAIL``,
            ``GAIL-GRAIL · off_support stay``).
        measured: What was measured, short.
        estimate: The measured quantity (NaN when not measured).
        low, high: Its 95 % interval (NaN when not measured).
        verdict: ``holds``, ``partly``, ``does not hold`` or ``not measured`` (see the module docstring).
    """

    claim: str
    source: str
    configuration: str
    measured: str
    estimate: float
    low: float
    high: float
    verdict: str


Cells = dict[tuple[str, float], OfflineRecord]


def headline_claims(records: Sequence[OfflineRecord], reps: int = 2000, seed: int = 0) -> list[ClaimResult]:
    """Every claim of :data:`CLAIMS` measured for every configuration it concerns, in claim order.

    Per claim: the canonical configuration of each method it names (a row even when never run), then each
    named variant of them that ran on one of its strata, sorted by label. Archived configurations and runs
    off a task's default protocol or parameters are left out.

    Args:
        records: Offline records (:func:`grail_bench.harness.modes.offline.aggregate`).
        reps: Bootstrap replicates.
        seed: Seed of the bootstrap (every row uses it: same records, same table).

    Raises:
        UserError: For ``reps`` below 1.
    """
    if reps < 1:
        raise UserError(f"reps must be positive, got {reps}")
    configs, methods = _paper_cells(records)
    results = []
    for claim in CLAIMS:
        wanted = set(claim.strata)
        variants = sorted(label for label, (method, canonical) in methods.items()
                          if method in claim.subjects and not canonical and wanted & set(configs[label]))
        baseline = configs.get(claim.baseline, {}) if claim.baseline else None
        for label in [*claim.subjects, *variants]:
            results.append(_measure(claim, label, configs.get(label, {}), baseline, reps, seed))
    return results


def claim_tasks() -> set[str]:
    """Every task a claim is measured on: a store holding none of them has no claim to show."""
    return {task for claim in CLAIMS for task in claim.tasks}


def _paper_cells(records: Sequence[OfflineRecord]) -> tuple[dict[str, Cells], dict[str, tuple[str, bool]]]:
    """The non-archived configurations' records under the paper's protocol, task parameters and generated
    demonstrations, by label and
    (task, observed share); and each label's method and whether it is canonical (labelled by the method)."""
    cells: dict[str, Cells] = defaultdict(dict)
    methods: dict[str, tuple[str, bool]] = {}
    tasks = claim_tasks()
    for r in records:
        params = json.dumps(r.task_params, sort_keys=True, default=str)
        if r.task not in tasks or r.protocol != _paper_protocol(r.task, params):
            continue
        config = configuration(r)
        if config.kind == "archived" or config.dataset is not None:  # the paper's demonstrations only
            continue
        cells[config.label].setdefault((r.task, round(float(r.observability), 6)), r)
        methods[config.label] = (config.method, config.canonical)
    return cells, methods


@lru_cache(maxsize=None)
def _paper_protocol(task_id: str, params: str) -> str | None:
    """The task's default protocol label when ``params`` are its default parameters, else None."""
    task = find_task(task_id)
    if task is None or variant(task, json.loads(params)):
        return None
    return task.protocol_label


def _stratum_scores(claim: Claim, cells: Cells, baseline: Cells | None) -> dict[tuple[str, float], np.ndarray]:
    """Per stratum with runs, the per-seed F1 values, or the paired gains over the baseline on the seeds both ran."""
    scores = {}
    for task, level in claim.strata:
        key = (task, round(level, 6))
        mine = cells.get(key)
        if mine is None:
            continue
        values = dict(zip(mine.seeds, mine.f1.values))
        if baseline is not None:
            theirs = baseline.get(key)
            base = dict(zip(theirs.seeds, theirs.f1.values)) if theirs is not None else {}
            values = {s: values[s] - base[s] for s in set(values) & set(base)}
        if values:
            scores[(task, level)] = np.array([values[s] for s in sorted(values)], dtype=float)
    return scores


def _statistic(claim: Claim) -> Any:
    """The claim's statistic over ``{stratum: values (..., seeds)}``: strata means combined as it says."""

    def statistic(scores: Mapping[Hashable, np.ndarray]) -> Any:
        means = {key: np.asarray(v).mean(axis=-1) for key, v in scores.items()}
        if claim.statistic == "max":
            return np.max(np.stack(list(means.values())), axis=0)
        if claim.statistic == "contrast":
            first = [m for (task, _), m in means.items() if task in claim.contrast]
            rest = [m for (task, _), m in means.items() if task not in claim.contrast]
            return np.mean(np.stack(first), axis=0) - np.mean(np.stack(rest), axis=0)
        return np.mean(np.stack(list(means.values())), axis=0)

    return statistic


def verdict(low: float, high: float, claimed_low: float, claimed_high: float, strict: bool = False) -> str:
    """``holds`` when ``[low, high]`` lies inside the claimed range, ``does not hold`` when wholly outside it,
    else ``partly``; ``not measured`` for a NaN interval. ``strict``: ``claimed_low`` itself is outside the range
    (an interval reaching down to it is not inside, one ending at it is wholly outside)."""
    if math.isnan(low) or math.isnan(high):
        return "not measured"
    above = low > claimed_low if strict else low >= claimed_low
    if above and high <= claimed_high:
        return "holds"
    below = high <= claimed_low if strict else high < claimed_low
    if below or low > claimed_high:
        return "does not hold"
    return "partly"


def _measure(claim: Claim, label: str, cells: Cells, baseline: Cells | None, reps: int, seed: int) -> ClaimResult:
    scores = _stratum_scores(claim, cells, baseline)
    needed = len(claim.strata)
    if len(scores) < needed:
        nan = float("nan")
        return ClaimResult(claim.claim, claim.source, label, f"{claim.measured} ({len(scores)} of {needed} run)",
                           nan, nan, nan, "not measured")
    interval = stratified_bootstrap(scores, _statistic(claim), reps=reps, seed=seed)
    return ClaimResult(claim.claim, claim.source, label, claim.measured, interval.point, interval.low,
                       interval.high, verdict(interval.low, interval.high, claim.low, claim.high, claim.strict))


def _number(value: float) -> str:
    return "–" if math.isnan(value) else f"{value + 0.0:.2f}".replace("-0.00", "0.00")


def claims_markdown(results: Sequence[ClaimResult]) -> str:
    """A Markdown section: the rules, then one table row per claim and configuration."""
    readings = {c.claim: c.reading for c in CLAIMS}
    lines = [
        "## The paper's headline claims",
        "",
        "Each claim of the GRAIL paper (AAMAS 2026) measured on our runs, for every canonical configuration it "
        "concerns and every named variant of them (archived configurations left out), under each task's default "
        "observation protocol. A gain over GRAQL or DRACO is the paired per-seed difference with that baseline's "
        "canonical configuration, over the seeds both ran; strata (task, observed share) weigh equally. "
        "Intervals are 95 % stratified bootstrap intervals.",
        "",
        "**Verdicts.** *holds*: the whole interval lies inside the claimed range; *does not hold*: it lies wholly "
        "outside; *partly*: it straddles an end of the range; *not measured*: the runs lack a stratum the claim "
        "needs (for a gain, one the baseline ran too, on a seed both ran).",
        "",
        "**Readings of the paper's vague words:**",
        "",
        *(f"- *{word}*: {reading}." for word, reading in READINGS),
        "",
        "| Claim | Source | Claimed | Configuration | Measured | Estimate [95 % CI] | Verdict |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    previous: ClaimResult | None = None
    for r in results:
        first = previous is None or r.claim != previous.claim
        shown_measured = first or previous is None or r.measured != previous.measured
        previous = r
        cells = [md(r.claim) if first else "", md(r.source) if first else "",
                 md(readings.get(r.claim, "")) if first else "", md(r.configuration),
                 md(r.measured) if shown_measured else "",
                 "–" if math.isnan(r.estimate) else f"{_number(r.estimate)} [{_number(r.low)}, {_number(r.high)}]",
                 f"**{r.verdict}**" if r.verdict == "holds" else r.verdict]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
