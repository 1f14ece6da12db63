"""Online recognition: every prefix of a test observation scored, and when the prediction settles.

An online observer sees the steps of the protocol's full observation (the path
up to the goal for ``subset`` and ``prefix``, the padded episode for the
``horizon-*`` protocols) one at a time. After each step ``k = 1..T`` the
recognizer's prediction is recorded; per trajectory that gives

* the **convergence point**: the observed fraction ``k* / T`` from which every
  later prediction is correct (1.0, flagged as *never*, when the last one is
  wrong);
* the **step accuracy**: the share of the ``T`` predictions that are correct;

and over the test set, the **F1 curve**: macro F1 when every trajectory is
observed up to ``k = n_observed(p, T)`` steps, as the offline ``prefix``
protocol observes it at level ``p``. Its area over ``p`` in (0, 1] is exact:
the curve is a step function with a breakpoint at every ``j / T``.
"""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from grail_bench.evaluation import metrics
from grail_bench.evaluation.protocol import cell_rng, get_protocol, observe, parse_label, protocol_label
from grail_bench.evaluation.runner import Planned, _task_params, check_scores, fit_recognizer
from grail_bench.recognizers.base import FitReport, RecognizerError
from grail_bench.store import OnlineRow
from grail_bench.task import GRTask
from grail_bench.trajectory import Demos, Goal

if TYPE_CHECKING:
    from imitation.data.types import Trajectory

#: Observed fractions the stored curves are sampled at.
GRID = tuple(round(0.05 * i, 2) for i in range(1, 21))
#: For each built-in protocol, the offline protocol whose observation at level ``p`` is the online prefix at ``p``.
PREFIX_OF = {"subset": "prefix", "prefix": "prefix", "horizon-subset": "horizon-prefix",
             "horizon-prefix": "horizon-prefix"}


def head(observed: Trajectory, k: int) -> Trajectory:
    """The first ``k`` pairs of an observation (and the state after the ``k``-th)."""
    from imitation.data.types import Trajectory

    return Trajectory(obs=observed.obs[: k + 1], acts=observed.acts[:k], infos=None, terminal=False)


def prefix_scores(recognizer: Any, observed: Trajectory, scorer: str | None, goals: Sequence[Goal],
                  name: str) -> np.ndarray:
    """Scores of every prefix of ``observed``, ``(T, K)``, row ``k - 1`` for the first ``k`` pairs.

    Recognizers with ``score_prefixes`` (the built-in ones) score all prefixes
    from one pass; any other recognizer is asked to ``score`` each prefix.

    Raises:
        RecognizerError: Unless every prefix gets one finite score per goal.
    """
    n = len(observed.acts)
    if not hasattr(recognizer, "score_prefixes"):
        return np.stack([check_scores(name, recognizer.score(head(observed, k), scorer), goals)
                         for k in range(1, n + 1)])
    scores = recognizer.score_prefixes(observed, scorer)
    if not isinstance(scores, Mapping) or {tuple(g) for g in scores} != set(goals):
        raise RecognizerError(f"recognizer {name!r} must return prefix scores for every candidate goal {list(goals)}")
    out = np.stack([np.asarray(scores[g], dtype=float) for g in goals], axis=1)
    if out.shape != (n, len(goals)) or not np.all(np.isfinite(out)):
        raise RecognizerError(f"recognizer {name!r} returned prefix scores of shape {out.shape} or non-finite "
                              f"values; expected {(n, len(goals))} finite scores")
    return out


def convergence(correct: Sequence[bool]) -> tuple[float, bool]:
    """When a sequence of per-prefix predictions settles on the truth.

    Args:
        correct: Whether the prediction after each of ``T`` steps was right.

    Returns:
        ``(k* / T, converged)``: ``k*`` is the first step from which every
        prediction is right; ``(1.0, False)`` if the last one is wrong.
    """
    ok = np.asarray(correct, dtype=bool)
    if len(ok) == 0:
        raise ValueError("convergence needs at least one prediction")
    if not ok[-1]:
        return 1.0, False
    wrong = np.flatnonzero(~ok)
    first = int(wrong[-1]) + 2 if len(wrong) else 1
    return first / len(ok), True


