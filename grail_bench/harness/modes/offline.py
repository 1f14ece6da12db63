"""Offline mode, the paper's protocol: each test demonstration observed once per level, its goal predicted.

Per seed: fit on the training demonstrations, observe every test
demonstration at each level (protocol and rounding of the run's
:class:`~grail_bench.task.observation.ObservationSpec`), score with each
scorer, and store accuracy, macro precision, recall and F1, ties, ranking
metrics and timings (:class:`ResultRow`). Across seeds: mean, std, a 95 %
percentile bootstrap interval of the mean (inside [0, 1]; :func:`grail_bench.stats.metrics.summarize`) and the
IQM (:class:`OfflineRecord`).

Goals tied at the best score share the prediction (uniform tie-breaking, in
expectation; see :mod:`grail_bench.stats.metrics`): accuracy is its
expectation, precision, recall and F1 those of the expected (fractional)
confusion matrix, which is stored as it is. Without ties they are the plain
argmax's. ``n_ties`` counts the observations whose best score tied.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from grail_bench.harness.modes.base import (LEAD, WHO, Column, Mode, Outputs, Record, Run, SeedRun, cells,
                                           record_fields)
from grail_bench.harness.planning import Fitted, check_scores, fit_recognizer
from grail_bench.stats import metrics
from grail_bench.task.observation import DATASET, level_text

#: A goal is in the set-valued answer when its score is within this share of the scores' range of the best.
SET_TOLERANCE = 0.1


@dataclass(frozen=True)
class ResultRow(Run):
    """Metrics of one recognizer on one task, seed and observability level."""

    observability: float
    protocol: str
    accuracy: float
    precision: float
    recall: float
    f1: float
    n_observations: int
    n_ties: int
    fit_seconds_per_goal: float
    score_us_per_observation: float
    config: str
    versions: str
    brier: float | None = None
    nll: float | None = None
    provenance: str | None = None  # JSON of grail_bench.core.provenance.stamp(); None for rows stored before it
    top2: float | None = None  # share of observations whose true goal ranks in the top 2 (None: stored before)
    mean_rank: float | None = None  # mean rank of the true goal, 1 = best (None: stored before)
    confusion: str | None = None  # JSON K x K expected counts (fractional with ties): row the true goal, column
    # the predicted (None: stored before)
    reliability: str | None = None  # JSON reliability bins of the posterior (posterior scorers only)
    set_precision: float | None = None  # of the set of goals within SET_TOLERANCE of the best: 1/|set| if it
    set_recall: float | None = None  # holds the true goal, else 0; whether it holds it; and its size,
    set_spread: float | None = None  # each a mean over observations (None: stored before)
    ties: str | None = metrics.TIE_RULE  # how ties were broken; None: stored before, towards the lowest index
    task_fingerprint: str | None = None  # the task as run (grail_bench.task.versions); None: stored before
    source: str | None = None  # JSON of the submission the row came from (lab, ...); None: run here


@dataclass(frozen=True, kw_only=True)
class OfflineRecord(Record):
    """One configuration at one level across seeds (the ``--json`` format of offline runs)."""

    observability: float
    f1: metrics.Summary  # macro F1 across seeds; written flat as f1_mean, f1_std, f1_ci95_low, ... (Record.to_dict)
    accuracy_mean: float
    precision_mean: float
    recall_mean: float
    score_us_per_observation: float
    tie_rate: float
    brier_mean: float | None = None
    nll_mean: float | None = None
    top2_mean: float | None = None
    mean_rank_mean: float | None = None
    confusion: list[list[float]] | None = None  # summed over seeds, ints when whole (None when a seed's was not stored)
    reliability: list[list[float]] | None = None  # summed over seeds (posterior scorers only)
    ece: float | None = None  # expected calibration error of the summed reliability bins
    set_precision_mean: float | None = None
    set_recall_mean: float | None = None
    set_spread_mean: float | None = None


def run(job: SeedRun) -> tuple[list[ResultRow], Fitted]:
    """Fit one recognizer on one seed's training demos, then score every level with every scorer.

    The recognizer never sees the true goal: it gets the training demos per
    goal, an env factory, and observations stripped of infos, scored in a
    seeded random order across goals. Each (seed, level, protocol) cell draws
    its observations from its own random stream, so the rows do not depend on
    which other levels run in the same call. With a scorer that yields a
    posterior (``loglik``), its Brier score and NLL are recorded too. Goals
    tied at the best score share the prediction (see the module docstring).
    Under the ``dataset`` protocol the observations are the task's own (its
    domain's ``dataset_observations``), scored whole, and the recognizer is
    fitted on no demonstration (a problem set holds none).

    Returns:
        The rows (one per level and scorer) and the fitted recognizer.
    """
    task, planned, spec = job.task, job.planned, job.observation
    if spec.protocol == DATASET:  # the task's own observations; the dataset holds no demonstration to fit on
        fitted = fit_recognizer(task, planned, job.seed, {g: [] for g in task.goals}, {})
        labelled = task.spec.dataset_observations(task)
    else:
        train, test = task.split(job.demos)
        fitted = fit_recognizer(task, planned, job.seed, train, test)
        labelled = [(i, traj) for i, goal in enumerate(task.goals) for traj in test[goal]]
    rows = []
    for level in spec.levels:
        rng = spec.rng(job.seed, level)
        order = rng.permutation(len(labelled))
        observations = [(labelled[j][0], labelled[j][1] if spec.protocol == DATASET else
                         spec.observe(labelled[j][1], level, rng)) for j in order]
        for scorer in planned.scorers:
            y_true, scored, lengths, elapsed_ns = [], [], [], 0
            for label, observed in observations:
                t0 = time.perf_counter_ns()
                scores = fitted.recognizer.score(observed, scorer.arg)
                elapsed_ns += time.perf_counter_ns() - t0
                scored.append(check_scores(planned.name, scores, task.goals))
                y_true.append(label)
                lengths.append(len(observed.acts))
            rows.append(ResultRow(
                task=task.id, recognizer=planned.name, scorer=scorer.label, config_hash=planned.config_hash,
                seed=job.seed, observability=level, protocol=spec.label,
                fit_seconds_per_goal=fitted.seconds_per_goal, score_us_per_observation=elapsed_ns / 1e3 / len(y_true),
                config=planned.config, versions=job.versions,
                **unit_metrics(y_true, scored, lengths, scorer.posterior, len(task.goals)),
            ))
            if job.outputs is not None:
                job.outputs.append(Outputs(rows[-1], {"y_true": y_true, "lengths": lengths, "scores": scored},
                                           scorer.posterior))
    return rows, fitted


def unit_metrics(y_true: list[int], scored: list[np.ndarray], lengths: list[int], posterior: bool,
                 n_goals: int) -> dict[str, Any]:
    """The metrics of one row (one unit, level and scorer) from its per-observation outputs.

    Args:
        y_true: Each observation's true goal (index into the task's goals).
        scored: Each observation's scores, one per goal (log-likelihoods for a posterior scorer).
        lengths: Each observation's number of observed steps.
        posterior: Whether the scores are log-likelihoods (Brier, NLL and reliability are recorded too).
        n_goals: The task's candidate goals.

    Returns:
        The :class:`ResultRow` fields they determine: every metric but the timings.
    """
    predicted, brier, nll, ranks, top2, confidence, in_set, set_sizes = [], [], [], [], [], [], [], []
    for label, values, length in zip(y_true, scored, lengths):
        predicted.append(metrics.prediction(values))
        rank, in_top2 = metrics.ranking(values, label)
        ranks.append(rank)
        top2.append(in_top2)
        chosen = metrics.goal_set(values, SET_TOLERANCE)
        in_set.append(label in chosen)
        set_sizes.append(len(chosen))
        if posterior:
            b, n, c = metrics.calibration(values, length, label)
            brier.append(b)
            nll.append(n)
            confidence.append(c)
    confusion = metrics.expected_confusion(y_true, np.array(predicted), n_goals)
    hit = [p[label] for p, label in zip(predicted, y_true)]  # each prediction's chance of being right
    return dict(
        n_observations=len(y_true), n_ties=metrics.n_tied(np.array(predicted)),
        brier=float(np.mean(brier)) if brier else None, nll=float(np.mean(nll)) if nll else None,
        top2=float(np.mean(top2)), mean_rank=float(np.mean(ranks)),
        confusion=json.dumps(metrics.plain_matrix(confusion)),
        reliability=json.dumps(metrics.reliability_bins(confidence, hit)) if posterior else None,
        set_precision=float(np.mean([hit / size for hit, size in zip(in_set, set_sizes)])),
        set_recall=float(np.mean(in_set)), set_spread=float(np.mean(set_sizes)),
        **metrics.classification_of(confusion),
    )


def _mean_or_none(values: list[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    return float(np.mean(present)) if present else None


def _summed(field: str, group: list[ResultRow], kind: type = float) -> list[list[Any]] | None:
    """A JSON matrix field summed over the seeds' rows (None when a row lacks it).

    ``kind=int`` (counts): ints when every sum is a whole number, floats where
    tied predictions left fractional counts.
    """
    values = [getattr(r, field) for r in group]
    if any(v is None for v in values):
        return None
    total = np.sum([np.asarray(json.loads(v), dtype=float) for v in values], axis=0)
    return metrics.plain_matrix(total) if kind is int else total.astype(kind).tolist()


def _calibration(group: list[ResultRow]) -> dict[str, Any]:
    bins = _summed("reliability", group)
    return {"reliability": bins, "ece": metrics.expected_calibration_error(bins) if bins else None}


def aggregate(rows: Iterable[ResultRow]) -> list[OfflineRecord]:
    """Across-seed records, one per configuration and level, sorted by task, recognizer, scorer, protocol, level."""
    records = []
    groups = cells(rows)
    f1s = metrics.summarize_many([[r.f1 for r in group] for group in groups])
    for group, f1 in zip(groups, f1s):
        n_obs = sum(r.n_observations for r in group)
        records.append(OfflineRecord(
            **record_fields(group, (), ("accuracy", "precision", "recall")),
            f1=f1,
            score_us_per_observation=float(np.mean([r.score_us_per_observation for r in group])),
            tie_rate=sum(r.n_ties for r in group) / n_obs if n_obs else 0.0,
            brier_mean=_mean_or_none([r.brier for r in group]), nll_mean=_mean_or_none([r.nll for r in group]),
            top2_mean=_mean_or_none([r.top2 for r in group]),
            mean_rank_mean=_mean_or_none([r.mean_rank for r in group]),
            confusion=_summed("confusion", group, int),
            **_calibration(group),
            set_precision_mean=_mean_or_none([r.set_precision for r in group]),
            set_recall_mean=_mean_or_none([r.set_recall for r in group]),
            set_spread_mean=_mean_or_none([r.set_spread for r in group]),
        ))
    return sorted(records, key=lambda r: (r.task, r.recognizer, r.scorer, r.protocol, r.observability))


COLUMNS = LEAD + (Column("obs", lambda r: level_text(r.observability), lambda r: r.observability),) + WHO + (
    Column("F1", lambda r: f"{r.f1.mean:.2f} ± {r.f1.std:.2f}", lambda r: r.f1.mean),
    Column("accuracy", lambda r: f"{r.accuracy_mean:.2f}", lambda r: r.accuracy_mean),
    Column("fit s/goal", lambda r: f"{r.fit_seconds_per_goal:.2f}", lambda r: r.fit_seconds_per_goal),
    Column("µs / observation", lambda r: f"{r.score_us_per_observation:.0f}", lambda r: r.score_us_per_observation),
)

MODE = Mode(
    name="offline", row=ResultRow, table="results",
    key=("task", "recognizer", "scorer", "config_hash", "seed", "observability", "protocol"),
    run=run, aggregate=aggregate, columns=COLUMNS,
    title="goal recognition (the paper's protocol)",
    intro="Mean ± std over seeds of macro F1; each test demonstration observed once per level.",
)
