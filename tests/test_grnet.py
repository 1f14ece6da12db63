"""GRNet (grail_bench.contrib.grnet): recognition, posteriors, prefixes, channels, caching, errors, the CLI.

The contract's conformance tests (tests/test_recognizers.py) cover it through its entry point: the protocol, same
seed same scores, one-line errors for malformed observations and scoring before fitting.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.special import logsumexp

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Trajectory
from grail_bench.harness.modes.online import head
from grail_bench.recognizers import make_recognizer
from grail_bench.task.observation import observe, project

TINY = {"epochs": 3, "draws": 10}
TASK = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
TRAIN, TEST = TASK.split(TASK.generate_demos(seed=0))


@pytest.fixture(scope="module")
def fitted():
    rec = make_recognizer("grnet", **TINY)
    rec.fit(TRAIN, TASK.make_env, seed=0)
    return rec


def accuracy(rec, levels=(0.3, 0.5, 1.0), channel="pairs") -> float:
    """Top-1 accuracy on the held-out demonstrations, observed under the task's protocol (ties share the hit)."""
    rng = np.random.default_rng(0)
    hits = []
    for level in levels:
        for goal, trajs in TEST.items():
            for traj in trajs:
                scores = rec.score(project(observe(traj, level, rng=rng, task=TASK), channel))
                best = max(scores.values())
                top = [g for g, v in scores.items() if v == best]
                hits.append((goal in top) / len(top))
    return float(np.mean(hits))


def test_grnet_beats_chance_on_four_minigrid_goals(fitted):
    assert accuracy(fitted) >= 0.5  # chance is 1/4
    untrained = make_recognizer("grnet", **{**TINY, "learning_rate": 1e-9})  # the same network, as initialised
    untrained.fit(TRAIN, TASK.make_env, seed=0)
    assert accuracy(untrained) < accuracy(fitted) - 0.2


def test_scores_are_a_log_posterior_over_the_fitted_goals(fitted):
    scores = fitted.score(observe(TEST[TASK.goals[1]][0], 0.5, rng=np.random.default_rng(0), task=TASK))
    assert set(scores) == set(TASK.goals)
    assert all(v <= 0 for v in scores.values())
    assert logsumexp(list(scores.values())) == pytest.approx(0.0, abs=1e-6)


