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

Ties. Where goals tie at the best score after step ``k``, each prefix's
prediction is a uniform choice among the tied goals ``W``, made independently
at every prefix (as each offline observation's is), and every metric is its
expectation, without a random draw: the prefix is correct with probability
``q_k = [true in W] / |W|``. Step accuracy and the accuracy curve average
``q_k``; the F1 curve (and area) is the macro F1 of the expected confusion
matrix of the prefixes observed (:mod:`grail_bench.stats.metrics`); *never* is
``1 - q_T``; the convergence point is its expectation,
``(1 - q_T) + sum_m (m / T) (1 - q_{m-1}) q_m ... q_T`` (``q_0 = 0``). Without
ties every ``q_k`` is 0 or 1 and each value is the plain argmax's.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable, Mapping, Sequence

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
from grail_bench.recognizers.contract import Capabilities, RecognizerError
from grail_bench.stats import metrics
from grail_bench.task.observation import observed_channel

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

#: Observed fractions the stored curves are sampled at.
GRID = tuple(round(0.05 * i, 2) for i in range(1, 21))


@dataclass(frozen=True)
class OnlineRow(Run):
    """Online recognition of one recognizer on one task and seed: every prefix of every test observation scored.

    Per test trajectory the harness records the convergence point (the
    observed fraction from which the prediction stays correct; 1.0 when it is
    not correct at the end) and the share of prefixes predicted correctly;
    the row holds their means over trajectories.
    """

    protocol: str
    n_trajectories: int
    convergence: float  # mean (expected) convergence point, a fraction of the observation (1.0 for never)
    never: float  # (expected) share of trajectories whose prediction is wrong after the last step
    step_accuracy: float  # mean (expected) share of prefixes predicted correctly
    f1_auc: float  # area under macro F1 against the observed fraction, over all prefixes
    curve: str  # JSON: {"fractions": [...], "accuracy": [...], "f1": [...]} on a fixed grid
    fit_seconds_per_goal: float
    score_us_per_prefix: float
    config: str
    versions: str
    provenance: str | None = None
    n_ties: int | None = None  # prefixes whose best score tied (None: stored before it was counted)
    ties: str | None = metrics.TIE_RULE  # how ties were broken; None: stored before, towards the lowest index
    task_fingerprint: str | None = None  # the task as run (grail_bench.task.versions); None: stored before
    source: str | None = None  # JSON of the submission the row came from (lab, ...); None: run here


@dataclass(frozen=True, kw_only=True)
class OnlineRecord(Record):
    """One configuration's online runs across seeds: means and 95 % intervals, and the mean curves with bands."""

    convergence_mean: float
    convergence_ci95_low: float
    convergence_ci95_high: float
    step_accuracy_mean: float
    step_accuracy_ci95_low: float
    step_accuracy_ci95_high: float
    f1_auc_mean: float
    f1_auc_ci95_low: float
    f1_auc_ci95_high: float
    never_mean: float
    fractions: list[float]
    accuracy_curve: list[float]
    accuracy_curve_low: list[float]
    accuracy_curve_high: list[float]
    f1_curve: list[float]
    f1_curve_low: list[float]
    f1_curve_high: list[float]
    score_us_per_prefix: float


def head(observed: Trajectory, k: int) -> Trajectory:
    """The first ``k`` pairs of an observation and the state after the ``k``-th, which a ``states`` channel hides
    as it hides an offline observation's last state (it would give the ``k``-th action away)."""
    from grail_bench.core.trajectory import Trajectory

    obs = observed.obs[: k + 1]
    if observed_channel(observed) == "states":
        obs = obs.astype(float)  # a copy
        obs[k] = np.nan
    return Trajectory(obs=obs, acts=observed.acts[:k], infos=None, terminal=False)


def prefix_scores(recognizer: Capabilities, observed: Trajectory, scorer: str | None,
                  goals: Sequence[Goal]) -> np.ndarray:
    """Scores of every prefix of ``observed``, ``(T, K)``, row ``k - 1`` for the first ``k`` pairs.

    Recognizers with ``score_prefixes`` (the built-in ones) score all prefixes
    from one pass; any other recognizer is asked to ``score`` each prefix.

    Raises:
        RecognizerError: Unless every prefix gets one finite score per goal.
    """
    n, name = len(observed.acts), recognizer.name
    scores = recognizer.score_prefixes(observed, scorer)
    if scores is None:
        return np.stack([check_scores(name, recognizer.score(head(observed, k), scorer), goals)
                         for k in range(1, n + 1)])
    if not isinstance(scores, Mapping) or {tuple(g) for g in scores} != set(goals):
        raise RecognizerError(f"recognizer {name!r} must return prefix scores for every candidate goal {list(goals)}")
    given = [np.asarray(scores[g]) for g in goals]
    if not all(a.dtype.kind in "iuf" for a in given):  # no text, no flags
        raise RecognizerError(f"recognizer {name!r} must return numbers as prefix scores, got "
                              f"{', '.join(sorted({str(a.dtype) for a in given}))}")
    if any(a.shape != (n,) for a in given):
        raise RecognizerError(f"recognizer {name!r} returned prefix scores of shapes "
                              f"{sorted({a.shape for a in given})}; expected {n} per goal")
    out = np.stack([a.astype(float) for a in given], axis=1)
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
    point, converged = expected_convergence(np.asarray(correct, dtype=bool))
    return point, converged == 1.0


def expected_convergence(right: Sequence[float]) -> tuple[float, float]:
    """:func:`convergence` in expectation, each prefix right with its own probability, independently.

    Args:
        right: ``q_k``, the probability that the prediction after step ``k`` is
            right (``[true in W] / |W|`` with tied goals ``W``; 0 or 1 without ties).

    Returns:
        The expected convergence point (1.0 counted when the last prediction is
        wrong) and the probability ``q_T`` of converging. With every ``q_k`` 0
        or 1, exactly :func:`convergence`'s values.
    """
    q = np.asarray(right, dtype=float)
    if len(q) == 0:
        raise ValueError("convergence needs at least one prediction")
    steps = np.arange(1, len(q) + 1)
    settled_from = np.cumprod(q[::-1])[::-1]  # P(right at every step m..T)
    wrong_before = 1.0 - np.concatenate([[0.0], q[:-1]])  # P(wrong at step m - 1); before step 1 there is none
    return float((1.0 - q[-1]) + np.sum(steps / len(q) * wrong_before * settled_from)), float(q[-1])


def observed_steps(fractions: np.ndarray, lengths: np.ndarray, rounding: str = "ceil") -> np.ndarray:
    """``(F, N)`` steps observed at each fraction for trajectories of each length (vectorised ``n_observed``)."""
    raw = np.round(fractions[:, None] * lengths[None, :], 9)
    k = np.ceil(raw) if rounding == "ceil" else np.floor(raw)
    return np.clip(k, 1, lengths[None, :]).astype(np.int64)


def _distributions(predictions: Sequence[np.ndarray], n_classes: int) -> list[np.ndarray]:
    """Each trajectory's ``(T, K)`` per-prefix prediction distributions (one-hot from ``(T,)`` indices)."""
    return [metrics.as_prediction(p, n_classes) for p in predictions]


def curves(predictions: Sequence[np.ndarray], labels: Sequence[int], n_classes: int, fractions: Iterable[float],
           rounding: str = "ceil") -> tuple[np.ndarray, np.ndarray]:
    """Accuracy and macro F1 at each observed fraction, over trajectories with per-prefix ``predictions``.

    Args:
        predictions: Per trajectory, the predicted goal after each step ``(T,)``,
            or each goal's probability of being predicted ``(T, K)`` (:func:`metrics.prediction`).
        labels: Each trajectory's true goal.
    """
    fractions = np.asarray(list(fractions), dtype=float)
    dists = _distributions(predictions, n_classes)
    lengths = np.array([len(p) for p in dists])
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    stacked = np.concatenate(dists)
    steps = observed_steps(fractions, lengths, rounding)
    y_true = np.asarray(labels, dtype=np.int64)
    seen: dict[bytes, tuple[float, float]] = {}  # many fractions observe the same steps
    accuracy, f1 = [], []
    for row in steps:
        key = row.tobytes()
        if key not in seen:
            predicted = stacked[starts + row - 1]
            m = metrics.classification_of(metrics.expected_confusion(y_true, predicted, n_classes))
            seen[key] = (float(np.mean(predicted[np.arange(len(y_true)), y_true])), m["f1"])
        accuracy.append(seen[key][0])
        f1.append(seen[key][1])
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
    """Every online metric of a test set: means of the per-trajectory ones, the F1 area and the curves.

    ``predictions`` as :func:`curves` takes them; with ties, each metric is its
    expectation (see the module docstring).
    """
    dists = _distributions(predictions, n_classes)
    right = [p[:, y] for p, y in zip(dists, labels)]  # per prefix, the probability it is predicted right
    settled = [expected_convergence(q) for q in right]
    accuracy, f1 = curves(dists, labels, n_classes, GRID, rounding)
    return {
        "convergence": float(np.mean([c for c, _ in settled])),
        "never": float(np.mean([1.0 - ok for _, ok in settled])),
        "step_accuracy": float(np.mean([np.mean(q) for q in right])),
        "f1_auc": f1_auc(dists, labels, n_classes, rounding),
        "curve": json.dumps({"fractions": list(GRID), "accuracy": accuracy.round(6).tolist(),
                             "f1": f1.round(6).tolist()}),
    }


def run(job: SeedRun) -> tuple[list[OnlineRow], Fitted]:
    """Fit one recognizer on one seed's training demos, then score every prefix of every test observation.

    The observation of a test demonstration is the protocol's at level 1.0
    (drawn from its own random stream), revealed one step at a time. Goals
    tied at a prefix's best score share its prediction (see the module docstring).

    Returns:
        One row per scorer, and the fitted recognizer.
    """
    task, planned, spec = job.task, job.planned, job.observation
    train, test = task.split(job.demos)
    fitted = fit_recognizer(task, planned, job.seed, train, test)
    rng = spec.rng(job.seed, 1.0, "online")
    labelled = [(i, spec.observe(traj, 1.0, rng)) for i, goal in enumerate(task.goals) for traj in test[goal]]
    labels = [i for i, _ in labelled]
    rows = []
    for scorer in planned.scorers:
        start = time.perf_counter_ns()
        scored = [prefix_scores(fitted.recognizer, observed, scorer.arg, task.goals) for _, observed in labelled]
        elapsed_us = (time.perf_counter_ns() - start) / 1e3
        rows.append(OnlineRow(
            task=task.id, recognizer=planned.name, scorer=scorer.label, config_hash=planned.config_hash, seed=job.seed,
            protocol=spec.label, fit_seconds_per_goal=fitted.seconds_per_goal,
            score_us_per_prefix=elapsed_us / sum(len(s) for s in scored), config=planned.config,
            versions=job.versions, **unit_metrics(scored, labels, len(task.goals), spec.rounding),
        ))
        if job.outputs is not None:
            job.outputs.append(Outputs(rows[-1], {"y_true": labels, "lengths": [len(s) for s in scored],
                                                  "scores": np.concatenate(scored)}))
    return rows, fitted


def unit_metrics(scored: Sequence[np.ndarray], labels: Sequence[int], n_goals: int,
                 rounding: str = "ceil") -> dict[str, Any]:
    """The metrics of one row from its per-instance outputs: each trajectory's prefix scores and true goal.

    Args:
        scored: Per trajectory, the ``(T, K)`` scores of its prefixes (:func:`prefix_scores`).
        labels: Each trajectory's true goal.
        n_goals: The task's candidate goals.
        rounding: The protocol's rounding of an observed fraction to steps.

    Returns:
        The :class:`OnlineRow` fields they determine: every metric but the timings.
    """
    predictions = [metrics.prediction(s) for s in scored]
    return dict(n_trajectories=len(predictions), n_ties=sum(metrics.n_tied(p) for p in predictions),
                **online_metrics(predictions, labels, n_goals, rounding))


def aggregate(rows: Iterable[OnlineRow]) -> list[OnlineRecord]:
    """Across-seed online records, one per (task, recognizer, scorer, configuration, protocol).

    Each has the mean and 95 % interval of the convergence point, step
    accuracy and F1 area, the share never converging, and the mean accuracy
    and F1 curves with their per-fraction 95 % intervals (the plot's bands).
    """
    records = []
    for group in cells(rows, by_level=False):
        fields = record_fields(group, ("convergence", "step_accuracy", "f1_auc"), ("never",))
        parsed = [json.loads(r.curve) for r in group]
        for key in ("accuracy", "f1"):
            per_fraction = [metrics.summarize(v) for v in zip(*(c[key] for c in parsed))]
            fields[f"{key}_curve"] = [s.mean for s in per_fraction]
            fields[f"{key}_curve_low"] = [s.ci95[0] for s in per_fraction]
            fields[f"{key}_curve_high"] = [s.ci95[1] for s in per_fraction]
        records.append(OnlineRecord(
            fractions=parsed[0]["fractions"],
            score_us_per_prefix=float(np.mean([r.score_us_per_prefix for r in group])), **fields,
        ))
    return records


COLUMNS = LEAD + WHO + (
    Column("convergence (of T)", interval("convergence", percent=True), lambda r: r.convergence_mean),
    Column("never", lambda r: f"{r.never_mean:.0%}", lambda r: r.never_mean),
    Column("step accuracy", interval("step_accuracy"), lambda r: r.step_accuracy_mean),
    Column("F1 AUC", interval("f1_auc"), lambda r: r.f1_auc_mean),
    Column("µs / prefix", lambda r: f"{r.score_us_per_prefix:.1f}", lambda r: r.score_us_per_prefix),
)

MODE = Mode(
    name="online", row=OnlineRow, table="online",
    key=("task", "recognizer", "scorer", "config_hash", "seed", "protocol"),
    run=run, aggregate=aggregate, columns=COLUMNS,
    title="online recognition (every prefix scored)",
    intro=("Mean over seeds; " + INTERVAL_NOTE + " Convergence: the observed fraction from which the prediction "
           "stays correct (100 % when it is wrong at the end, counted in 'never'). Step accuracy: the share "
           "of prefixes predicted correctly. F1 AUC: area under macro F1 against the observed fraction."),
    takes_levels=False,
)