def macro_f1(y_true: np.ndarray, y_pred: np.ndarray, n_classes: int) -> float:
    """Macro F1 over ``n_classes`` (0 for a class never true nor predicted), as scikit-learn's with ``zero_division=0``."""
    tp = np.bincount(y_true[y_true == y_pred], minlength=n_classes)
    support = np.bincount(y_true, minlength=n_classes) + np.bincount(y_pred, minlength=n_classes)
    return float(np.mean(np.divide(2 * tp, support, out=np.zeros(n_classes), where=support > 0)))


def observed_steps(fractions: np.ndarray, lengths: np.ndarray, rounding: str = "ceil") -> np.ndarray:
    """``(F, N)`` steps observed at each fraction for trajectories of each length (vectorised ``n_observed``)."""
    raw = np.round(fractions[:, None] * lengths[None, :], 9)
    k = np.ceil(raw) if rounding == "ceil" else np.floor(raw)
    return np.clip(k, 1, lengths[None, :]).astype(np.int64)


def curves(predictions: Sequence[np.ndarray], labels: Sequence[int], n_classes: int, fractions: Iterable[float],
           rounding: str = "ceil") -> tuple[np.ndarray, np.ndarray]:
    """Accuracy and macro F1 at each observed fraction, over trajectories with per-prefix ``predictions``."""
    fractions = np.asarray(list(fractions), dtype=float)
    lengths = np.array([len(p) for p in predictions])
    steps = observed_steps(fractions, lengths, rounding)
    y_true = np.asarray(labels)
    accuracy, f1 = [], []
    for row in steps:
        y_pred = np.array([p[k - 1] for p, k in zip(predictions, row)])
        accuracy.append(float(np.mean(y_pred == y_true)))
        f1.append(macro_f1(y_true, y_pred, n_classes))
    return np.array(accuracy), np.array(f1)


def f1_auc(predictions: Sequence[np.ndarray], labels: Sequence[int], n_classes: int, rounding: str = "ceil") -> float:
    """Exact area under macro F1 against the observed fraction in (0, 1].

    With ``ceil`` rounding the prediction of a ``T``-step trajectory is
    constant on each ``((j - 1) / T, j / T]``, so F1 is constant between
    consecutive breakpoints ``j / T`` and its value at the right end holds on
    the whole interval (``floor``: at the left end).
    """
    ends = np.unique(np.concatenate([np.arange(1, len(p) + 1) / len(p) for p in predictions] + [[0.0, 1.0]]))
    widths = np.diff(ends)
    where = ends[1:] if rounding == "ceil" else ends[:-1]
    _, f1 = curves(predictions, labels, n_classes, np.maximum(where, 1e-12), rounding)
    return float(np.sum(widths * f1))


def online_metrics(predictions: Sequence[np.ndarray], labels: Sequence[int], n_classes: int,
                   rounding: str = "ceil") -> dict[str, Any]:
    """Every online metric of a test set: means of the per-trajectory ones, the F1 area and the curves."""
    settled = [convergence(p == y) for p, y in zip(predictions, labels)]
    accuracy, f1 = curves(predictions, labels, n_classes, GRID, rounding)
    return {
        "convergence": float(np.mean([c for c, _ in settled])),
        "never": float(np.mean([not ok for _, ok in settled])),
        "step_accuracy": float(np.mean([np.mean(p == y) for p, y in zip(predictions, labels)])),
        "f1_auc": f1_auc(predictions, labels, n_classes, rounding),
        "curve": json.dumps({"fractions": list(GRID), "accuracy": accuracy.round(6).tolist(),
                             "f1": f1.round(6).tolist()}),
    }


