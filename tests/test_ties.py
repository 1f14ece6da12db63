"""Ties between goals: every metric is its expectation under uniform tie-breaking, in every mode.

Hand-computed cases, the old lowest-index metrics reproduced exactly where nothing ties, and whole runs of a
recognizer that ties every goal.
"""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest
from conftest import run_mode

import grail_bench
from grail_bench.harness.modes import offline
from grail_bench.harness.modes.online import GRID, convergence, curves, expected_convergence, online_metrics
from grail_bench.harness.modes.open_set import open_set_metrics
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.recognizers.registry import register_recognizer, unregister_recognizer
from grail_bench.stats import metrics

# --- the old rule (lowest-index tie-breaking), as grail-bench computed it before, for comparison ---------------


def old_predict(scores: np.ndarray) -> int:
    return int(np.flatnonzero(scores == scores.max())[0])


def old_classification(y_true, y_pred, n):
    yt, yp = np.asarray(y_true, dtype=np.int64), np.asarray(y_pred, dtype=np.int64)
    tp = np.bincount(yt[yt == yp], minlength=n).astype(float)
    true, pred = np.bincount(yt, minlength=n).astype(float), np.bincount(yp, minlength=n).astype(float)
    div = lambda a, b: np.divide(a, b, out=np.zeros(len(a)), where=b > 0)  # noqa: E731
    return {"accuracy": float(np.mean(yt == yp)), "precision": float(np.mean(div(tp, pred))),
            "recall": float(np.mean(div(tp, true))), "f1": float(np.mean(div(2 * tp, true + pred)))}


def old_convergence(ok):
    ok = np.asarray(ok, dtype=bool)
    if not ok[-1]:
        return 1.0, False
    wrong = np.flatnonzero(~ok)
    return (int(wrong[-1]) + 2 if len(wrong) else 1) / len(ok), True


def old_curves(predictions, labels, n, fractions):
    """The old accuracy and F1 curves of per-prefix predicted indices (ceil rounding)."""
    lengths = np.array([len(p) for p in predictions])
    steps = np.clip(np.ceil(np.round(np.asarray(fractions)[:, None] * lengths[None, :], 9)), 1, lengths).astype(int)
    accuracy, f1 = [], []
    for row in steps:
        y_pred = np.array([p[k - 1] for p, k in zip(predictions, row)])
        accuracy.append(float(np.mean(y_pred == np.asarray(labels))))
        f1.append(old_classification(labels, y_pred, n)["f1"])
    return np.array(accuracy), np.array(f1)


def old_online(predictions, labels, n):
    """The old online metrics of per-prefix predicted indices (ceil rounding)."""
    settled = [old_convergence(p == y) for p, y in zip(predictions, labels)]
    accuracy, f1 = old_curves(predictions, labels, n, GRID)
    ends = np.unique(np.concatenate([np.arange(1, len(p) + 1) / len(p) for p in predictions] + [[0.0, 1.0]]))
    area = float(np.sum(np.diff(ends) * old_curves(predictions, labels, n, np.maximum(ends[1:], 1e-12))[1]))
    return {"convergence": float(np.mean([c for c, _ in settled])),
            "never": float(np.mean([not ok for _, ok in settled])),
            "step_accuracy": float(np.mean([np.mean(p == y) for p, y in zip(predictions, labels)])),
            "f1_auc": area, "accuracy": accuracy.round(6).tolist(), "f1": f1.round(6).tolist()}


def new_metrics(scores: np.ndarray, labels) -> tuple[dict[str, float], np.ndarray]:
    predicted = metrics.prediction(scores)
    matrix = metrics.expected_confusion(labels, predicted, scores.shape[1])
    return metrics.classification_of(matrix), matrix


# --- hand-computed cases --------------------------------------------------------------------------------------


