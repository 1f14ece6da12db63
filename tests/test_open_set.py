"""Open set: the held-out goal, the calibrated rule (training data only) and its metrics."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from conftest import FAST, run_mode
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.harness.api import evaluate
from grail_bench.harness.modes.open_set import held_out_goal, open_set_metrics
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.harness.store import OpenSetRow, ResultsStore
from grail_bench.recognizers.registry import register_recognizer, unregister_recognizer

TASK = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")


def test_each_goal_is_held_out_in_turn():
    goals = [(1, 1), (2, 2), (3, 3)]
    assert [held_out_goal(goals, s) for s in range(6)] == goals + goals


def test_two_goals_cannot_hold_one_out():
    with pytest.raises(grail_bench.UserError, match="at least 3 candidate goals"):
        held_out_goal([(1, 1), (2, 2)], 0)


def test_metrics_of_a_hand_made_case():
    # Two known goals (0, 1) and the extra class 2. Best scores below 0.5 are answered "none of these".
    best = np.array([0.9, 0.4, 0.3, 0.6])
    argmax = np.array([0, 1, 0, 1])
    labels = np.array([0, 1, 2, 2])
    m = open_set_metrics(best, argmax, labels, threshold=0.5, n_known=2)
    # Predicted (0, 2, 2, 1): one false alarm of two known, one of two unknown found.
    assert m["false_alarm"] == 0.5 and m["unknown_recall"] == 0.5 and m["accuracy"] == 0.5
    # Unknown best scores (0.3, 0.6) against known (0.9, 0.4): lower in 3 of the 4 pairs.
    assert m["auroc"] == 0.75
    # Per class F1: goal 0: 1, goal 1: 0, none: 1/2.
    assert m["f1"] == pytest.approx((1 + 0 + 0.5) / 3)


class Spy:
    """Remembers what it was fitted on and everything it scored; scores by the distance of the last observed state."""

    name = "open-spy"
    config: dict = {}
    default_scorer = "default"
    fitted: list = []
    scored: list = []

    def exposes(self, action_space):
        return frozenset()

    def fit(self, demos, env_factory, *, seed, cache_key=None):
        Spy.fitted.append(sorted(demos))
        self.goals = list(demos)

    def score(self, observed, scorer=None):
        Spy.scored.append(np.asarray(observed.obs).tobytes())
        last = np.asarray(observed.obs[-1], dtype=float)
        return {g: -float(np.abs(last[:2] - np.asarray(g)).sum()) for g in self.goals}


@pytest.fixture
def spy():
    Spy.fitted, Spy.scored = [], []
    register_recognizer("open-spy", Spy)
    yield Spy
    unregister_recognizer("open-spy")


def _planned(name, config=None):
    return plan(TASK, RecognizerSpec(name, config or {}), TASK.make_env().action_space)


def test_the_held_out_goal_is_never_fitted_but_is_tested(spy):
    demos = TASK.generate_demos(2)
    rows, _ = run_mode("open-set", TASK, _planned("open-spy"), 2, (0.5,), "subset", demos)
    hidden = TASK.goals[2]
    assert spy.fitted == [sorted(g for g in TASK.goals if g != hidden)]
    (row,) = rows
    assert json.loads(row.held_out) == list(hidden)
    assert row.n_observations == sum(len(t) for t in TASK.split(demos)[1].values())


def test_calibration_never_sees_test_trajectories(spy, monkeypatch):
    from grail_bench.harness.modes import open_set

    given = []
    real = open_set.calibrate

    def recording(recognizer, train, *args, **kwargs):
        given.append(train)
        return real(recognizer, train, *args, **kwargs)

    monkeypatch.setattr(open_set, "calibrate", recording)
    demos = TASK.generate_demos(0)
    train, test = TASK.split(demos)
    rows, _ = run_mode("open-set", TASK, _planned("open-spy"), 0, (0.3, 1.0), "subset", demos)
    assert len(given) == 2  # once per level
    for calibration in given:  # only the known goals' training demonstrations
        assert set(calibration) == set(TASK.goals[1:])
        assert all(t is u for g, trajs in calibration.items() for t, u in zip(trajs, train[g], strict=True))
    # Swapping every goal's test trajectories for the next goal's changes the test, never the threshold.
    goals = list(TASK.goals)
    swapped = {g: list(train[g]) + list(test[goals[(i + 1) % len(goals)]]) for i, g in enumerate(goals)}
    again, _ = run_mode("open-set", TASK, _planned("open-spy"), 0, (0.3, 1.0), "subset", swapped)
    assert [r.threshold for r in rows] == [r.threshold for r in again]
    assert [r.auroc for r in rows] != [r.auroc for r in again]


def test_open_set_runs_are_deterministic_and_stored(tmp_path):
    timing = ("fit_seconds_per_goal",)
    with ResultsStore(tmp_path / "r.sqlite") as store:
        records = evaluate(TASK.id, [("bc", FAST["bc"])], seeds=4, mode="open-set", observability=[0.3, 1.0],
                           store=store)
        rows = store.select(OpenSetRow)
    assert len(rows) == 8  # 4 seeds x 2 levels
    assert sorted({r.held_out for r in rows}) == sorted(json.dumps(list(g)) for g in TASK.goals)
    again, _ = run_mode("open-set", TASK, _planned("bc", FAST["bc"]), 0, (0.3, 1.0), "subset", rounding=TASK.rounding)
    first = [r for r in rows if r.seed == 0]
    strip = lambda r: {k: v for k, v in dataclasses.asdict(r).items() if k not in timing + ("provenance", "versions", "task_fingerprint")}  # noqa: E731
    assert [strip(r) for r in first] == [strip(r) for r in again]
    for record in records:
        assert record.n_seeds == 4 and 0 <= record.auroc_mean <= 1 and 0 <= record.f1_mean <= 1


def test_cli_open_set_run_and_leaderboard(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))
    store = tmp_path / "r.sqlite"
    runner = CliRunner()
    result = runner.invoke(app, ["run", "-t", TASK.id, "-r", "bc", "--set", "bc.n_epochs=3", "--open-set",
                                 "--seeds", "2", "-o", "0.5", "--store", str(store), "--no-progress"])
    assert result.exit_code == 0, result.output
    assert "open set" in result.output
    result = runner.invoke(app, ["leaderboard", "--open-set", "--store", str(store)])
    assert result.exit_code == 0 and "AUROC" in result.output
