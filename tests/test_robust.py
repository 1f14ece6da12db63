"""Robust statistics against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from grail_bench.core.errors import UserError
from grail_bench.stats.robust import (
    Interval,
    iqm,
    pooled_iqm,
    pooled_mean,
    probability_of_improvement,
    probability_of_improvement_ci,
    stratified_bootstrap,
    tied_best,
)


def test_iqm_trims_a_quarter_from_each_end():
    assert iqm([1, 2, 3, 4]) == 2.5  # drops 1 and 4
    assert iqm([1, 2, 3, 4, 5, 6, 7, 8]) == 4.5  # drops 1, 2, 7, 8
    assert iqm([0, 0, 1, 1, 1, 1, 100, 100]) == 1.0  # outliers do not move it
    assert iqm([0.2, 0.9]) == pytest.approx(0.55)  # fewer than 4 scores: the mean
    np.testing.assert_allclose(iqm(np.array([[1, 2, 3, 4], [0, 0, 0, 8]])), [2.5, 0.0])  # over the last axis
    with pytest.raises(UserError):
        iqm([])


def test_pooled_statistics_pool_runs_of_every_task():
    scores = {"a": [1.0, 2.0], "b": [3.0, 4.0, 5.0, 6.0]}
    assert pooled_mean(scores) == 3.5
    assert pooled_iqm(scores) == pytest.approx(3.5)  # 6 scores: trims 1 from each end -> mean(2, 3, 4, 5)


def test_probability_of_improvement_counts_ties_half_and_averages_tasks():
    # task a: pairs (1,0) win, (1,2) loss, (2,0) win, (2,2) tie -> 2.5 / 4
    assert probability_of_improvement({"a": [1, 2]}, {"a": [0, 2]}) == 0.625
    # task b: X always better -> 1.0; mean over the tasks both have
    assert probability_of_improvement({"a": [1, 2], "b": [5]}, {"a": [0, 2], "b": [1, 2], "c": [9]}) == 0.8125
    assert probability_of_improvement({"a": [3]}, {"a": [3]}) == 0.5
    with pytest.raises(UserError, match="tasks both"):
        probability_of_improvement({"a": [1]}, {"b": [1]})


def test_bootstrap_of_two_runs_spans_their_values():
    # Replicates of the mean of [0, 1] are 0, 0.5 and 1 (p = 1/4, 1/2, 1/4): the 95 % interval is [0, 1].
    interval = stratified_bootstrap({"a": [0.0, 1.0]}, pooled_mean, reps=4000, seed=3)
    assert interval == Interval(0.5, 0.0, 1.0)


def test_bootstrap_is_stratified_by_task():
    # Resampling within each task keeps one 0 and one 1 per replicate: the pooled mean never moves.
    # An unstratified bootstrap of the pooled scores [0, 0, 0, 1, 1, 1] would.
    interval = stratified_bootstrap({"a": [0.0, 0.0, 0.0], "b": [1.0, 1.0, 1.0]}, pooled_mean, reps=500)
    assert (interval.low, interval.point, interval.high) == (0.5, 0.5, 0.5)


def test_bootstrap_is_seeded_and_narrows_with_more_runs():
    rng = np.random.default_rng(0)
    few, many = {"a": rng.normal(size=5)}, {"a": rng.normal(size=500)}
    first = stratified_bootstrap(few, pooled_iqm, seed=7)
    assert first == stratified_bootstrap(few, pooled_iqm, seed=7)
    assert first != stratified_bootstrap(few, pooled_iqm, seed=8)
    wide, narrow = first.high - first.low, (lambda i: i.high - i.low)(stratified_bootstrap(many, pooled_iqm))
    assert narrow < wide / 3
    assert first.low <= first.point <= first.high


def test_bootstrap_rejects_bad_arguments():
    with pytest.raises(UserError):
        stratified_bootstrap({"a": []}, pooled_mean)
    with pytest.raises(UserError):
        stratified_bootstrap({"a": [1.0]}, pooled_mean, confidence=1.0)
    with pytest.raises(UserError):
        stratified_bootstrap({"a": [1.0]}, pooled_mean, reps=0)


def test_probability_of_improvement_interval():
    clear = probability_of_improvement_ci({"a": [0.9, 0.95, 1.0]}, {"a": [0.1, 0.2, 0.3]})
    assert (clear.point, clear.low, clear.high) == (1.0, 1.0, 1.0)
    mixed = probability_of_improvement_ci({"a": [0.1, 0.9, 0.5, 0.6]}, {"a": [0.4, 0.5, 0.7, 0.2]}, seed=1)
    assert mixed.low < 0.5 < mixed.high


def test_tied_best_marks_every_interval_overlapping_the_best():
    intervals = {"bc": Interval(0.80, 0.70, 0.90), "gail": Interval(0.75, 0.60, 0.85),
                 "graql": Interval(0.30, 0.20, 0.40)}
    assert tied_best(intervals) == {"bc", "gail"}
    assert tied_best({"bc": Interval(0.8, 0.75, 0.85), "gail": Interval(0.5, 0.4, 0.6)}) == {"bc"}
    assert tied_best({}) == set()


def test_performance_profile_and_optimality_gap_of_hand_computed_runs():
    from grail_bench.stats.robust import optimality_gap, performance_profile, stratified_bootstrap_curve

    scores = {"a": [0.2, 0.6], "b": [1.0, 1.2, 0.4]}  # five runs in all
    profile = performance_profile(scores, np.array([0.0, 0.5, 1.0]))
    assert profile.tolist() == [1.0, 3 / 5, 1 / 5]  # above 0: all; above 0.5: 0.6, 1.0, 1.2; above 1: 1.2
    assert optimality_gap(scores) == pytest.approx((0.8 + 0.4 + 0 + 0 + 0.6) / 5)  # 1.2 counts 0, not -0.2
    point, low, high = stratified_bootstrap_curve(scores, lambda s: performance_profile(s, np.array([0.5])),
                                                  reps=500, seed=1)
    assert point.tolist() == [0.6] and low[0] <= 0.6 <= high[0]
    again = stratified_bootstrap_curve(scores, lambda s: performance_profile(s, np.array([0.5])), reps=500, seed=1)
    assert (again[1] == low).all() and (again[2] == high).all()  # seeded
    # Stratified: a task whose runs all lie above tau stays above it in every replicate.
    _, low, _ = stratified_bootstrap_curve({"x": [0.9, 0.95]}, lambda s: performance_profile(s, np.array([0.5])))
    assert low.tolist() == [1.0]