def test_two_goals_tied_share_the_credit():
    # Goal 0's observation ties goals 0 and 1; goal 1's is recognised.
    m, matrix = new_metrics(np.array([[1.0, 1.0], [0.0, 1.0]]), [0, 1])
    assert matrix.tolist() == [[0.5, 0.5], [0.0, 1.0]]
    assert m["accuracy"] == 0.75
    # Class 0: TP .5, true 1, predicted .5: P 1, R .5, F1 2/3. Class 1: TP 1, true 1, predicted 1.5: P 2/3, R 1,
    # F1 .8.
    assert m["precision"] == pytest.approx((1 + 2 / 3) / 2) and m["recall"] == pytest.approx((0.5 + 1) / 2)
    assert m["f1"] == pytest.approx((2 / 3 + 0.8) / 2) == pytest.approx(11 / 15)
    # The old rule handed the tie to goal 0, the true one: a perfect score.
    assert old_classification([0, 1], [old_predict(np.array([1.0, 1.0])), 1], 2)["f1"] == 1.0


def test_three_goals_tied():
    # Goal 2's observation ties all three goals; goal 0's is recognised.
    m, matrix = new_metrics(np.array([[0.3, 0.3, 0.3], [1.0, 0.0, 0.0]]), [2, 0])
    assert matrix == pytest.approx(np.array([[1, 0, 0], [0, 0, 0], [1 / 3, 1 / 3, 1 / 3]]))
    assert m["accuracy"] == pytest.approx(2 / 3)
    # Class 0: TP 1, true 1, predicted 4/3: P 3/4, R 1, F1 6/7. Class 1: never true, predicted 1/3: 0.
    # Class 2: TP 1/3, true 1, predicted 1/3: P 1, R 1/3, F1 1/2.
    assert m["precision"] == pytest.approx((3 / 4 + 0 + 1) / 3)
    assert m["recall"] == pytest.approx((1 + 0 + 1 / 3) / 3)
    assert m["f1"] == pytest.approx((6 / 7 + 0 + 1 / 2) / 3)
    assert metrics.per_class_f1_of(matrix) == pytest.approx([6 / 7, 0, 1 / 2])


def test_accuracy_is_the_mean_credit_of_the_true_goal(rng):
    for _ in range(200):
        k, n = int(rng.integers(2, 6)), int(rng.integers(1, 30))
        scores = rng.integers(0, 3, size=(n, k)).astype(float)  # coarse: many ties
        labels = rng.integers(0, k, size=n)
        m, matrix = new_metrics(scores, labels)
        credit = [(y in np.flatnonzero(s == s.max())) / np.sum(s == s.max()) for s, y in zip(scores, labels)]
        assert m["accuracy"] == pytest.approx(np.mean(credit))
        assert matrix.sum(axis=1) == pytest.approx(np.bincount(labels, minlength=k))  # each observation adds 1


def test_without_ties_everything_equals_the_old_metrics_exactly(rng):
    for _ in range(500):
        k, n = int(rng.integers(2, 9)), int(rng.integers(1, 40))
        scores, labels = rng.normal(size=(n, k)), rng.integers(0, k, size=n)
        predicted = metrics.prediction(scores)
        assert metrics.n_tied(predicted) == 0
        old = [old_predict(s) for s in scores]
        m, matrix = new_metrics(scores, labels)
        assert m == old_classification(labels, old, k)  # to the last bit
        assert metrics.plain_matrix(matrix) == metrics.confusion(labels, old, k).tolist()
        assert metrics.per_class_f1_of(matrix).tolist() == metrics.per_class_f1(labels, old, k).tolist()
        hit = predicted[np.arange(n), labels]
        conf = rng.uniform(size=n)
        assert metrics.reliability_bins(conf, hit) == metrics.reliability_bins(conf, np.array(old) == labels)


