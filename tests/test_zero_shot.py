"""Many-goal tasks, the goal-conditioned GC-BC and the zero-shot mode (goals without training demonstrations)."""

from __future__ import annotations

import dataclasses
import json
import sqlite3
import time

import numpy as np
import pytest
from conftest import run_mode
from gymnasium import spaces
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.harness.api import evaluate
from grail_bench.harness.modes import MODES
from grail_bench.harness.modes.zero_shot import held_out_goals, n_held_out
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.harness.store import SCHEMA_VERSION, ResultsStore, ZeroShotRow
from grail_bench.core.scaling import scale_of
from grail_bench.recognizers.gcbc import GCBCRecognizer, GoalEncoder
from grail_bench.recognizers.registry import register_recognizer, unregister_recognizer
from grail_bench.task.observation import observe

OPTIMAL = ["GRAIL/MiniGrid-Optimal-v0"] + [f"GRAIL/MiniGrid-Optimal-{k}Goals-v0" for k in (4, 6, 12, 24)]
TINY = {"n_batches": 300}


def test_each_goal_set_is_a_superset_of_the_smaller_ones():
    sets = [grail_bench.make_task(t).goals for t in OPTIMAL]
    assert [len(s) for s in sets] == [2, 4, 6, 12, 24]
    for small, large in zip(sets, sets[1:]):
        assert set(small) < set(large)
    for goals in sets:
        assert len(set(goals)) == len(goals)
    for small, large in (("GRAIL/PandaReach-Gaussian-0.1-v0", "GRAIL/PandaReach-Gaussian-0.1-8Goals-v0"),
                         ("GRAIL/PandaReach-Gaussian-0.1-8Goals-v0", "GRAIL/PandaReach-Gaussian-0.1-12Goals-v0"),
                         ("GRAIL/PointMaze-Optimal-v0", "GRAIL/PointMaze-Optimal-10Goals-v0")):
        assert set(grail_bench.make_task(small).goals) < set(grail_bench.make_task(large).goals)


def test_goals_shared_across_sets_get_the_same_demonstrations():
    """Demonstrations are keyed by goal: a goal's are the same in every task that lists it."""
    six, twelve = (grail_bench.make_task(t) for t in OPTIMAL[2:4])
    a, b = six.generate_demos(1), twelve.generate_demos(1)
    for goal in six.goals:
        assert [t.acts.tolist() for t in a[goal]] == [t.acts.tolist() for t in b[goal]]


def test_gc_bc_does_not_depend_on_the_order_goals_are_listed_in():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    train, test = task.split(task.generate_demos(0))
    observed = observe(test[task.goals[0]][0], 0.3, "prefix")
    scores = []
    for goals in (list(task.goals), list(reversed(task.goals))):
        recognizer = GCBCRecognizer(**TINY)
        recognizer.fit({g: train[g] for g in goals}, task.env_factory(), seed=3)
        scores.append(recognizer.score(observed))
    assert set(scores[0]) == set(task.goals)
    for goal in task.goals:
        assert scores[0][goal] == pytest.approx(scores[1][goal], abs=1e-6)


def test_a_goal_coordinate_every_goal_shares_is_not_blown_up_by_rounding():
    # gr_libs' PandaReach goals all lie at z = 0.1, whose spread computes to ~1e-17, not 0: dividing by it made the
    # goal features ~1e16 and every goal's policy the same (every observation a tie).
    goals = [(-0.1, -0.1, 0.1), (-0.1, 0.1, 0.1), (0.2, 0.2, 0.1)]
    assert 0 < np.asarray(goals).std(axis=0)[2] < 1e-15
    np.testing.assert_array_equal(scale_of(np.asarray(goals))[2], 1.0)
    encoder = GoalEncoder(spaces.Box(-1.0, 1.0, (3,)), goals)
    features = encoder.goal_features(goals)
    assert np.all(np.abs(features) < 3) and len({tuple(f) for f in features.tolist()}) == 3


def test_gc_bc_scores_a_goal_it_was_never_fitted_on():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
    train, test = task.split(task.generate_demos(0))
    recognizer = GCBCRecognizer(**TINY)
    recognizer.fit({g: train[g] for g in task.goals[:4]}, task.env_factory(), seed=0)
    recognizer.set_goals(task.goals)
    scores = recognizer.score(observe(test[task.goals[5]][0], 0.2, "prefix"))
    assert set(scores) == set(task.goals) and all(np.isfinite(list(scores.values())))
    with pytest.raises(grail_bench.UserError, match="2 coordinates"):
        recognizer.set_goals([(1, 2, 3)])


