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
"""

from __future__ import annotations

import json
from typing import Any, Iterable, Sequence

import numpy as np
from sklearn.metrics import roc_auc_score

from grail_bench.errors import UserError
from grail_bench.evaluation import metrics
from grail_bench.evaluation.protocol import ProtocolLike, cell_rng, get_protocol, observe, protocol_label
from grail_bench.evaluation.runner import Planned, check_scores, fit_recognizer
from grail_bench.recognizers.base import FitReport
from grail_bench.store import OpenSetRow
from grail_bench.task import GRTask
from grail_bench.trajectory import Demos, Goal

#: Share of training observations the calibrated rule would answer "none of these".
ALPHA = 0.05


def held_out_goal(goals: Sequence[Goal], seed: int) -> Goal:
    """The goal seed ``seed`` holds out: each goal in turn across seeds.

    Raises:
        UserError: With fewer than 3 goals (one must stay out, two must remain to recognise).
    """
    if len(goals) < 3:
        raise UserError(f"open set holds one goal out and needs at least 3 candidate goals; this task has "
                        f"{len(goals)}")
    return tuple(goals[seed % len(goals)])


def best_scores(recognizer: Any, observations: Sequence[Any], scorer: str | None, goals: Sequence[Goal],
                name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(best score, index of the best goal)`` of each observation, ties to the lowest index."""
    scores = np.stack([check_scores(name, recognizer.score(o, scorer), goals) for o in observations])
    return scores.max(axis=1), scores.argmax(axis=1)


def calibrate(recognizer: Any, train: Demos, level: float, protocol: ProtocolLike, rng: np.random.Generator,
              scorer: str | None, name: str, rounding: str = "ceil", alpha: float = ALPHA) -> float:
    """The rule's threshold: the ``alpha``-quantile of the best scores of training observations.

    Args:
        recognizer: Fitted on ``train``.
        train: The training demonstrations of the known goals, the only data
            the rule sees.
        level: Observability level; each training demonstration is observed
            as a test one would be, under ``protocol`` and ``rounding``.
        rng: The calibration's own random stream.
    """
    observations = [observe(traj, level, protocol, rng, rounding) for trajs in train.values() for traj in trajs]
    best, _ = best_scores(recognizer, observations, scorer, list(train), name)
    return float(np.quantile(best, alpha))


def open_set_metrics(best: np.ndarray, argmax: np.ndarray, labels: np.ndarray, threshold: float,
                     n_known: int) -> dict[str, float]:
    """Metrics with the extra class ``n_known`` ("none of these") that the held-out goal's observations carry.

    Args:
        best: Best score of each observation.
        argmax: Index (among the known goals) of its best score.
        labels: True class: a known goal's index, or ``n_known``.
        threshold: Below it, the answer is "none of these".
    """
    unknown = labels == n_known
    predicted = np.where(best < threshold, n_known, argmax)
    m = metrics.classification(labels.tolist(), predicted.tolist(), n_known + 1)
    return {
        "auroc": float(roc_auc_score(unknown, -best)),
        "f1": m["f1"], "accuracy": m["accuracy"],
        "unknown_recall": float(np.mean(predicted[unknown] == n_known)),
        "false_alarm": float(np.mean(predicted[~unknown] == n_known)),
    }


def run_open_set_seed(task: GRTask, planned: Planned, seed: int, levels: Sequence[float], protocol: str,
                      versions: str, demos: Demos | None = None,
                      rounding: str = "ceil") -> tuple[list[OpenSetRow], FitReport | None]:
    """Hold out seed ``seed``'s goal, fit on the others, calibrate, and score test observations of all goals.

    Returns:
        One row per level and scorer, and the recognizer's fit report.
    """
    chosen = get_protocol(protocol)
    label = protocol_label(chosen.name, rounding)
    name = planned.spec.name
    hidden = held_out_goal(task.goals, seed)
    known = [g for g in task.goals if g != hidden]
    train, test = task.split(demos if demos is not None else task.generate_demos(seed))
    known_train = {g: train[g] for g in known}
    recognizer, report, fit_per_goal = fit_recognizer(task, planned, seed, known_train)
    labelled = [(known.index(g) if g != hidden else len(known), traj) for g in task.goals for traj in test[g]]
    labels = np.array([y for y, _ in labelled])
    rows = []
    for level in levels:
        rng = cell_rng(seed, level, f"open-set:{label}")
        observations = [observe(traj, level, chosen, rng, rounding) for _, traj in labelled]
        for scorer, score_arg in zip(planned.scorers, planned.score_args):
            calibration_rng = cell_rng(seed, level, f"open-set-calibration:{label}")  # the same draws per scorer
            threshold = calibrate(recognizer, known_train, level, chosen, calibration_rng, score_arg, name, rounding)
            best, argmax = best_scores(recognizer, observations, score_arg, known, name)
            rows.append(OpenSetRow(
                task=task.id, recognizer=name, scorer=scorer, config_hash=planned.config_hash, seed=seed,
                observability=level, protocol=label, held_out=json.dumps(list(hidden)), threshold=threshold,
                n_observations=len(observations), fit_seconds_per_goal=fit_per_goal, config=planned.config,
                versions=versions, **open_set_metrics(best, argmax, labels, threshold, len(known)),
            ))
    return rows, report


def aggregate_open_set(rows: Iterable[OpenSetRow]) -> list[dict[str, Any]]:
    """Across-seed open-set records, one per (task, recognizer, scorer, configuration, protocol, level)."""
    groups: dict[tuple, list[OpenSetRow]] = {}
    for r in rows:
        groups.setdefault((r.task, r.recognizer, r.scorer, r.config_hash, r.protocol, r.observability), []).append(r)
    records = []
    for (task, rec, scorer, chash, protocol, level), group in sorted(groups.items()):
        group.sort(key=lambda r: r.seed)
        record: dict[str, Any] = {"task": task, "recognizer": rec, "scorer": scorer, "protocol": protocol,
                                  "observability": level, "config_hash": chash, "n_seeds": len(group),
                                  "seeds": [r.seed for r in group],
                                  "held_out": [json.loads(r.held_out) for r in group]}
        for key in ("auroc", "f1"):
            record |= metrics.summary_fields(key, [getattr(r, key) for r in group])
        for key in ("accuracy", "unknown_recall", "false_alarm"):
            record[f"{key}_mean"] = float(np.mean([getattr(r, key) for r in group]))
        record["fit_seconds_per_goal"] = float(np.mean([r.fit_seconds_per_goal for r in group]))
        records.append(record)
    return records
