"""Scorer registry and the DRACO / log-likelihood scorers on hand-computed examples."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces
from scipy import stats

from grail_bench.recognizers import make_recognizer, scoring
from grail_bench.recognizers.scoring import (
    BUILTIN,
    PolicyOutput,
    UnknownScorerError,
    available_scorers,
    check_scorer,
    get_scorer,
)
from grail_bench.stats import metrics


def test_builtin_scorers_listed():
    assert {"mse", "wasserstein", "kl", "loglik"} <= set(available_scorers())
    with pytest.raises(UnknownScorerError, match="unknown scorer 'nope'; available: mse"):
        get_scorer("nope")


def test_wasserstein_discrete_hand_computed():
    probs = np.array([[[1.0, 0.0, 0.0]], [[0.5, 0.5, 0.0]], [[0.0, 0.0, 1.0]]])
    scores = scoring.neg_wasserstein_discrete(probs, np.array([0]))
    assert scores.tolist() == [0.0, -0.5, -2.0]  # all mass on the observed action scores best


def test_wasserstein_discrete_matches_scipy(rng):
    probs = rng.dirichlet(np.ones(4), size=(1, 5))
    actions = rng.integers(0, 4, size=5)
    expected = np.mean([stats.wasserstein_distance(np.arange(4), [a], u_weights=p) for p, a in zip(probs[0], actions)])
    assert scoring.neg_wasserstein_discrete(probs, actions)[0] == pytest.approx(-expected)


def test_wasserstein_gaussian_closed_form(rng):
    mean, std = np.array([[[0.3]]]), np.array([[[0.5]]])
    samples = rng.normal(0.3, 0.5, size=200_000)
    for a in (0.3, 1.0, -0.4):
        expected = np.mean(np.abs(samples - a))  # W1 to a point mass = E|X - a|
        got = -scoring.neg_wasserstein_gaussian(mean, std, np.array([[a]]))[0]
        assert got == pytest.approx(expected, rel=1e-2)
    assert -scoring.neg_wasserstein_gaussian(mean, std, np.array([[0.3]]))[0] == pytest.approx(0.5 * np.sqrt(2 / np.pi))


def test_continuous_policy_with_mean_on_observed_action_scores_best():
    actions = np.array([[0.1, -0.2, 0.5], [0.0, 0.4, -0.3]])
    mean = np.stack([actions, actions + 0.2, actions - 0.5])
    out = PolicyOutput(mean=mean, std=np.full((3, 1, 3), 0.3))
    for name in ("mse", "wasserstein", "loglik"):
        assert get_scorer(name).fn(out, actions).argmax() == 0, name


def test_loglik_matches_scipy(rng):
    mean, std = rng.normal(size=(2, 4, 3)), np.exp(rng.normal(size=(2, 1, 3)))
    actions = rng.normal(size=(4, 3))
    expected = [np.mean(np.sum(stats.norm.logpdf(actions, mean[k], std[k]), axis=-1)) for k in range(2)]
    np.testing.assert_allclose(scoring.loglik_gaussian(mean, std, actions), expected, rtol=1e-10)
    probs = np.array([[[0.7, 0.3], [0.2, 0.8]]])
    assert scoring.loglik_discrete(probs, np.array([0, 1]))[0] == pytest.approx((np.log(0.7) + np.log(0.8)) / 2)


def test_posterior_sums_to_one_and_calibration(rng):
    for _ in range(20):
        p = scoring.posterior(rng.normal(size=6) * 10, n_steps=int(rng.integers(1, 30)))
        assert p.sum() == pytest.approx(1.0) and np.all(p >= 0)
    brier, nll, confidence = metrics.calibration(np.log(np.array([0.5, 0.25, 0.25])), 1, label=0)
    assert brier == pytest.approx(0.25 + 0.0625 + 0.0625)
    assert nll == pytest.approx(np.log(2)) and confidence == pytest.approx(0.5)


def test_expected_calibration_error_of_a_hand_computed_case():
    # Four predictions: confidence 0.9 (right, right, wrong) and 0.35 (right).
    bins = metrics.reliability_bins([0.9, 0.9, 0.9, 0.35], [True, True, False, True])
    assert bins[9] == pytest.approx([3, 2.7, 2]) and bins[3] == pytest.approx([1, 0.35, 1])
    assert sum(b[0] for b in bins) == 4
    # Bin 9: accuracy 2/3 against confidence 0.9; bin 3: 1 against 0.35. ECE = 3/4 * 0.2333 + 1/4 * 0.65.
    assert metrics.expected_calibration_error(bins) == pytest.approx(0.75 * (0.9 - 2 / 3) + 0.25 * 0.65)
    assert metrics.expected_calibration_error(metrics.reliability_bins([1.0], [True])) == 0.0  # 1.0 in the top bin
    assert metrics.expected_calibration_error([[0, 0, 0]] * 10) is None


def test_goal_sets_within_a_share_of_the_score_range():
    scores = np.array([-1.0, -0.05, 0.0, -0.5])  # range 1: within 0.1 of the best, goals 1 and 2
    assert metrics.goal_set(scores, 0.1).tolist() == [1, 2]
    assert metrics.goal_set(scores, 0.0).tolist() == [2] and metrics.goal_set(scores, 1.0).tolist() == [0, 1, 2, 3]
    assert metrics.goal_set(np.zeros(3), 0.1).tolist() == [0, 1, 2]  # all tied: every goal
    assert metrics.goal_set(scores * 1000 + 7, 0.1).tolist() == [1, 2]  # scale-free


def test_unsupported_scorer_names_both():
    rec = make_recognizer("bc")
    box = spaces.Box(-1, 1, (3,))
    with pytest.raises(ValueError, match="scorer 'kl' needs action probabilities; recognizer 'bc' exposes mean, "
                                         "occupancy, std"):
        check_scorer("kl", rec.exposes(box), rec.name)
    assert check_scorer("wasserstein", rec.exposes(box), rec.name).name == "wasserstein"
    assert check_scorer("kl", rec.exposes(spaces.Discrete(4)), rec.name).name == "kl"
    assert [s for s in BUILTIN.values() if s.posterior] == [BUILTIN["loglik"], BUILTIN["occupancy"]]
    with pytest.raises(UnknownScorerError):
        make_recognizer("bc", scorer="nope")


def test_scorer_plugin_through_entry_point(tmp_path, monkeypatch):
    (tmp_path / "my_scorers.py").write_text(
        "import numpy as np\nfrom grail_bench.recognizers.scoring import Scorer\n"
        "constant = Scorer('constant', lambda out, acts: np.zeros(out.probs.shape[0]), (frozenset({'probs'}),), 'zeros')\n"
    )
    dist = tmp_path / "my_scorers-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: my-scorers\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[grail_bench.scorers]\nconstant = my_scorers:constant\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert "constant" in available_scorers()
    assert get_scorer("constant").fn(PolicyOutput(probs=np.ones((3, 2, 4))), np.zeros(2)).tolist() == [0, 0, 0]