def test_a_third_of_the_goals_are_held_out_whatever_their_order():
    goals = grail_bench.make_task(OPTIMAL[-1]).goals
    assert [n_held_out(k) for k in (3, 6, 12, 24)] == [1, 2, 4, 8]
    for seed in range(3):
        hidden = held_out_goals(goals, seed)
        assert len(hidden) == 8 and set(hidden) <= set(goals)
        assert hidden == held_out_goals(list(reversed(goals)), seed)
    assert len({tuple(held_out_goals(goals, s)) for s in range(5)}) > 1  # seeds hold out different goals


class GoalSpy:
    """Records the goals it was fitted on and the candidate goals it was given; scores by the last state."""

    name = "zero-spy"
    config: dict = {}
    default_scorer = "default"
    fitted: list = []
    told: list = []

    def exposes(self, action_space):
        return frozenset()

    def fit(self, demos, env_factory, *, seed, cache_key=None):
        GoalSpy.fitted.append(sorted(demos))
        self.goals = list(demos)

    def set_goals(self, goals):
        GoalSpy.told.append(list(goals))
        self.goals = list(goals)

    def score(self, observed, scorer=None):
        last = np.asarray(observed.obs[-1], dtype=float)
        return {g: -float(np.abs(last[:2] - np.asarray(g)).sum()) for g in self.goals}


@pytest.fixture
def goal_spy():
    GoalSpy.fitted, GoalSpy.told = [], []
    register_recognizer("zero-spy", GoalSpy)
    yield GoalSpy
    unregister_recognizer("zero-spy")


def test_held_out_goals_never_reach_fit_but_are_tested(goal_spy):
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
    planned = plan(task, RecognizerSpec("zero-spy", {}), task.make_env().action_space)
    rows, _ = run_mode("zero-shot", task, planned, 4, (1.0,), "subset")
    hidden = held_out_goals(task.goals, 4)
    assert goal_spy.fitted == [sorted(g for g in task.goals if g not in hidden)]
    assert goal_spy.told == [list(task.goals)]
    (row,) = rows
    assert json.loads(row.held_out) == [list(g) for g in hidden]
    assert row.n_observations == sum(len(t) for t in task.split(task.generate_demos(4))[1].values())
    # The last observed state is the goal at full observability: this spy recognises every goal, held out or not.
    assert row.accuracy_held_out == 1.0 and row.f1 == 1.0


def test_a_per_goal_recognizer_is_refused_before_any_work(tmp_path):
    result = CliRunner().invoke(app, ["run", "-t", OPTIMAL[2], "-r", "bc", "--mode", "zero-shot",
                                      "--store", str(tmp_path / "r.sqlite"), "--no-progress"])
    assert result.exit_code == 2
    assert "zero-shot mode scores goals without demonstrations" in result.output
    if (tmp_path / "r.sqlite").exists():
        with ResultsStore(tmp_path / "r.sqlite") as store:
            assert store.select(ZeroShotRow) == []


def test_mode_flags_conflict_and_unknown_modes_are_one_line_errors(tmp_path):
    runner = CliRunner()
    both = runner.invoke(app, ["run", "--online", "--mode", "zero-shot", "--store", str(tmp_path / "r.sqlite")])
    assert both.exit_code == 2 and "choose one mode" in both.output
    unknown = runner.invoke(app, ["run", "--mode", "zero", "--store", str(tmp_path / "r.sqlite")])
    assert unknown.exit_code == 2 and "unknown mode 'zero'" in unknown.output


def test_tiny_budget_zero_shot_beats_chance_on_held_out_goals(tmp_path):
    """24 goals, 8 of them never fitted: GC-BC still recognises the held-out goals far above chance (1/24)."""
    records = evaluate(OPTIMAL[-1], [("gc-bc", TINY)], seeds=2, mode="zero-shot", observability=[1.0],
                       store=None)
    (record,) = records
    assert record.n_seeds == 2 and record.n_goals == 24
    assert record.accuracy_held_out_mean > 3 / 24
    assert record.f1_trained_mean > 3 / 24


def test_cli_zero_shot_run_and_leaderboard(tmp_path):
    store = tmp_path / "r.sqlite"
    runner = CliRunner()
    result = runner.invoke(app, ["run", "-t", OPTIMAL[2], "-r", "gc-bc", "--set", "gc-bc.n_batches=100",
                                 "--mode", "zero-shot", "--seeds", "1", "-o", "0.5", "--store", str(store),
                                 "--no-progress"])
    assert result.exit_code == 0, result.output
    assert "zero-shot" in result.output
    result = runner.invoke(app, ["leaderboard", "--mode", "zero-shot", "--store", str(store)])
    assert result.exit_code == 0 and "zero-shot goals" in result.output
    with ResultsStore(store) as opened:
        (row,) = opened.select(ZeroShotRow)
    assert (row.recognizer, row.n_goals, len(json.loads(row.held_out))) == ("gc-bc", 6, 2)
    empty = runner.invoke(app, ["leaderboard", "--online", "--store", str(store)])
    assert empty.exit_code == 2 and "--mode online" in empty.output