def test_without_ties_online_metrics_equal_the_old_ones_exactly(rng):
    for _ in range(100):
        k, n = int(rng.integers(2, 6)), int(rng.integers(1, 12))
        scores = [rng.normal(size=(int(rng.integers(1, 15)), k)) for _ in range(n)]
        labels = rng.integers(0, k, size=n).tolist()
        new = online_metrics([metrics.prediction(s) for s in scores], labels, k)
        old = old_online([np.argmax(s, axis=1) for s in scores], labels, k)
        same = ("convergence", "never", "step_accuracy", "f1_auc")
        assert {key: new[key] for key in same} == {key: old[key] for key in same}  # to the last bit
        curve = json.loads(new["curve"])
        assert (curve["accuracy"], curve["f1"]) == (old["accuracy"], old["f1"])


def test_expected_convergence_is_the_mean_over_every_tie_breaking(rng):
    for _ in range(50):
        q = rng.choice([0.0, 1 / 3, 0.5, 1.0], size=int(rng.integers(1, 7)))
        point = converged = 0.0
        for outcome in itertools.product([True, False], repeat=len(q)):  # each prefix right or not, independently
            p = float(np.prod([qi if ok else 1 - qi for qi, ok in zip(q, outcome)]))
            c, ok = convergence(list(outcome))
            point, converged = point + p * c, converged + p * ok
        assert expected_convergence(q) == pytest.approx((point, converged))
    # Two prefixes each right with probability 1/2: right-right settles at 1/2, anything else at 1.
    assert expected_convergence([0.5, 0.5]) == pytest.approx((0.25 * 0.5 + 0.75 * 1.0, 0.5))


def test_online_prefixes_with_a_tie():
    # Goal 0's trajectory ties after step 1, then is recognised; goal 1's is recognised, then ties at the end.
    a = np.array([[1.0, 1.0], [1.0, 0.0]])  # right with probability 1/2, then 1
    b = np.array([[0.0, 1.0], [1.0, 1.0]])  # right with probability 1, then 1/2
    m = online_metrics([metrics.prediction(a), metrics.prediction(b)], [0, 1], 2)
    assert m["step_accuracy"] == 0.75
    assert m["never"] == 0.25  # only b can end wrong, with probability 1/2
    # a: settles at 1/2 (right-right, 1/2) or at 1 (wrong-right, 1/2); b: at 1/2 (1/2) or never, 1.0 (1/2).
    assert m["convergence"] == pytest.approx(0.75)
    # Either step: one trajectory split 1/2-1/2 and one recognised, confusion [[.5, .5], [0, 1]] or its mirror.
    assert m["f1_auc"] == pytest.approx(11 / 15)
    curve = json.loads(m["curve"])
    assert set(curve["accuracy"]) == {0.75} and curve["f1"] == pytest.approx([11 / 15] * len(GRID))
    # The old rule: a right at both steps, b right then wrong (the tie went to goal 0).
    old = old_online([np.argmax(a, axis=1), np.argmax(b, axis=1)], [0, 1], 2)
    assert (old["convergence"], old["never"]) == ((0.5 + 1.0) / 2, 0.5)


def test_curves_take_indices_or_distributions_alike(rng):
    hard = [rng.integers(0, 3, size=int(rng.integers(1, 9))) for _ in range(6)]
    labels = rng.integers(0, 3, size=6).tolist()
    onehot = [np.eye(3)[p] for p in hard]
    for rounding in ("ceil", "floor"):
        assert [c.tolist() for c in curves(hard, labels, 3, GRID, rounding)] == \
            [c.tolist() for c in curves(onehot, labels, 3, GRID, rounding)]


