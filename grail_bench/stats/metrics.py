"""Metrics as pure functions: per-seed classification scores and across-seed summaries.

Ties. Where several goals share the best score, the prediction is the
expectation under uniform tie-breaking, without a random draw: each of the
tied goals ``W`` is predicted with probability ``1 / |W|`` (:func:`prediction`).
An observation adds ``1 / |W|`` to the cell (true goal, w) of the *expected*
confusion matrix for each ``w`` in ``W`` (:func:`expected_confusion`), so
accuracy is exactly its expectation, the mean of ``[true in W] / |W|``, and
precision, recall and F1 are those of the expected (fractional) confusion
matrix (:func:`classification_of`), each observation giving fractional credit.
Without ties every prediction is one goal and every value equals that of the
plain argmax to the last bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.stats import robust

#: How predictions break ties between goals of equal best score, as stored rows record it (the store's
#: ``ties`` column): expected over a uniform choice among the tied goals. Rows stored before carry none;
#: they gave the prediction to the lowest-index tied goal.
TIE_RULE = "uniform"


def prediction(scores: np.ndarray) -> np.ndarray:
    """Each goal's probability of being predicted under uniform tie-breaking, along the last axis.

    The goals tied at the best score each get ``1 / |W|``, the others 0: a
    ``(K,)`` score vector gives a ``(K,)`` distribution, ``(T, K)`` prefix
    scores one per row. Without a tie it is the one-hot vector of the argmax.
    """
    scores = np.asarray(scores, dtype=float)
    best = scores == scores.max(axis=-1, keepdims=True)
    return best / best.sum(axis=-1, keepdims=True)


def n_tied(predicted: np.ndarray) -> int:
    """How many rows of :func:`prediction` (or one vector) spread over more than one tied goal."""
    return int(np.sum(np.max(predicted, axis=-1) < 1.0))


def as_prediction(predicted: np.ndarray, n_classes: int) -> np.ndarray:
    """``(N, n_classes)`` prediction distributions from either predicted indices ``(N,)`` (one-hot) or distributions."""
    predicted = np.asarray(predicted)
    if predicted.ndim == 1:
        return np.eye(n_classes)[predicted.astype(np.int64)]
    return predicted.astype(float)


def ranking(scores: np.ndarray, label: int, k: int = 2) -> tuple[float, float]:
    """Rank of the true goal (1 = best) and whether it is in the top ``k``, expected under random tie-breaking.

    With ``h`` goals scoring strictly higher than the true goal and ``t``
    others tying with it, the expected rank is ``h + 1 + t / 2`` and the
    chance of being among the ``k`` best is ``clip((k - h) / (t + 1), 0, 1)``.
    """
    mine = scores[label]
    higher = int(np.sum(scores > mine))
    tied = int(np.sum(scores == mine)) - 1
    return higher + 1 + tied / 2, float(np.clip((k - higher) / (tied + 1), 0.0, 1.0))


def _safe_divide(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    return np.divide(num, den, out=np.zeros(len(num)), where=den > 0)


def classification(y_true: Sequence[int], y_pred: Sequence[int], n_classes: int) -> dict[str, float]:
    """Accuracy and macro precision, recall and F1 over all ``n_classes`` candidate goals, of hard predictions.

    A class never predicted (or never true) scores 0 precision (recall) and 0
    F1, as scikit-learn's ``precision_recall_fscore_support(average="macro",
    zero_division=0)`` computes them (tested equal); numpy only, so importing
    the metrics imports no scikit-learn.
    """
    return classification_of(confusion(y_true, y_pred, n_classes))


def classification_of(matrix: np.ndarray) -> dict[str, float]:
    """Accuracy and macro precision, recall and F1 of a confusion matrix, counts or expected (fractional) counts.

    Per class: true positives the diagonal cell, true count the row sum,
    predicted count the column sum; a zero denominator scores 0 (as
    :func:`classification`). Accuracy is the diagonal's share of the total.
    """
    c = np.asarray(matrix, dtype=float)
    tp, true, pred = np.diag(c).copy(), c.sum(axis=1), c.sum(axis=0)
    return {"accuracy": float(tp.sum() / c.sum()), "precision": float(np.mean(_safe_divide(tp, pred))),
            "recall": float(np.mean(_safe_divide(tp, true))), "f1": float(np.mean(_safe_divide(2 * tp, true + pred)))}


def per_class_f1(y_true: Sequence[int], y_pred: Sequence[int], n_classes: int) -> np.ndarray:
    """``(n_classes,)`` F1 of each class (0 for a class never true nor predicted); their mean is the macro F1."""
    return per_class_f1_of(confusion(y_true, y_pred, n_classes))


def per_class_f1_of(matrix: np.ndarray) -> np.ndarray:
    """``(K,)`` F1 of each class of a (possibly expected) confusion matrix; their mean is the macro F1."""
    c = np.asarray(matrix, dtype=float)
    return _safe_divide(2 * np.diag(c), c.sum(axis=1) + c.sum(axis=0))


def confusion(y_true: Sequence[int], y_pred: Sequence[int], n_classes: int) -> np.ndarray:
    """``(n_classes, n_classes)`` counts: row the true class, column the predicted one."""
    out = np.zeros((n_classes, n_classes), dtype=np.int64)
    np.add.at(out, (np.asarray(y_true, dtype=np.int64), np.asarray(y_pred, dtype=np.int64)), 1)
    return out


def expected_confusion(y_true: Sequence[int], predicted: np.ndarray, n_classes: int) -> np.ndarray:
    """``(n_classes, n_classes)`` expected counts: row the true class, column the predicted one.

    Args:
        y_true: The true class of each observation.
        predicted: ``(N, n_classes)``: each observation's prediction distribution (:func:`prediction`),
            added to its true class's row; or ``(N,)`` predicted indices (then the counts of :func:`confusion`).
    """
    out = np.zeros((n_classes, n_classes))
    np.add.at(out, np.asarray(y_true, dtype=np.int64), as_prediction(predicted, n_classes))
    return out


def plain_matrix(matrix: np.ndarray) -> list[list[Any]]:
    """A matrix as nested lists for JSON: ints when every entry is whole (as counts were stored), else floats."""
    m = np.asarray(matrix, dtype=float)
    return m.astype(np.int64).tolist() if np.all(m == np.round(m)) else m.tolist()


def macro_f1(y_true: np.ndarray, y_pred: np.ndarray, n_classes: int) -> float:
    """Macro F1 of :func:`classification` alone."""
    return classification(y_true, y_pred, n_classes)["f1"]


def calibration(loglik: np.ndarray, n_steps: int, label: int) -> tuple[float, float, float]:
    """Brier score and negative log-likelihood of the posterior over goals, and its top-label confidence.

    The posterior is the softmax of summed log-likelihoods (mean ``loglik``
    times the ``n_steps`` observed), i.e. Bayes' rule with a uniform prior.
    """
    from scipy.special import softmax  # here: the report imports this module, not scipy.special

    p = softmax(loglik * n_steps)
    target = np.zeros_like(p)
    target[label] = 1.0
    return float(np.sum((p - target) ** 2)), float(-np.log(max(p[label], 1e-12))), float(p.max())


#: Equal-width confidence bins of the reliability diagram and the ECE.
CALIBRATION_BINS = 10


def reliability_bins(confidences: Sequence[float], correct: Sequence[bool],
                     bins: int = CALIBRATION_BINS) -> list[list[float]]:
    """Per equal-width confidence bin on [0, 1]: ``[count, summed confidence, correct count]`` (addable across seeds).

    Args:
        confidences: The posterior probability of each prediction's goal (the top-label confidence).
        correct: Whether each prediction was the true goal, or its probability under uniform tie-breaking.
    """
    conf = np.asarray(confidences, dtype=float)
    index = np.minimum((conf * bins).astype(np.int64), bins - 1)
    out = np.zeros((bins, 3))
    np.add.at(out, index, np.stack([np.ones_like(conf), conf, np.asarray(correct, dtype=float)], axis=1))
    return out.tolist()


def expected_calibration_error(binned: Sequence[Sequence[float]]) -> float | None:
    """ECE from :func:`reliability_bins`: the count-weighted mean gap between each bin's accuracy and confidence.

    ``None`` without predictions.
    """
    b = np.asarray(binned, dtype=float)
    total = b[:, 0].sum()
    if total == 0:
        return None
    used = b[:, 0] > 0
    gap = np.abs(b[used, 2] - b[used, 1]) / b[used, 0]  # |accuracy - mean confidence| per bin
    return float(np.sum(b[used, 0] * gap) / total)


def goal_set(scores: np.ndarray, tolerance: float) -> np.ndarray:
    """The goals whose score is within ``tolerance`` of the best, as a share of the scores' range (indices).

    Every goal is in the set when all scores are equal. Scale-free, so one tolerance serves every scorer.
    """
    best, worst = scores.max(), scores.min()
    return np.flatnonzero(scores >= best - tolerance * (best - worst))


@dataclass(frozen=True)
class Summary:
    """One metric across seeds.

    Attributes:
        mean: The mean over seeds.
        std: The sample standard deviation (0 with one seed).
        ci95: ``(low, high)``, the seeded 95 % percentile bootstrap interval of the mean
            (:data:`BOOTSTRAP_REPS` resamples of the seeds, seed :data:`BOOTSTRAP_SEED`). Every resampled mean
            lies within the values' range, so the interval of a metric bounded in [0, 1] stays in [0, 1];
            with one seed, or identical values, it is the value itself.
        iqm: The interquartile mean (:func:`grail_bench.stats.robust.iqm`).
        values: The per-seed values, in seed order.
    """

    mean: float
    std: float
    ci95: tuple[float, float]
    iqm: float
    values: tuple[float, ...]

    def flat(self, name: str) -> dict[str, Any]:
        """The summary as flat JSON fields: ``{name}_mean``, ``_std``, ``_ci95_low``, ``_ci95_high``, ``_iqm``,
        ``_values``, in that order."""
        return {f"{name}_mean": self.mean, f"{name}_std": self.std, f"{name}_ci95_low": self.ci95[0],
                f"{name}_ci95_high": self.ci95[1], f"{name}_iqm": self.iqm, f"{name}_values": self.values}


#: Resamples and seed of every across-seed interval (:func:`summarize`): same values, same interval.
BOOTSTRAP_REPS = 2000
BOOTSTRAP_SEED = 0


def summarize(values: Sequence[float], reps: int = BOOTSTRAP_REPS, seed: int = BOOTSTRAP_SEED) -> Summary:
    """Mean, sample standard deviation, 95 % interval of the mean and IQM of per-seed values.

    The interval is a percentile bootstrap of the mean (resampling the seeds with replacement,
    :func:`grail_bench.stats.robust.stratified_bootstrap` with one stratum), not a Student-t interval: it
    never leaves the values' range, so a bounded metric's interval keeps its bounds.

    Raises:
        UserError: Without values.
    """
    x = np.asarray(values, dtype=float).ravel()
    if x.size == 0:
        raise UserError("a summary over seeds needs at least one value")
    mean = float(x.mean())
    if x.size == 1 or np.all(x == x[0]):
        return Summary(mean, 0.0, (mean, mean), mean, tuple(x.tolist()))
    interval = robust.stratified_bootstrap({0: x}, robust.pooled_mean, reps=reps, seed=seed)
    low, high = np.clip([interval.low, interval.high], x.min(), x.max())  # no rounding past the values' range
    return Summary(mean, float(x.std(ddof=1)), (float(low), float(high)), float(robust.iqm(x)), tuple(x.tolist()))


def summarize_many(groups: Sequence[Sequence[float]], reps: int = BOOTSTRAP_REPS,
                   seed: int = BOOTSTRAP_SEED) -> list[Summary]:
    """:func:`summarize` of each group, the same numbers, with the bootstraps of groups of equal size computed
    together (an aggregation of thousands of cells of ten seeds each resamples them in a few array operations).

    Raises:
        UserError: For a group without values.
    """
    out: list[Summary | None] = [None] * len(groups)
    by_size: dict[int, list[tuple[int, np.ndarray]]] = {}
    for i, values in enumerate(groups):
        x = np.asarray(values, dtype=float).ravel()
        if x.size <= 1 or np.all(x == x[0]):
            out[i] = summarize(x, reps, seed)
        else:
            by_size.setdefault(x.size, []).append((i, x))
    tail = 100 * (1 - 0.95) / 2  # as stratified_bootstrap computes it
    for n, items in by_size.items():
        (draws,) = robust.bootstrap_draws(seed, reps, (n,))
        for start in range(0, len(items), 256):  # (256, reps, n) floats at a time
            chunk = items[start:start + 256]
            x = np.stack([v for _, v in chunk])
            # Means of (replicates x seeds) rows, as each group's own bootstrap takes them (a 3-d mean sums in
            # another order, off in the last bit). take() lays the draws out row by row (x[:, draws] does not, so
            # reshaping it copied them all again).
            means = np.take(x, draws, axis=1).reshape(-1, n).mean(axis=-1).reshape(len(chunk), reps)
            lows, highs = np.percentile(means, [tail, 100 - tail], axis=-1)
            iqms = robust.iqm(x)
            for (i, v), low, high, iqm in zip(chunk, lows, highs, np.atleast_1d(iqms)):
                low, high = np.clip([low, high], v.min(), v.max())
                out[i] = Summary(float(v.mean()), float(v.std(ddof=1)), (float(low), float(high)), float(iqm),
                                 tuple(v.tolist()))
    return out  # type: ignore[return-value]


def summary_fields(name: str, values: Sequence[float]) -> dict[str, float]:
    """``{name}_mean``, ``{name}_ci95_low`` and ``{name}_ci95_high`` of :func:`summarize`, flat as records carry
    them."""
    s = summarize(values)
    return {f"{name}_mean": s.mean, f"{name}_ci95_low": s.ci95[0], f"{name}_ci95_high": s.ci95[1]}


def thin(values: Sequence[float], points: int = 50) -> list[float]:
    """A curve of at most ``points`` values: the means of equal consecutive chunks (unchanged if short)."""
    values = [float(v) for v in values]
    if len(values) <= points:
        return values
    return [float(np.mean(chunk)) for chunk in np.array_split(np.asarray(values), points)]