def test_every_prefix_from_one_pass_scores_as_that_prefix_alone(fitted):
    observed = observe(TEST[TASK.goals[2]][0], 1.0, "prefix")
    for channel in ("pairs", "states", "actions"):
        shown = project(observed, channel)
        prefixes = fitted.score_prefixes(shown)
        assert all(v.shape == (len(observed.acts),) for v in prefixes.values())
        for k in (1, len(observed.acts) // 2, len(observed.acts)):
            alone = fitted.score(head(shown, k))
            assert [prefixes[g][k - 1] for g in TASK.goals] == pytest.approx([alone[g] for g in TASK.goals], abs=1e-5)


def test_states_and_actions_channels_are_scored_and_a_channel_not_trained_on_is_refused(fitted):
    assert fitted.channels == {"pairs", "states", "actions"}
    for channel in ("states", "actions"):
        assert accuracy(fitted, levels=(1.0,), channel=channel) > 0.25
    pairs_only = make_recognizer("grnet", **TINY, train_channels=("pairs",))
    pairs_only.fit(TRAIN, TASK.make_env, seed=0)
    with pytest.raises(UserError, match="trained on the pairs channel") as err:
        pairs_only.score(project(observe(TEST[TASK.goals[0]][0], 0.5, "prefix"), "states"))
    assert "\n" not in str(err.value)


def test_the_trained_network_is_cached_and_reloaded(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    observed = observe(TEST[TASK.goals[0]][0], 0.4, "prefix")
    first = make_recognizer("grnet", **TINY)
    assert first.fit(TRAIN, TASK.make_env, seed=0, cache_key="minigrid").trained == 1
    second = make_recognizer("grnet", **TINY)
    report = second.fit(TRAIN, TASK.make_env, seed=0, cache_key="minigrid")
    assert (report.trained, report.reused) == (0, 1) and report.train_seconds > 0
    assert second.score(observed) == first.score(observed)
    other_seed = make_recognizer("grnet", **TINY)
    assert other_seed.fit(TRAIN, TASK.make_env, seed=1, cache_key="minigrid").trained == 1
    assert other_seed.score(observed) != first.score(observed)


@pytest.mark.parametrize(("settings", "message"), [
    ({"epochs": 0}, "epochs"),
    ({"hidden": 10**6}, "out of range"),
    ({"min_level": 0.0}, "min_level"),
    ({"protocols": ("nearby",)}, "unknown observation protocol"),
    ({"protocols": ()}, "at least one"),
    ({"train_channels": ("colour",)}, "train_channels"),
    ({"learning_rate": -1.0}, "learning_rate"),
    ({"width": 3}, "width"),
])
def test_bad_settings_are_one_line_errors(settings, message):
    with pytest.raises(UserError, match=message) as err:
        make_recognizer("grnet", **settings)
    assert "\n" not in str(err.value)


def test_bad_fits_and_observations_are_one_line_errors(fitted):
    cases = [
        (lambda: make_recognizer("grnet").fit({TASK.goals[0]: TRAIN[TASK.goals[0]]}, TASK.make_env), "two goals"),
        (lambda: make_recognizer("grnet").fit(TRAIN), "env factory"),
        (lambda: make_recognizer("grnet").fit({**TRAIN, TASK.goals[0]: []}, TASK.make_env), "no demonstrations"),
        (lambda: make_recognizer("grnet").score(observe(TEST[TASK.goals[0]][0], 0.5, "prefix")), "fit"),
        (lambda: fitted.score(SimpleNamespace(obs=np.zeros((1, 3)), acts=np.zeros(0))), "empty"),
        (lambda: fitted.score(Trajectory(obs=np.full((3, 3), 99), acts=np.zeros(2, int), infos=None,
                                         terminal=False)), "observed states"),
    ]
    for call, message in cases:
        with pytest.raises(UserError, match=message) as err:
            call()
        assert "\n" not in str(err.value)


@pytest.mark.slow
def test_grnet_runs_end_to_end_from_the_command_line(tmp_path):
    env = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_STORE": str(tmp_path / "store.sqlite"),
           "GRAIL_BENCH_CACHE": str(tmp_path / "cache")}
    run = [sys.executable, "-m", "grail_bench", "run", "-t", "GRAIL/MiniGrid-Optimal-4Goals-v0", "-r", "grnet",
           "--seeds", "1", "--no-progress"]
    out = subprocess.run([*run, "--set", "grnet.epochs=2", "--set", "grnet.draws=5", "--json",
                          str(tmp_path / "r.json")], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr
    records = json.loads((tmp_path / "r.json").read_text())
    assert {r["recognizer"] for r in records} == {"grnet"}
    assert {r["observability"] for r in records} == set(TASK.observability)
    assert all(0 <= r["f1_mean"] <= 1 for r in records)
    bad = subprocess.run([*run, "--set", "grnet.epochs=0"], capture_output=True, text=True, env=env, timeout=600)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "epochs" in bad.stderr


@pytest.mark.parametrize("task_id", ["GRAIL/PointMaze-Biased-v0", "GRAIL/Symbolic-Grid-Optimal-v0"])
def test_grnet_recognises_continuous_and_symbolic_tasks(task_id):
    task = grail_bench.make_task(task_id)
    train, test = task.split(task.generate_demos(seed=0))
    rec = make_recognizer("grnet", epochs=3, draws=5)
    rec.fit(train, task.make_env, seed=0)
    rng = np.random.default_rng(0)
    hits = [max(scores, key=scores.get) == goal for goal, trajs in test.items() for traj in trajs
            for scores in [rec.score(observe(traj, 1.0, rng=rng, task=task))]]
    assert np.mean(hits) >= 0.5  # chance is 1/5 and 1/3
