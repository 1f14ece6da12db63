"""Open-set recognition: one goal held out of the fit, its observations to be answered "none of these".

Per seed ``s`` the held-out goal is ``goals[s % K]``, so a run over ``K``
seeds holds out each goal in turn. The recognizer is fitted on the training
demonstrations of the other ``K - 1`` goals and scores test observations of
all ``K``. The harness, not the recognizer, decides "none of these", with one
rule for every recognizer:

    answer "none of these" when the best score is below the ``alpha``-quantile
    of the best scores of the training demonstrations' observations (drawn
    under the same protocol and level).

The threshold is therefore calibrated on training demonstrations only (with
``alpha = 0.05``, 5 % of them would be rejected); test observations are never
seen when calibrating. Training demonstrations fit their own goal's policy
better than unseen ones do, so the rule errs towards false alarms; the AUROC
of known versus unknown (observations ranked by their best score) does not
depend on the threshold at all.

Ties. The "none of these" decision depends on the best score alone, so ties
leave it as it is. An observation answered with a known goal, where several
known goals tie at the best score ``W``, predicts each with probability
``1 / |W|``: accuracy is its expectation, F1 that of the expected (fractional)
confusion matrix (:mod:`grail_bench.stats.metrics`). The unknown recall and
false-alarm rate, decided by the threshold only, are unchanged.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Demos, Goal
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
from grail_bench.recognizers.contract import Capabilities
from grail_bench.stats import metrics
from grail_bench.task.observation import ObservationSpec
from grail_bench.task.observation import level_text

#: Share of training observations the calibrated rule would answer "none of these".
ALPHA = 0.05


@dataclass(frozen=True)
class OpenSetRow(Run):
    """Open-set recognition of one recognizer on one task, seed and level: one goal held out of the fit.

    Observations of the held-out goal should be answered "none of these";
    the decision rule was calibrated on the training demonstrations only.
    """

    observability: float
    protocol: str
    held_out: str  # JSON list: the goal the recognizer was not fitted on
    auroc: float  # known versus unknown, ranking observations by their best score
    f1: float  # macro F1 over the known goals and the extra class "none of these"
    accuracy: float
    unknown_recall: float  # share of the held-out goal's observations answered "none of these"
    false_alarm: float  # share of known goals' observations answered "none of these"
    threshold: float  # the calibrated rule's threshold on the best score
    n_observations: int
    fit_seconds_per_goal: float
    config: str
    versions: str
    provenance: str | None = None
    n_ties: int | None = None  # observations whose best known goals tied (None: stored before it was counted)
    ties: str | None = metrics.TIE_RULE  # how ties were broken; None: stored before, towards the lowest index
    task_fingerprint: str | None = None  # the task as run (grail_bench.task.versions); None: stored before
    source: str | None = None  # JSON of the submission the row came from (lab, ...); None: run here


@dataclass(frozen=True, kw_only=True)
class OpenSetRecord(Record):
    """One configuration's open-set runs at one level across seeds."""

    observability: float
    held_out: list[list[float]]
    auroc_mean: float
    auroc_ci95_low: float
    auroc_ci95_high: float
    f1_mean: float
    f1_ci95_low: float
    f1_ci95_high: float
    accuracy_mean: float
    unknown_recall_mean: float
    false_alarm_mean: float


def held_out_goal(goals: Sequence[Goal], seed: int) -> Goal:
    """The goal seed ``seed`` holds out: each goal in turn across seeds.

    Raises:
        UserError: With fewer than 3 goals (one must stay out, two must remain to recognise).
    """
    if len(goals) < 3:
        raise UserError(f"open set holds one goal out and needs at least 3 candidate goals; this task has "
                        f"{len(goals)}")
    return tuple(goals[seed % len(goals)])


def known_scores(recognizer: Capabilities, observations: Sequence[Any], scorer: str | None,
                 goals: Sequence[Goal]) -> np.ndarray:
    """Each observation's scores of the known goals ``(N, K)``."""
    return np.stack([check_scores(recognizer.name, recognizer.score(o, scorer), goals) for o in observations])


def best_scores(recognizer: Capabilities, observations: Sequence[Any], scorer: str | None,
                goals: Sequence[Goal]) -> tuple[np.ndarray, np.ndarray]:
    """The best score of each observation ``(N,)``, and each goal's probability of being predicted ``(N, K)``.

    Goals tied at the best score share the prediction equally (:func:`metrics.prediction`).
    """
    scores = known_scores(recognizer, observations, scorer, goals)
    return scores.max(axis=1), metrics.prediction(scores)


def calibrate(recognizer: Capabilities, train: Demos, level: float, observation: ObservationSpec,
              rng: np.random.Generator, scorer: str | None) -> np.ndarray:
    """The best scores of training observations, which the rule's threshold is a quantile of (:func:`threshold_of`).

    Args:
        recognizer: Fitted on ``train``.
        train: The training demonstrations of the known goals, the only data
            the rule sees.
        level: Observability level; each training demonstration is observed
            as a test one would be, under the run's protocol and rounding.
        rng: The calibration's own random stream.
    """
    observations = [observation.observe(traj, level, rng) for trajs in train.values() for traj in trajs]
    best, _ = best_scores(recognizer, observations, scorer, list(train))
    return best


def threshold_of(calibration: np.ndarray, alpha: float = ALPHA) -> float:
    """The rule's threshold: the ``alpha``-quantile of the training observations' best scores (:func:`calibrate`)."""
    return float(np.quantile(calibration, alpha))