class SlowAdaptingSpy(GoalSpy):
    """A :class:`GoalSpy` whose adaptation to the candidate goals takes a known time."""

    name = "slow-spy"
    ADAPT_SECONDS = 0.05

    def set_goals(self, goals):
        time.sleep(self.ADAPT_SECONDS)
        super().set_goals(goals)


def test_zero_shot_rows_carry_the_three_times_gr_libs_reports(goal_spy):
    """Learning (fit s/goal), adaptation (set_goals, per new goal) and inference (µs per observation) per row."""
    register_recognizer("slow-spy", SlowAdaptingSpy)
    try:
        task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
        planned = plan(task, RecognizerSpec("slow-spy", {}), task.make_env().action_space)
        rows, _ = run_mode("zero-shot", task, planned, 4, (0.5, 1.0), "subset")
    finally:
        unregister_recognizer("slow-spy")
    new_goals = n_held_out(len(task.goals))
    assert len(rows) == 2 and rows[0].adapt_seconds_per_goal == rows[1].adapt_seconds_per_goal  # one set_goals
    # The call's time shared out over the held-out goals (2 of 6), not over every candidate goal.
    assert SlowAdaptingSpy.ADAPT_SECONDS / new_goals <= rows[0].adapt_seconds_per_goal < 1.0
    assert all(r.score_us_per_observation > 0 and r.fit_seconds_per_goal >= 0 for r in rows)
    (record,) = [r for r in MODES["zero-shot"].aggregate(rows) if r.observability == 1.0]
    assert record.adapt_seconds_per_goal == pytest.approx(rows[1].adapt_seconds_per_goal)
    shown = {c.header: c.text(record) for c in MODES["zero-shot"].columns}  # what every report of the mode shows
    # shown to two significant digits: within 5 % of the record whatever the timing
    assert float(shown["adapt s/new goal"]) == pytest.approx(record.adapt_seconds_per_goal, rel=0.05)
    assert float(shown["µs / observation"]) > 0 and "fit s/goal" in shown


def _schema_8(path):
    """Make ``path`` a schema-8 store: its zero-shot table as it was before the times were recorded."""
    conn = sqlite3.connect(path)
    for column in ("adapt_seconds_per_goal", "score_us_per_observation"):
        conn.execute(f"ALTER TABLE zero_shot DROP COLUMN {column}")
    conn.execute("PRAGMA user_version = 8")
    conn.commit()
    conn.close()


def test_a_store_from_before_the_times_keeps_its_zero_shot_rows(tmp_path):
    """Migrating a schema-8 store adds the columns empty: every stored row is kept as it was, and still counts as
    done; the leaderboard shows its missing times as '-'."""
    path = tmp_path / "old.sqlite"
    old = ZeroShotRow(task="GRAIL/T-v0", recognizer="gc-bc", scorer="mse", config_hash="abc", seed=0,
                      observability=0.5, protocol="subset", held_out="[[7, 3]]", n_goals=3, f1=0.6, accuracy=0.7,
                      f1_held_out=0.4, f1_trained=0.7, accuracy_held_out=0.5, accuracy_trained=0.8, n_observations=9,
                      fit_seconds_per_goal=0.25, config="{}", versions="{}", n_ties=0)
    with ResultsStore(path) as store:
        store.add([old])
    _schema_8(path)
    before = sqlite3.connect(path).execute("SELECT * FROM zero_shot").fetchall()
    with ResultsStore(path, read_only=True) as store:  # reading upgrades a copy in memory only
        assert store.select(ZeroShotRow) == [old]
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == 8
    with ResultsStore(path) as store:
        (kept,) = store.select(ZeroShotRow)
        assert kept == old and kept.adapt_seconds_per_goal is None and kept.score_us_per_observation is None
        assert store.completed("GRAIL/T-v0", "gc-bc", "mse", "abc", "subset", ZeroShotRow) == {(0, 0.5)}
        assert store.add([dataclasses.replace(old, f1=0.1, adapt_seconds_per_goal=1.0)]) == 0  # first write wins
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    new = ("adapt_seconds_per_goal", "score_us_per_observation")
    columns = [r[1] for r in conn.execute("PRAGMA table_info(zero_shot)")]
    assert columns[-2:] == list(new)
    after = conn.execute(f"SELECT {', '.join(columns[:-2])} FROM zero_shot").fetchall()
    assert after == before  # the stored values, created_at included, untouched
    (record,) = MODES["zero-shot"].aggregate([kept])
    assert record.adapt_seconds_per_goal is None
    assert [c.text(record) for c in MODES["zero-shot"].columns][-3:] == ["0.25", "-", "-"]
