"""Zero-shot goals: some candidate goals have no training demonstrations at all.

Per seed, a third of the goals (at least one: ``K // 3``) are held out of the
fit, drawn from the seed's own stream, so that across seeds different goals
are held out. The recognizer is fitted on the training demonstrations of the
other goals only, then told the full candidate set (``set_goals``) and asked
to recognise test observations of every goal, exactly as offline. Only a
recognizer that can score goals it was never fitted on (a goal-conditioned
one) can run; per-goal methods are refused before any work.

Stored per level and scorer: macro F1 and accuracy over all ``K`` goals, and
separately the mean per-class F1 and the accuracy on the held-out goals and on
the trained ones. Chance is ``1 / K``. And the three times gr_libs reports per
run: learning (``fit_seconds_per_goal``, per goal fitted), adaptation
(``adapt_seconds_per_goal``: what ``set_goals`` took, per held-out goal, the
goals it is new to; gr_libs' ``goals_adaptation_phase``) and inference
(``score_us_per_observation``, as offline). Rows stored before the last two were
recorded have them NULL.

Goals tied at the best score share the prediction, as offline: accuracies are
expectations under uniform tie-breaking, F1 that of the expected (fractional)
confusion matrix (:mod:`grail_bench.stats.metrics`).
"""

from __future__ import annotations

import json
import time
import zlib
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from grail_bench.core.trajectory import Goal
from grail_bench.harness.modes.base import (
    INTERVAL_NOTE,
    LEAD,
    WHO,
    Column,
    Mode,
    Outputs,
    Record,
    Run,
    SeedRun,
    cells,
    interval,
    record_fields,
)
from grail_bench.harness.planning import Fitted, check_scores, fit_recognizer
from grail_bench.stats import metrics
from grail_bench.task.observation import level_text


@dataclass(frozen=True)
class ZeroShotRow(Run):
    """Recognition of one recognizer on one task, seed and level with some goals never fitted."""

    observability: float
    protocol: str
    held_out: str  # JSON list of the goals without training demonstrations
    n_goals: int
    f1: float  # macro F1 over all goals
    accuracy: float
    f1_held_out: float  # mean per-class F1 of the held-out goals
    f1_trained: float  # mean per-class F1 of the goals fitted on
    accuracy_held_out: float  # share of the held-out goals' observations recognised
    accuracy_trained: float
    n_observations: int
    fit_seconds_per_goal: float
    config: str
    versions: str
    provenance: str | None = None
    n_ties: int | None = None  # observations whose best score tied (None: stored before it was counted)
    ties: str | None = metrics.TIE_RULE  # how ties were broken; None: stored before, towards the lowest index
    task_fingerprint: str | None = None  # the task as run (grail_bench.task.versions); None: stored before
    source: str | None = None  # JSON of the submission the row came from (lab, ...); None: run here
    adapt_seconds_per_goal: float | None = None  # set_goals' seconds per held-out goal (None: stored before)
    score_us_per_observation: float | None = None  # (None: stored before it was timed)


@dataclass(frozen=True, kw_only=True)
class ZeroShotRecord(Record):
    """One configuration's zero-shot runs at one level across seeds."""

    observability: float
    n_goals: int
    held_out: list[list[list[float]]]
    f1_mean: float
    f1_ci95_low: float
    f1_ci95_high: float
    f1_held_out_mean: float
    f1_held_out_ci95_low: float
    f1_held_out_ci95_high: float
    f1_trained_mean: float
    accuracy_mean: float
    accuracy_held_out_mean: float
    accuracy_trained_mean: float
    adapt_seconds_per_goal: float | None = None  # mean over the seeds that recorded it (None: none did)
    score_us_per_observation: float | None = None


