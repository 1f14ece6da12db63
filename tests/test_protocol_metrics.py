"""Observation protocol and metrics as pure functions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from grail_bench.core.trajectory import Trajectory

from grail_bench.core.errors import UserError
from grail_bench.core.seeding import seed_list
from grail_bench.core.trajectory import goal_horizon
from grail_bench.stats import metrics
from grail_bench.task.observation import observe, parse_observability


def demo(T: int = 10, horizon: int = 20) -> Trajectory:
    infos = np.array([{"is_success": t >= T - 1} for t in range(horizon)])
    return Trajectory(obs=np.arange(horizon + 1)[:, None] * np.ones((1, 3), int), acts=np.arange(horizon) % 4,
                      infos=infos, terminal=True)


def test_goal_horizon_counts_up_to_success():
    assert goal_horizon(demo(T=7)) == 7
    no_info = Trajectory(obs=np.zeros((6, 1)), acts=np.zeros(5), infos=None, terminal=True)
    assert goal_horizon(no_info) == 5


@pytest.mark.parametrize("fraction, k", [(0.1, 1), (0.2, 2), (0.25, 3), (0.3, 3), (0.01, 1), (1.0, 10)])
def test_prefix_length_is_ceil_of_fraction_of_goal_horizon(fraction, k):
    observed = observe(demo(T=10), fraction)
    assert len(observed.acts) == k == max(1, math.ceil(fraction * 10))
    assert len(observed.obs) == k + 1
    assert observed.infos is None  # nothing about the goal leaks
    assert observed.obs[:, 0].tolist() == list(range(k + 1))


@pytest.mark.parametrize("bad", ["0", "1.5", "abc", "-0.1", "", "nan"])
def test_parse_observability_rejects(bad):
    with pytest.raises(ValueError):
        parse_observability(bad)


def test_parse_observability_accepts_strings_and_dedupes():
    assert parse_observability("0.1,0.2,0.1") == (0.1, 0.2)
    assert parse_observability([0.3]) == (0.3,)


def test_seed_list():
    assert seed_list(3) == [0, 1, 2]
    assert seed_list([5, 7]) == [5, 7]
    with pytest.raises(ValueError):
        seed_list(0)


def test_prediction_shares_ties_evenly_and_counts_them():
    assert metrics.prediction(np.array([0.1, 0.5, 0.2])).tolist() == [0.0, 1.0, 0.0]
    assert metrics.prediction(np.array([0.5, 0.1, 0.5])).tolist() == [0.5, 0.0, 0.5]
    rows = metrics.prediction(np.array([[0.1, 0.5, 0.2], [0.5, 0.1, 0.5], [0.0, 0.0, 0.0]]))
    assert rows.tolist() == [[0.0, 1.0, 0.0], [0.5, 0.0, 0.5], [1 / 3, 1 / 3, 1 / 3]]
    assert metrics.n_tied(rows) == 2 and metrics.n_tied(rows[0]) == 0


def test_classification_macro_scores():
    m = metrics.classification([0, 0, 1, 1], [0, 1, 1, 1], n_classes=3)
    assert m["accuracy"] == 0.75
    # class 0: P=1, R=.5, F1=2/3; class 1: P=2/3, R=1, F1=.8; class 2 (never true or predicted): 0
    assert m["precision"] == pytest.approx((1 + 2 / 3 + 0) / 3)
    assert m["f1"] == pytest.approx((2 / 3 + 0.8 + 0) / 3)


def test_classification_equals_scikit_learn_to_the_last_bit(rng):
    from sklearn.metrics import accuracy_score, precision_recall_fscore_support

    for _ in range(2000):
        n, size = int(rng.integers(2, 8)), int(rng.integers(1, 40))
        y_true, y_pred = rng.integers(0, n, size=size), rng.integers(0, n, size=size)
        p, r, f, _ = precision_recall_fscore_support(y_true, y_pred, labels=list(range(n)), average="macro",
                                                     zero_division=0)
        expected = {"accuracy": accuracy_score(y_true, y_pred), "precision": p, "recall": r, "f1": f}
        assert metrics.classification(y_true, y_pred, n) == {k: float(v) for k, v in expected.items()}
        assert metrics.macro_f1(y_true, y_pred, n) == float(f)
        per_class = precision_recall_fscore_support(y_true, y_pred, labels=list(range(n)), average=None,
                                                    zero_division=0)[2]
        assert metrics.per_class_f1(y_true, y_pred, n).tolist() == per_class.tolist()


def test_summarize_is_mean_std_iqm_and_a_percentile_bootstrap_of_the_mean():
    values = [0.5, 0.7, 0.9, 0.6]
    s = metrics.summarize(values)
    means = np.asarray(values)[np.random.default_rng(metrics.BOOTSTRAP_SEED).integers(
        0, 4, size=(metrics.BOOTSTRAP_REPS, 4))].mean(axis=1)
    assert s.mean == pytest.approx(0.675) and s.std == pytest.approx(np.std(values, ddof=1))
    assert s.ci95 == pytest.approx(tuple(np.percentile(means, [2.5, 97.5])))
    assert s.iqm == pytest.approx(0.65) and s.values == tuple(values)
    assert metrics.summary_fields("f1", values) == {"f1_mean": s.mean, "f1_ci95_low": s.ci95[0],
                                                   "f1_ci95_high": s.ci95[1]}
    assert list(s.flat("f1").items()) == [("f1_mean", s.mean), ("f1_std", s.std), ("f1_ci95_low", s.ci95[0]),
                                          ("f1_ci95_high", s.ci95[1]), ("f1_iqm", s.iqm), ("f1_values", s.values)]


@pytest.mark.parametrize("values", [[0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 0.98], [0.02, 0.0, 0.0],
                                    [0.999, 1.0], [0.3]])
def test_an_interval_of_f1_never_leaves_zero_one(values):
    low, high = metrics.summarize(values).ci95
    assert 0.0 <= low <= high <= 1.0
    assert min(values) <= low and high <= max(values)


def test_one_seed_or_identical_values_give_the_value_itself_and_same_seed_same_interval():
    assert metrics.summarize([0.4]) == metrics.Summary(0.4, 0.0, (0.4, 0.4), 0.4, (0.4,))
    assert metrics.summarize([0.1] * 3).ci95 == (pytest.approx(0.1), pytest.approx(0.1))
    assert metrics.summarize([0.0, 1.0]).ci95 == (0.0, 1.0)  # replicate means 0, 0.5, 1 with p 1/4, 1/2, 1/4
    values = [0.2, 0.5, 0.55, 0.9, 0.4]
    assert metrics.summarize(values).ci95 == metrics.summarize(values).ci95
    assert metrics.summarize(values, seed=1).ci95 != metrics.summarize(values).ci95


def test_summarize_refuses_no_values():
    with pytest.raises(UserError):
        metrics.summarize([])


@pytest.mark.parametrize("scores, label, rank, top2", [
    ([0.9, 0.5, 0.1], 0, 1.0, 1.0),        # best
    ([0.9, 0.5, 0.1], 1, 2.0, 1.0),        # second
    ([0.9, 0.5, 0.1], 2, 3.0, 0.0),        # last of three
    ([0.5, 0.5, 0.5, 0.5], 2, 2.5, 0.5),   # a four-way tie: any rank 1-4 equally likely
    ([0.9, 0.5, 0.5, 0.1], 1, 2.5, 0.5),   # tied for 2nd and 3rd
    ([0.9, 0.8, 0.5, 0.5], 3, 3.5, 0.0),   # tied for 3rd and 4th: never in the top 2
])
def test_ranking_of_the_true_goal_under_random_tie_breaking(scores, label, rank, top2):
    assert metrics.ranking(np.array(scores), label) == (rank, top2)