def test_open_set_with_a_tie_among_known_goals():
    # Two known goals and "none of these" (class 2); a best score below 0.5 is answered "none".
    scores = np.array([[0.9, 0.9], [0.2, 0.8], [0.3, 0.1], [0.6, 0.6]])
    labels = np.array([0, 1, 2, 2])
    m = open_set_metrics(scores.max(axis=1), metrics.prediction(scores), labels, threshold=0.5, n_known=2)
    # Expected confusion: [[.5, .5, 0], [0, 1, 0], [.5, .5, 1]]: the first and last observations split.
    assert m["accuracy"] == pytest.approx((0.5 + 1 + 1 + 0) / 4)
    # F1: goal 0: TP .5, true 1, predicted 1: 1/2; goal 1: TP 1, true 1, predicted 2: 2/3; none: TP 1, true 2,
    # predicted 1: 2/3.
    assert m["f1"] == pytest.approx((1 / 2 + 2 / 3 + 2 / 3) / 3)
    # The threshold's decisions do not depend on ties.
    assert m["unknown_recall"] == 0.5 and m["false_alarm"] == 0.0 and m["auroc"] == 1.0
    hard = open_set_metrics(scores.max(axis=1), np.array([0, 1, 0, 0]), labels, threshold=0.5, n_known=2)
    assert hard["accuracy"] == 0.75  # the old rule: the first tie went to goal 0, the true one


def test_summed_confusions_stay_ints_when_whole():
    row = offline.ResultRow(task="GRAIL/T-v0", recognizer="r", scorer="s", config_hash="h", seed=0,
                            observability=1.0, protocol="prefix", accuracy=0.5, precision=0.5, recall=0.5, f1=0.5,
                            n_observations=2, n_ties=1, fit_seconds_per_goal=0.0, score_us_per_observation=1.0,
                            config="{}", versions="{}", confusion=json.dumps([[0.5, 0.5], [0, 1]]))
    (record,) = offline.aggregate([row, dataclasses.replace(row, seed=1)])
    assert record.confusion == [[1, 1], [0, 2]] and all(type(v) is int for r in record.confusion for v in r)
    (record,) = offline.aggregate([row, dataclasses.replace(row, seed=1, confusion="[[1, 0], [0, 1]]")])
    assert record.confusion == [[1.5, 0.5], [0.0, 2.0]]
    (record,) = offline.aggregate([dataclasses.replace(row, confusion="[[2, 0], [1, 1]]")])  # an old row
    assert record.confusion == [[2, 0], [1, 1]] and record.tie_rate == 0.5


# --- whole runs of a recognizer that ties every goal ------------------------------------------------------------


class Flat:
    """Scores every goal the same: every observation (and prefix) ties all of them."""

    name = "flat"
    config: dict = {}
    default_scorer = "default"

    def exposes(self, action_space):
        return frozenset()

    def fit(self, demos, env_factory, *, seed, cache_key=None):
        self.goals = list(demos)

    def set_goals(self, goals):
        self.goals = list(goals)

    def score(self, observed, scorer=None):
        return {g: 0.0 for g in self.goals}


@pytest.fixture
def flat():
    register_recognizer("flat", Flat)
    yield Flat
    unregister_recognizer("flat")


def _planned(task):
    return plan(task, RecognizerSpec("flat", {}), task.make_env().action_space)


def _split_evenly(counts: np.ndarray) -> tuple[float, np.ndarray]:
    """Accuracy and per-class F1 when every observation splits evenly over the ``K`` goals."""
    k, n = len(counts), counts.sum()
    return 1 / k, 2 * (counts / k) / (counts + n / k)


