"""Scorers on hand-computed examples."""

from __future__ import annotations

import numpy as np
import pytest

from grail_bench.recognizers import scoring


def test_one_hot():
    assert scoring.one_hot(np.array([2, 0]), 3).tolist() == [[0, 0, 1], [1, 0, 0]]


def test_neg_mse_hand_computed():
    predicted = np.array([[[1.0, 0.0]], [[0.5, 0.5]], [[0.0, 1.0]]])  # 3 goals, 1 step, 2 actions
    observed = np.array([[1.0, 0.0]])
    assert scoring.neg_mse(predicted, observed).tolist() == [0.0, -0.25, -1.0]


def test_mse_of_probabilities_needs_no_one_hot_matrix(rng):
    probs = rng.dirichlet(np.ones(4), size=(6, 30)).astype(np.float32)
    actions = rng.integers(0, 4, size=30)
    fast = scoring.mse_probs_steps(probs, actions)
    reference = scoring.mse_steps(probs, scoring.one_hot(actions, 4))
    np.testing.assert_allclose(fast, reference, rtol=1e-5, atol=1e-7)
    np.testing.assert_array_equal(fast.argmax(axis=0), reference.argmax(axis=0))


def test_neg_mse_continuous_mean_on_observed_scores_best():
    observed = np.array([[0.2, -0.1, 0.4], [0.0, 0.3, -0.2]])
    predicted = np.stack([observed, observed + 0.1, -observed])
    scores = scoring.neg_mse(predicted, observed)
    assert scores[0] == 0.0 and scores.argmax() == 0
    assert scores[1] == pytest.approx(-0.01)


def test_neg_kl_all_mass_on_observed_scores_best():
    actions = np.array([0, 2])
    sharp = np.array([[0.98, 0.01, 0.01], [0.01, 0.01, 0.98]])
    uniform = np.full((2, 3), 1 / 3)
    wrong = np.array([[0.01, 0.98, 0.01], [0.98, 0.01, 0.01]])
    scores = scoring.neg_kl(np.stack([uniform, sharp, wrong]), actions, eps=0.02)
    assert scores.argmax() == 1
    assert scores[1] == pytest.approx(0.0, abs=1e-12)  # pseudo-policy equals the policy
    assert scores[2] < scores[0] < scores[1]


def test_neg_kl_hand_computed():
    probs = np.array([[[0.5, 0.5]]])
    # pseudo = [0.9, 0.1]; KL = 0.9 ln(0.9/0.5) + 0.1 ln(0.1/0.5)
    expected = -(0.9 * np.log(1.8) + 0.1 * np.log(0.2))
    assert scoring.neg_kl(probs, np.array([0]), eps=0.1)[0] == pytest.approx(expected)