def run_online_seed(task: GRTask, planned: Planned, seed: int, protocol: str, versions: str,
                    demos: Demos | None = None, rounding: str = "ceil") -> tuple[list[OnlineRow], FitReport | None]:
    """Fit one recognizer on one seed's training demos, then score every prefix of every test observation.

    The observation of a test demonstration is the protocol's at level 1.0
    (drawn from its own random stream), revealed one step at a time.

    Returns:
        One row per scorer, and the recognizer's fit report.
    """
    chosen = get_protocol(protocol)
    label = protocol_label(chosen.name, rounding)
    name = planned.spec.name
    train, test = task.split(demos if demos is not None else task.generate_demos(seed))
    recognizer, report, fit_per_goal = fit_recognizer(task, planned, seed, train)
    rng = cell_rng(seed, 1.0, f"online:{label}")
    labelled = [(i, observe(traj, 1.0, chosen, rng, rounding)) for i, goal in enumerate(task.goals)
                for traj in test[goal]]
    labels = [i for i, _ in labelled]
    rows = []
    for scorer, score_arg in zip(planned.scorers, planned.score_args):
        start = time.perf_counter_ns()
        predictions = [np.argmax(prefix_scores(recognizer, observed, score_arg, task.goals, name), axis=1)
                       for _, observed in labelled]
        elapsed_us = (time.perf_counter_ns() - start) / 1e3
        n_prefixes = sum(len(p) for p in predictions)
        rows.append(OnlineRow(
            task=task.id, recognizer=name, scorer=scorer, config_hash=planned.config_hash, seed=seed, protocol=label,
            n_trajectories=len(labelled), fit_seconds_per_goal=fit_per_goal, score_us_per_prefix=elapsed_us / n_prefixes,
            config=planned.config, versions=versions, **online_metrics(predictions, labels, len(task.goals), rounding),
        ))
    return rows, report


def aggregate_online(rows: Iterable[OnlineRow]) -> list[dict[str, Any]]:
    """Across-seed online records, one per (task, recognizer, scorer, configuration, protocol).

    Each has the mean and 95 % interval of the convergence point, step
    accuracy and F1 area, the share never converging, and the mean accuracy
    and F1 curves with their per-fraction 95 % intervals (the plot's bands).
    """
    groups: dict[tuple, list[OnlineRow]] = {}
    for r in rows:
        groups.setdefault((r.task, r.recognizer, r.scorer, r.config_hash, r.protocol), []).append(r)
    records = []
    for (task, rec, scorer, chash, protocol), group in sorted(groups.items()):
        group.sort(key=lambda r: r.seed)
        record: dict[str, Any] = {"task": task, "recognizer": rec, "scorer": scorer, "protocol": protocol,
                                  "config_hash": chash, "n_seeds": len(group), "seeds": [r.seed for r in group]}
        for key in ("convergence", "step_accuracy", "f1_auc"):
            record |= metrics.summary_fields(key, [getattr(r, key) for r in group])
        record["never_mean"] = float(np.mean([r.never for r in group]))
        parsed = [json.loads(r.curve) for r in group]
        record["fractions"] = parsed[0]["fractions"]
        for key in ("accuracy", "f1"):
            per_fraction = [metrics.summarize(v) for v in zip(*(c[key] for c in parsed))]
            record[f"{key}_curve"] = [s["mean"] for s in per_fraction]
            record[f"{key}_curve_low"] = [s["ci_low"] for s in per_fraction]
            record[f"{key}_curve_high"] = [s["ci_high"] for s in per_fraction]
        record["fit_seconds_per_goal"] = float(np.mean([r.fit_seconds_per_goal for r in group]))
        record["score_us_per_prefix"] = float(np.mean([r.score_us_per_prefix for r in group]))
        record["task_params"] = _task_params(group[0].config)
        records.append(record)
    return records


def ceiling_curve(record: dict[str, Any], samples: int = 2000,
                  on_level: Callable[[], None] | None = None) -> list[float] | None:
    """The Bayes ceiling of an online record at each of its fractions (cached on disk).

    Online, the first ``n_observed(p, T)`` steps are what the offline prefix
    protocol of the same span observes at level ``p``, so the ceiling is that
    protocol's. ``None`` where there is none (other domains, plugin protocols).
    ``on_level`` is called after each fraction (for a progress bar).
    """
    from grail_bench.evaluation.ceiling import cached_ceiling
    from grail_bench.leaderboard import _task

    name, rounding = parse_label(record["protocol"])
    task = _task(record["task"], record.get("task_params"))
    if name not in PREFIX_OF or task is None:
        return None
    curve = []
    for fraction in record["fractions"]:
        ceiling = cached_ceiling(task, protocol_label(PREFIX_OF[name], rounding), fraction, samples=samples)
        if ceiling is None:
            return None
        curve.append(ceiling.accuracy)
        if on_level is not None:
            on_level()
    return curve