def n_held_out(n_goals: int) -> int:
    """Goals held out of the fit: a third, at least one."""
    return max(1, n_goals // 3)


def held_out_goals(goals: Sequence[Goal], seed: int) -> list[Goal]:
    """The goals seed ``seed`` holds out (its own stream; the same whatever order the goals are listed in)."""
    ordered = sorted(tuple(g) for g in goals)
    rng = np.random.default_rng([int(seed), zlib.crc32(b"zero-shot")])
    return [ordered[i] for i in sorted(rng.choice(len(ordered), size=n_held_out(len(ordered)), replace=False))]


def run(job: SeedRun) -> tuple[list[ZeroShotRow], Fitted]:
    """Fit on the goals not held out, give the recognizer every goal, and recognise test observations of all.

    Returns:
        One row per level and scorer, and the fitted recognizer.
    """
    task, planned, spec, seed = job.task, job.planned, job.observation, job.seed
    hidden = held_out_goals(task.goals, seed)
    train, test = task.split(job.demos)
    known = [g for g in task.goals if g not in hidden]
    fitted = fit_recognizer(task, planned, seed, {g: train[g] for g in known}, {g: test[g] for g in known})
    start = time.perf_counter()
    fitted.recognizer.set_goals(task.goals)
    adapt_seconds = time.perf_counter() - start
    held_out_index = [i for i, g in enumerate(task.goals) if g in hidden]
    labelled = [(i, traj) for i, goal in enumerate(task.goals) for traj in test[goal]]
    rows = []
    for level in spec.levels:
        rng = spec.rng(seed, level, "zero-shot")
        order = rng.permutation(len(labelled))
        observations = [(labelled[j][0], spec.observe(labelled[j][1], level, rng)) for j in order]
        y_true = np.array([label for label, _ in observations])
        for scorer in planned.scorers:
            scored, elapsed_ns = [], 0
            for _, observed in observations:
                t0 = time.perf_counter_ns()
                scores = fitted.recognizer.score(observed, scorer.arg)
                elapsed_ns += time.perf_counter_ns() - t0
                scored.append(check_scores(planned.name, scores, task.goals))
            rows.append(ZeroShotRow(
                task=task.id, recognizer=planned.name, scorer=scorer.label, config_hash=planned.config_hash, seed=seed,
                observability=level, protocol=spec.label, held_out=json.dumps([list(g) for g in hidden]),
                fit_seconds_per_goal=fitted.seconds_per_goal, config=planned.config, versions=job.versions,
                adapt_seconds_per_goal=adapt_seconds / len(hidden),
                score_us_per_observation=elapsed_ns / 1e3 / len(observations),
                **unit_metrics(y_true, np.array(scored), held_out_index),
            ))
            if job.outputs is not None:
                job.outputs.append(Outputs(rows[-1], {"y_true": y_true, "scores": np.array(scored),
                                                      "held_out": held_out_index}))
    return rows, fitted


def unit_metrics(y_true: np.ndarray, scores: np.ndarray, held_out: Sequence[int]) -> dict[str, Any]:
    """The metrics of one row from its per-instance outputs.

    Args:
        y_true: Each observation's true goal (index into the task's goals).
        scores: Each observation's scores of every goal ``(N, K)``.
        held_out: The indices of the goals held out of the fit.

    Returns:
        The :class:`ZeroShotRow` fields they determine: every metric and the counts.
    """
    y_true, scores = np.asarray(y_true, dtype=np.int64), np.asarray(scores, dtype=float)
    n_goals = scores.shape[1]
    is_hidden = np.isin(np.arange(n_goals), np.asarray(held_out, dtype=np.int64))
    predicted = metrics.prediction(scores)
    confusion = metrics.expected_confusion(y_true, predicted, n_goals)
    per_class = metrics.per_class_f1_of(confusion)
    hit = predicted[np.arange(len(y_true)), y_true]  # each prediction's chance of being right
    on_hidden = is_hidden[y_true]
    return dict(n_goals=n_goals, f1=float(per_class.mean()), accuracy=float(np.mean(hit)),
                f1_held_out=float(per_class[is_hidden].mean()), f1_trained=float(per_class[~is_hidden].mean()),
                accuracy_held_out=float(np.mean(hit[on_hidden])), accuracy_trained=float(np.mean(hit[~on_hidden])),
                n_observations=len(y_true), n_ties=metrics.n_tied(predicted))


def aggregate(rows: Iterable[ZeroShotRow]) -> list[ZeroShotRecord]:
    """Across-seed zero-shot records, one per (task, recognizer, scorer, configuration, protocol, level)."""
    means = ("f1_trained", "accuracy", "accuracy_held_out", "accuracy_trained")
    return [ZeroShotRecord(n_goals=group[0].n_goals, held_out=[json.loads(r.held_out) for r in group],
                           adapt_seconds_per_goal=_recorded_mean(group, "adapt_seconds_per_goal"),
                           score_us_per_observation=_recorded_mean(group, "score_us_per_observation"),
                           **record_fields(group, ("f1", "f1_held_out"), means))
            for group in cells(rows)]


def _recorded_mean(group: Sequence[ZeroShotRow], key: str) -> float | None:
    """The mean of a row field over the rows that recorded it (None when none did)."""
    values = [getattr(r, key) for r in group if getattr(r, key) is not None]
    return float(np.mean(values)) if values else None


def _time_text(value: float | None, fmt: str) -> str:
    return "-" if value is None else fmt.format(value)


COLUMNS = LEAD + (Column("obs", lambda r: level_text(r.observability), lambda r: r.observability),) + WHO + (
    Column("F1 (all goals)", interval("f1"), lambda r: r.f1_mean),
    Column("F1 held-out goals", interval("f1_held_out"), lambda r: r.f1_held_out_mean),
    Column("F1 trained goals", lambda r: f"{r.f1_trained_mean:.2f}", lambda r: r.f1_trained_mean),
    Column("accuracy held-out", lambda r: f"{r.accuracy_held_out_mean:.2f}", lambda r: r.accuracy_held_out_mean),
    Column("chance", lambda r: f"{1 / r.n_goals:.2f}", lambda r: 1 / r.n_goals),
    Column("fit s/goal", lambda r: f"{r.fit_seconds_per_goal:.2f}", lambda r: r.fit_seconds_per_goal),
    Column("adapt s/new goal", lambda r: _time_text(r.adapt_seconds_per_goal, "{:.2g}"),
           lambda r: r.adapt_seconds_per_goal),
    Column("µs / observation", lambda r: _time_text(r.score_us_per_observation, "{:.0f}"),
           lambda r: r.score_us_per_observation),
)

MODE = Mode(
    name="zero-shot", row=ZeroShotRow, table="zero_shot",
    key=("task", "recognizer", "scorer", "config_hash", "seed", "observability", "protocol"),
    run=run, aggregate=aggregate, columns=COLUMNS,
    title="zero-shot goals (a third of the goals never fitted)",
    intro=("Mean over seeds; " + INTERVAL_NOTE + " Per seed, a third of the goals have no training demonstrations; "
           "the recognizer is fitted on the others and then scores all of them. F1 per class, averaged over "
           "the held-out goals and over the trained ones; chance is 1/K. Times as gr_libs reports them: learning "
           "(fit s/goal, per goal fitted), adaptation (what making the recognizer score the new goals took, per "
           "held-out goal; - for runs stored before it was timed) and inference (per observation)."),
    min_goals=3, held_out=n_held_out, scores_unfitted=True,
)
