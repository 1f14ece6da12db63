"""The evaluation harness: records, resume, interruption, and what recognizers get to see."""

from __future__ import annotations

import json

import numpy as np
import pytest

import grail_bench
from grail_bench.harness.api import evaluate
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.harness.store import ResultsStore
from grail_bench.recognizers import RecognizerError, UnknownRecognizerError
from grail_bench.recognizers.registry import register_recognizer, unregister_recognizer

TASK_ID = "GRAIL/MiniGrid-Biased-v0"


class Spy:
    """Records everything the harness hands over; scores by a fixed rule."""

    name = "spy"
    config: dict = {}
    default_scorer = "default"
    fits: list = []
    observed: list = []
    fail_on_seed: int | None = None
    bad_scores = None

    def exposes(self, action_space):
        return frozenset()

    def fit(self, demos, env_factory, *, seed, cache_key=None):
        if seed == Spy.fail_on_seed:
            raise KeyboardInterrupt
        Spy.fits.append((seed, sorted(demos)))
        self.goals = list(demos)

    def score(self, observed, scorer=None):
        assert scorer is None
        Spy.observed.append(observed)
        if Spy.bad_scores is not None:
            return Spy.bad_scores
        return {g: float(i) for i, g in enumerate(self.goals)}


@pytest.fixture
def spy():
    Spy.fits, Spy.observed, Spy.fail_on_seed, Spy.bad_scores = [], [], None, None
    register_recognizer("spy", Spy)
    yield Spy
    unregister_recognizer("spy")


RECORD_KEYS = (
    "task", "recognizer", "scorer", "protocol", "observability", "n_seeds", "f1_mean", "f1_std",
    "f1_ci95_low", "f1_ci95_high", "f1_iqm", "f1_values", "accuracy_mean", "precision_mean", "recall_mean",
    "fit_seconds_per_goal", "score_us_per_observation", "tie_rate", "brier_mean", "nll_mean", "top2_mean",
    "mean_rank_mean", "config_hash", "task_params",
)


def test_records_have_the_documented_keys(spy):
    records = evaluate(TASK_ID, ["spy"], seeds=2, observability=[0.2, 0.4])
    assert len(records) == 2
    for r in records:
        assert isinstance(r, OfflineRecord) and set(RECORD_KEYS) <= set(r.to_dict())
        assert r.n_seeds == 2
        flat = json.loads(json.dumps(r.to_dict()))  # the --json format: F1's summary flat, beside the other fields
        assert "f1" not in flat and (flat["f1_mean"], flat["f1_std"], flat["f1_iqm"]) == (r.f1.mean, r.f1.std, r.f1.iqm)
        assert (flat["f1_ci95_low"], flat["f1_ci95_high"]) == r.f1.ci95 and tuple(flat["f1_values"]) == r.f1.values
        assert len(r.f1.values) == 2 and r.f1.ci95[0] <= r.f1.mean <= r.f1.ci95[1]
    # The spy always picks the last goal: accuracy 1/2, F1 = (0 + 2/3) / 2.
    assert records[0].accuracy_mean == 0.5
    assert records[0].f1.mean == pytest.approx(1 / 3)
    # The first goal's observations rank it second of two, the last goal's first.
    assert records[0].mean_rank_mean == 1.5 and records[0].top2_mean == 1.0


def test_recognizer_never_sees_the_true_goal(spy):
    evaluate(TASK_ID, ["spy"], seeds=1, observability=[0.2, 0.3, 0.4])
    assert spy.fits == [(0, [(7, 1), (7, 7)])]
    task = grail_bench.make_task(TASK_ID)
    _, test = task.split(task.generate_demos(0))
    first_states = {goal: [tuple(t.obs[1].tolist()) for t in trajs] for goal, trajs in test.items()}
    labels = []
    for observed in spy.observed:
        assert observed.infos is None
        assert not observed.terminal
        start = tuple(observed.obs[1].tolist())
        labels.append(next(i for i, g in enumerate(task.goals) if start in first_states[g]))
    per_level = [labels[i:i + 6] for i in range(0, 18, 6)]
    assert any(level != sorted(level) for level in per_level), "observations must not arrive in goal order"


def test_resume_skips_finished_seeds_and_adds_no_duplicates(spy, tmp_path):
    with ResultsStore(tmp_path / "r.sqlite") as store:
        evaluate(TASK_ID, ["spy"], seeds=2, store=store)
        assert len(spy.fits) == 2
        records = evaluate(TASK_ID, ["spy"], seeds=3, store=store)
        assert [s for s, _ in spy.fits] == [0, 1, 2]
        assert len(store.rows()) == 3 * 3
        assert all(r.n_seeds == 3 for r in records)