def test_offline_run_of_a_recognizer_that_ties_every_goal(flat):
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    demos = task.generate_demos(0)
    rows, _ = run_mode("offline", task, _planned(task), 0, (0.3, 1.0), "subset", demos)
    test = task.split(demos)[1]
    counts = np.array([len(test[g]) for g in task.goals])
    accuracy, per_class = _split_evenly(counts)
    for r in rows:
        assert r.n_ties == r.n_observations == counts.sum() and r.ties == "uniform"
        assert r.accuracy == pytest.approx(accuracy) and r.f1 == pytest.approx(per_class.mean())
        assert r.recall == pytest.approx(accuracy) and r.mean_rank == pytest.approx((len(counts) + 1) / 2)
        assert np.array(json.loads(r.confusion)) == pytest.approx(np.outer(counts, np.full(len(counts), 0.25)))
    (record, _) = offline.aggregate(rows)
    assert record.tie_rate == 1.0
    again, _ = run_mode("offline", task, _planned(task), 0, (0.3, 1.0), "subset", demos)
    timing = ("score_us_per_observation", "fit_seconds_per_goal")
    strip = lambda r: {k: v for k, v in dataclasses.asdict(r).items() if k not in timing}  # noqa: E731
    assert [strip(r) for r in rows] == [strip(r) for r in again]  # deterministic: no random draw


def test_online_run_of_a_recognizer_that_ties_every_goal(flat):
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    (row,), _ = run_mode("online", task, _planned(task), 0, (), "subset")
    assert row.step_accuracy == pytest.approx(0.25) and row.never == pytest.approx(0.75)
    assert row.n_ties > 0 and row.ties == "uniform"
    assert 0.75 < row.convergence < 1.0  # the last prefix is right 1/4 of the time, earlier ones too sometimes
    assert set(json.loads(row.curve)["accuracy"]) == {0.25}


def test_open_set_run_of_a_recognizer_that_ties_every_goal(flat):
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    demos = task.generate_demos(1)
    (row,), _ = run_mode("open-set", task, _planned(task), 1, (1.0,), "subset", demos)
    test = task.split(demos)[1]
    hidden = task.goals[1]
    n_known = sum(len(t) for g, t in test.items() if g != hidden)
    # Every best score is 0, the threshold too: nothing is answered "none"; each known observation splits over the
    # 3 known goals.
    assert row.false_alarm == 0.0 and row.unknown_recall == 0.0 and row.n_ties == row.n_observations
    assert row.accuracy == pytest.approx(n_known / 3 / row.n_observations) and row.ties == "uniform"


def test_zero_shot_run_of_a_recognizer_that_ties_every_goal(flat):
    from grail_bench.harness.modes.zero_shot import held_out_goals

    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
    demos = task.generate_demos(2)
    (row,), _ = run_mode("zero-shot", task, _planned(task), 2, (1.0,), "subset", demos)
    test = task.split(demos)[1]
    counts = np.array([len(test[g]) for g in task.goals])
    accuracy, per_class = _split_evenly(counts)
    hidden = np.array([g in held_out_goals(task.goals, 2) for g in task.goals])
    assert row.accuracy == pytest.approx(accuracy) and row.accuracy_held_out == pytest.approx(accuracy)
    assert row.f1 == pytest.approx(per_class.mean()) and row.f1_held_out == pytest.approx(per_class[hidden].mean())
    assert row.n_ties == row.n_observations and row.ties == "uniform"


@pytest.mark.parametrize("mode,levels", [("offline", (1.0,)), ("online", ()), ("open-set", (1.0,)),
                                         ("zero-shot", (1.0,))])
def test_tied_runs_of_every_mode_are_recomputed_exactly_from_their_outputs(flat, mode, levels):
    from grail_bench.harness.modes import MODES, SeedRun
    from grail_bench.harness.outputs import disagreements, output_row
    from grail_bench.task.observation import ObservationSpec

    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    kept: list = []
    job = SeedRun(task=task, planned=_planned(task), seed=1,
                  observation=ObservationSpec.resolve("subset", "ceil", levels), versions="{}",
                  demos=task.generate_demos(1), outputs=kept)
    (row,), _ = MODES[mode].run(job)
    (outputs,) = kept
    assert outputs.row is row and row.n_ties > 0  # every observation (or prefix) tied
    stored = output_row(outputs)
    assert disagreements(row, stored) == []
    assert disagreements(dataclasses.replace(row, n_ties=row.n_ties - 1), stored) == ["n_ties"]
