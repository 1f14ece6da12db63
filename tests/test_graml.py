"""GRAML and GC-GRAML (grail_bench.contrib.graml): the learnt metric, recognition, zero-shot goals, caching, errors.

The contract's conformance tests (tests/test_recognizers.py) cover both through their entry points: the
protocol, same seed same scores, one-line errors for malformed observations and scoring before fitting.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from gymnasium import spaces
from grail_bench.core.trajectory import Trajectory

import grail_bench
from grail_bench.contrib.graml import GRAMLRecognizer
from grail_bench.recognizers import build, make_recognizer
from grail_bench.task.observation import observe

TINY = {"n_pairs": 300, "n_epochs": 3}
TASK = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
TRAIN, TEST = TASK.split(TASK.generate_demos(seed=0))

TOY_SPACES = SimpleNamespace(observation_space=spaces.Box(-50.0, 50.0, (4,), np.float32),
                             action_space=spaces.Box(-5.0, 5.0, (2,), np.float32), close=lambda: None)


def toy_demos(rng: np.random.Generator, n: int) -> dict[tuple[float, ...], list[Trajectory]]:
    """Two goals, ``n`` 12-step sequences each: the first state coordinate drifts up (goal (1,)) or down (goal
    (-1,)); the other three coordinates and the actions are noise of larger spread, the same for both goals."""
    demos = {}
    for goal, drift in (((1.0,), 0.3), ((-1.0,), -0.3)):
        walks = []
        for _ in range(n):
            obs = rng.normal(0, 1, (13, 4))
            obs[:, 0] = drift * np.arange(13) + rng.normal(0, 0.3, 13)
            acts = np.clip(rng.normal(0, 1, (12, 2)), -5, 5)
            walks.append(Trajectory(obs=obs.astype(np.float32), acts=acts.astype(np.float32), infos=None,
                                    terminal=True))
        demos[goal] = walks
    return demos


def separation(rec: GRAMLRecognizer) -> tuple[float, float]:
    """On held-out toy sequences observed for their first 4 of 12 steps: the mean same-goal embedding distance
    over the mean other-goal one, and the share of sequences whose nearest other sequence pursues their goal."""
    held_out = toy_demos(np.random.default_rng(1), 6)
    embedded = np.stack([rec.embed(walk.obs[:4], walk.acts[:4]) for walks in held_out.values() for walk in walks])
    distance = np.abs(embedded[:, None] - embedded[None]).sum(-1)
    same = np.equal.outer(np.arange(12) // 6, np.arange(12) // 6)
    np.fill_diagonal(distance, np.inf)
    nearest = distance.argmin(axis=1)
    return (distance[same & np.isfinite(distance)].mean() / distance[~same].mean(),
            float(np.mean(same[np.arange(12), nearest])))


def test_the_learnt_metric_puts_held_out_sequences_of_a_goal_closer_than_those_of_the_other():
    trained = GRAMLRecognizer(**TINY)
    trained.fit(toy_demos(np.random.default_rng(0), 8), lambda goal: TOY_SPACES, seed=0)
    ratio, neighbours = separation(trained)
    assert ratio < 0.5 and neighbours == 1.0
    untrained = GRAMLRecognizer(**{**TINY, "learning_rate": 1e-9})  # the same network, left as initialised
    untrained.fit(toy_demos(np.random.default_rng(0), 8), lambda goal: TOY_SPACES, seed=0)
    ratio, neighbours = separation(untrained)
    assert ratio > 0.8 and neighbours < 0.9  # the noise dominates until the metric is learnt


@pytest.mark.parametrize("protocol", ["prefix", "subset"])
def test_graml_recognises_held_out_minigrid_demonstrations(protocol):
    rec = make_recognizer("graml", **TINY)
    rec.fit(TRAIN, TASK.make_env, seed=0)
    rng = np.random.default_rng(0)
    hits = []
    for goal, trajs in TEST.items():
        for traj in trajs:
            scores = rec.score(observe(traj, 1.0, protocol, rng))
            hits.append(max(scores, key=scores.get) == goal)
    assert np.mean(hits) >= 5 / 6  # chance is 1/2


def test_gc_graml_scores_goals_it_has_no_demonstrations_of():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    train, test = task.split(task.generate_demos(seed=0))
    fitted, new = list(task.goals[:3]), task.goals[3]
    rec = make_recognizer("gc-graml", gc_batches=300, n_rollouts=3, **TINY)
    rec.fit({g: train[g] for g in fitted}, task.make_env, seed=0)
    observed = observe(test[new][0], 1.0)
    assert set(rec.score(observed)) == set(fitted)
    rec.set_goals(task.goals)
    scores = rec.score(observed)
    assert set(scores) == set(task.goals) and all(np.isfinite(list(scores.values())))
    again = make_recognizer("gc-graml", gc_batches=300, n_rollouts=3, **TINY)
    again.fit({g: train[g] for g in fitted}, task.make_env, seed=0)
    again.set_goals(task.goals)
    assert again.score(observed) == scores  # the new goal's references are seeded too
    with pytest.raises(grail_bench.UserError, match="2 coordinates"):
        rec.set_goals([(1, 2, 3)])


def test_only_gc_graml_takes_new_goals():
    assert build("gc-graml").has_set_goals and not build("graml").has_set_goals
    with pytest.raises(RuntimeError, match="fit"):
        make_recognizer("gc-graml").set_goals(TASK.goals)


def test_the_metric_is_cached_and_reloaded(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    observed = observe(TEST[(7, 7)][0], 0.3)
    first, second = (make_recognizer("graml", **TINY) for _ in range(2))
    report = first.fit(TRAIN, TASK.make_env, seed=0, cache_key="minigrid")
    assert (report.trained, report.reused) == (1, 0)
    report = second.fit(TRAIN, TASK.make_env, seed=0, cache_key="minigrid")
    assert (report.trained, report.reused) == (0, 1) and report.train_seconds > 0
    assert first.score(observed) == second.score(observed)
    scored_apart = make_recognizer("graml", aggregate="min", **TINY)  # a scoring setting shares the model
    assert scored_apart.fit(TRAIN, TASK.make_env, seed=0, cache_key="minigrid").reused == 1


@pytest.mark.parametrize(("settings", "message"), [
    ({"n_pairs": 0}, r"n_pairs=0 is out of range \(allowed 1\.\."),
    ({"fractions": [0.5, 1.5]}, "fractions in"),
    ({"inputs": "pixels"}, "inputs expects one of"),
    ({"hiden": 8}, "unexpected keyword argument 'hiden'"),
])
def test_bad_settings_are_one_line_errors(settings, message):
    with pytest.raises(grail_bench.UserError, match=message):
        make_recognizer("graml", **settings)


def test_bad_demonstrations_and_observations_are_one_line_errors():
    rec = GRAMLRecognizer(**TINY)
    with pytest.raises(grail_bench.UserError, match="at least two goals"):
        rec.fit({(7, 1): TRAIN[(7, 1)]}, TASK.make_env)
    with pytest.raises(grail_bench.UserError, match=r"goal \(7, 7\) has no demonstrations"):
        rec.fit({(7, 1): TRAIN[(7, 1)], (7, 7): []}, TASK.make_env)
    rec.fit(toy_demos(np.random.default_rng(0), 3), lambda goal: TOY_SPACES)
    walk = toy_demos(np.random.default_rng(1), 1)[(1.0,)][0]
    broken = Trajectory(obs=np.where(np.arange(13)[:, None] == 2, np.nan, walk.obs), acts=walk.acts, infos=None,
                        terminal=True)
    with pytest.raises(grail_bench.UserError, match="outside the env's space"):
        rec.score(broken)