def test_interrupted_run_keeps_finished_seeds_and_resumes(spy, tmp_path):
    path = tmp_path / "r.sqlite"
    spy.fail_on_seed = 2
    with ResultsStore(path) as store, pytest.raises(KeyboardInterrupt):
        evaluate(TASK_ID, ["spy"], seeds=4, store=store)
    with ResultsStore(path) as store:
        assert sorted({r.seed for r in store.rows()}) == [0, 1]
        spy.fail_on_seed = None
        evaluate(TASK_ID, ["spy"], seeds=4, store=store)
        assert sorted(r.seed for r in store.rows()) == sorted([0, 1, 2, 3] * 3)


@pytest.mark.parametrize("bad, message", [({(7, 1): 1.0}, "one score per candidate goal"),
                                          ({(7, 1): 1.0, (7, 7): float("nan")}, "non-finite"),
                                          ([1.0, 2.0], "one score per candidate goal"),
                                          ({(7, 1): "0.9", (7, 7): 0.1}, "must return numbers as scores, got float, str"),
                                          ({(7, 1): True, (7, 7): 0.1}, "must return numbers as scores")])
def test_protocol_violations_are_reported(spy, bad, message):
    spy.bad_scores = bad
    with pytest.raises(RecognizerError, match=message):
        evaluate(TASK_ID, ["spy"], seeds=1)


def test_unknown_names_fail_before_any_work(spy):
    with pytest.raises(UnknownRecognizerError):
        evaluate(TASK_ID, ["spy", "nope"], seeds=1)
    assert spy.fits == []


def test_bad_arguments():
    with pytest.raises(ValueError, match="observability"):
        evaluate(TASK_ID, ["bc"], observability="0.1,2")
    with pytest.raises(ValueError, match="unknown observation protocol 'middle'"):
        evaluate(TASK_ID, ["bc"], protocol="middle")
    with pytest.raises(ValueError, match="rounding"):
        evaluate(TASK_ID, ["bc"], rounding="half")


def test_random_subsets_are_seeded(spy):
    evaluate(TASK_ID, ["spy"], seeds=1, protocol="subset")
    first = [o.obs.tolist() for o in spy.observed]
    spy.observed.clear()
    evaluate(TASK_ID, ["spy"], seeds=1, protocol="subset")
    assert [o.obs.tolist() for o in spy.observed] == first


@pytest.mark.slow
def test_end_to_end_bc_beats_chance_on_biased_task():
    records = evaluate(TASK_ID, [("bc", {"n_epochs": 10}), ("graql", {"episodes": 1000})], seeds=2)
    bc = [r for r in records if r.recognizer == "bc"]
    assert len(bc) == 3
    assert all(r.f1.mean > 0.8 for r in bc), bc  # chance is 0.5
    assert all(0 <= r.f1.mean <= 1 for r in records)
    assert all(r.fit_seconds_per_goal > 0 and r.score_us_per_observation > 0 for r in records)


def test_several_scorers_share_one_fit_and_loglik_reports_calibration(tmp_path):
    from grail_bench.harness.planning import RecognizerSpec

    records = evaluate(TASK_ID, [RecognizerSpec("bc", {"n_epochs": 3}, ("mse", "wasserstein", "loglik"))],
                       seeds=1, observability=[0.3])
    by_scorer = {r.scorer: r for r in records}
    assert set(by_scorer) == {"mse", "wasserstein", "loglik"}
    assert len({r.fit_seconds_per_goal for r in records}) == 1  # one fit
    assert by_scorer["mse"].brier_mean is None
    assert 0 <= by_scorer["loglik"].brier_mean <= 2 and by_scorer["loglik"].nll_mean >= 0


def test_scorers_need_a_recognizer_that_has_them(spy):
    from grail_bench.harness.planning import RecognizerSpec

    with pytest.raises(ValueError, match="scores with its own default scorer only"):
        evaluate(TASK_ID, [RecognizerSpec("spy", {}, ("mse",))], seeds=1)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["gail", "airl"])
def test_end_to_end_adversarial_beats_chance_on_biased_task(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    budget = {"total_timesteps": 8192, "n_envs": 8, "n_steps": 64}
    records = evaluate(TASK_ID, [(name, budget)], seeds=2)
    assert np.mean([r.f1.mean for r in records]) > 0.6, records  # chance is 0.5
    assert list(tmp_path.iterdir()) == [], "SB3 must not leave logs behind"