def open_set_metrics(best: np.ndarray, predicted: np.ndarray, labels: np.ndarray, threshold: float,
                     n_known: int) -> dict[str, float]:
    """Metrics with the extra class ``n_known`` ("none of these") that the held-out goal's observations carry.

    Args:
        best: Best score of each observation.
        predicted: Among the known goals, each observation's prediction distribution ``(N, n_known)``
            (tied goals sharing it, :func:`best_scores`), or the index of its best goal ``(N,)``.
        labels: True class: a known goal's index, or ``n_known``.
        threshold: Below it, the answer is "none of these" (whatever the ties).
    """
    from sklearn.metrics import roc_auc_score  # imported here: scikit-learn brings torch with it

    unknown = labels == n_known
    rejected = best < threshold
    known = np.hstack([metrics.as_prediction(predicted, n_known), np.zeros((len(best), 1))])
    answer = np.where(rejected[:, None], np.eye(n_known + 1)[n_known], known)  # over the known goals and "none"
    m = metrics.classification_of(metrics.expected_confusion(labels, answer, n_known + 1))
    return {
        "auroc": float(roc_auc_score(unknown, -best)),
        "f1": m["f1"], "accuracy": m["accuracy"],
        "unknown_recall": float(np.mean(rejected[unknown])),
        "false_alarm": float(np.mean(rejected[~unknown])),
    }


def unit_metrics(scores: np.ndarray, labels: np.ndarray, calibration: np.ndarray) -> dict[str, Any]:
    """The metrics of one row from its per-instance outputs.

    Args:
        scores: Each observation's scores of the known goals ``(N, K)``.
        labels: True class: a known goal's index, or ``K`` for the held-out goal.
        calibration: The training observations' best scores (:func:`calibrate`), which set the threshold.

    Returns:
        The :class:`OpenSetRow` fields they determine: every metric, the threshold and the counts.
    """
    scores = np.asarray(scores, dtype=float)
    threshold = threshold_of(calibration)
    predicted = metrics.prediction(scores)
    return dict(threshold=threshold, n_observations=len(scores), n_ties=metrics.n_tied(predicted),
                **open_set_metrics(scores.max(axis=1), predicted, np.asarray(labels), threshold, scores.shape[1]))


def run(job: SeedRun) -> tuple[list[OpenSetRow], Fitted]:
    """Hold out seed ``seed``'s goal, fit on the others, calibrate, and score test observations of all goals.

    Returns:
        One row per level and scorer, and the fitted recognizer.
    """
    task, planned, spec, seed = job.task, job.planned, job.observation, job.seed
    hidden = held_out_goal(task.goals, seed)
    known = [g for g in task.goals if g != hidden]
    train, test = task.split(job.demos)
    known_train = {g: train[g] for g in known}
    fitted = fit_recognizer(task, planned, seed, known_train, test)
    labelled = [(known.index(g) if g != hidden else len(known), traj) for g in task.goals for traj in test[g]]
    labels = np.array([y for y, _ in labelled])
    rows = []
    for level in spec.levels:
        rng = spec.rng(seed, level, "open-set")
        observations = [spec.observe(traj, level, rng) for _, traj in labelled]
        for scorer in planned.scorers:
            calibration_rng = spec.rng(seed, level, "open-set-calibration")  # the same draws per scorer
            calibration = calibrate(fitted.recognizer, known_train, level, spec, calibration_rng, scorer.arg)
            scores = known_scores(fitted.recognizer, observations, scorer.arg, known)
            rows.append(OpenSetRow(
                task=task.id, recognizer=planned.name, scorer=scorer.label, config_hash=planned.config_hash, seed=seed,
                observability=level, protocol=spec.label, held_out=json.dumps(list(hidden)),
                fit_seconds_per_goal=fitted.seconds_per_goal, config=planned.config, versions=job.versions,
                **unit_metrics(scores, labels, calibration),
            ))
            if job.outputs is not None:
                job.outputs.append(Outputs(rows[-1], {"y_true": labels, "scores": scores,
                                                      "calibration": calibration}))
    return rows, fitted


def aggregate(rows: Iterable[OpenSetRow]) -> list[OpenSetRecord]:
    """Across-seed open-set records, one per (task, recognizer, scorer, configuration, protocol, level)."""
    return [OpenSetRecord(held_out=[json.loads(r.held_out) for r in group],
                          **record_fields(group, ("auroc", "f1"), ("accuracy", "unknown_recall", "false_alarm")))
            for group in cells(rows)]


COLUMNS = LEAD + (Column("obs", lambda r: level_text(r.observability), lambda r: r.observability),) + WHO + (
    Column("AUROC", interval("auroc"), lambda r: r.auroc_mean),
    Column("F1 (+ none)", interval("f1"), lambda r: r.f1_mean),
    Column("accuracy", lambda r: f"{r.accuracy_mean:.2f}", lambda r: r.accuracy_mean),
    Column("unknown found", lambda r: f"{r.unknown_recall_mean:.0%}", lambda r: r.unknown_recall_mean),
    Column("false alarms", lambda r: f"{r.false_alarm_mean:.0%}", lambda r: r.false_alarm_mean),
)

MODE = Mode(
    name="open-set", row=OpenSetRow, table="open_set",
    key=("task", "recognizer", "scorer", "config_hash", "seed", "observability", "protocol"),
    run=run, aggregate=aggregate, columns=COLUMNS,
    title="open set (one goal held out per seed)",
    intro=("Mean over seeds; " + INTERVAL_NOTE + " AUROC: known against held-out goal, observations ranked by "
           "their best score. F1 over the known goals plus 'none of these', answered when the best score "
           "is below the 5 % quantile of the training demonstrations' best scores."),
    min_goals=3, held_out=lambda n_goals: 1,
)
