"""Online mode: every prefix scored in one pass, equal to offline scoring at the same k; its metrics."""

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
from grail_bench.harness.executors import SerialExecutor
from grail_bench.harness.modes.online import (
    GRID,
    convergence,
    curves,
    f1_auc,
    head,
    online_metrics,
    prefix_scores,
)
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.harness.store import OnlineRow, ResultsStore
from grail_bench.recognizers import capabilities, make_recognizer
from grail_bench.task.observation import observe

TASK = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-6Goals-v1")
DEMOS = TASK.generate_demos(0)
TRAIN, TEST = TASK.split(DEMOS)


@pytest.mark.parametrize("correct, expected", [
    ([False, False, True, True], (0.75, True)),
    ([True, True, True], (1 / 3, True)),
    ([True, False, True], (1.0, True)),  # right only after the last step: converged at T
    ([True, True, False], (1.0, False)),  # wrong at the end: never
    ([False], (1.0, False)),
    ([True], (1.0, True)),
])
def test_convergence_point_of_hand_made_sequences(correct, expected):
    assert convergence(correct) == pytest.approx(expected)


def test_metrics_of_hand_made_score_sequences():
    # Two trajectories of goal 0 against 2 goals, scores after each step (rows: k = 1..T).
    settles = np.array([[0.1, 0.5], [0.4, 0.3], [0.6, 0.2]])  # wrong, right, right: converges at k = 2 of 3
    flips = np.array([[0.9, 0.1], [0.2, 0.3]])  # right, then wrong at the end: never
    predictions = [np.argmax(settles, axis=1), np.argmax(flips, axis=1)]
    m = online_metrics(predictions, [0, 0], 2)
    assert m["convergence"] == pytest.approx((2 / 3 + 1.0) / 2)
    assert m["never"] == 0.5
    assert m["step_accuracy"] == pytest.approx((2 / 3 + 1 / 2) / 2)
    curve = json.loads(m["curve"])
    assert curve["accuracy"][curve["fractions"].index(1.0)] == 0.5  # the last predictions: right, wrong


def test_convergence_of_nothing_is_an_error():
    with pytest.raises(ValueError):
        convergence([])


def test_f1_area_of_a_hand_made_case():
    # A (goal 0, T = 2) is wrong after one step and right after two; B (goal 1, T = 1) is always right.
    # (0, 1/2]: predictions (1, 1), macro F1 = (0 + 2/3) / 2; (1/2, 1]: all right, F1 = 1.
    predictions, labels = [np.array([1, 0]), np.array([1])], [0, 1]
    assert f1_auc(predictions, labels, 2) == pytest.approx(0.5 * (1 / 3) + 0.5 * 1.0)


def test_f1_area_is_the_limit_of_a_fine_grid(rng):
    predictions = [rng.integers(0, 3, size=int(rng.integers(1, 12))) for _ in range(15)]
    labels = rng.integers(0, 3, size=15).tolist()
    fractions = (np.arange(20000) + 0.5) / 20000
    for rounding in ("ceil", "floor"):
        _, f1 = curves(predictions, labels, 3, fractions, rounding)
        assert f1_auc(predictions, labels, 3, rounding) == pytest.approx(f1.mean(), abs=2e-3)


@pytest.fixture(scope="module")
def fitted():
    out = {}
    for name in ("bc", "graql"):
        out[name] = make_recognizer(name, **FAST[name])
        out[name].fit(TRAIN, TASK.make_env, seed=0)
    return out


@pytest.mark.parametrize("name, scorers", [("bc", ("mse", "wasserstein", "loglik")),
                                           ("graql", ("kl", "mse", "loglik"))])
def test_prefix_scores_equal_scoring_each_prefix(fitted, name, scorers):
    rec = fitted[name]
    observed = observe(TEST[TASK.goals[2]][0], 1.0, "prefix")
    for scorer in scorers:
        all_prefixes = prefix_scores(capabilities(rec, name), observed, scorer, TASK.goals)
        assert all_prefixes.shape == (len(observed.acts), 6)
        for k in range(1, len(observed.acts) + 1):
            one = rec.score(head(observed, k), scorer)
            np.testing.assert_allclose(all_prefixes[k - 1], [one[g] for g in TASK.goals], rtol=1e-5, atol=1e-6)


def test_continuous_prefix_scores_equal_scoring_each_prefix():
    task = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0", n_demos=2, n_train=1)
    train, test = task.split(task.generate_demos(0))
    rec = make_recognizer("bc", n_epochs=1)
    rec.fit(train, task.make_env, seed=0)
    observed = observe(test[task.goals[0]][0], 0.2, "prefix")
    for scorer in ("mse", "wasserstein", "loglik"):
        all_prefixes = prefix_scores(capabilities(rec, "bc"), observed, scorer, task.goals)
        for k in (1, len(observed.acts) // 2, len(observed.acts)):
            one = rec.score(head(observed, k), scorer)
            np.testing.assert_allclose(all_prefixes[k - 1], [one[g] for g in task.goals], rtol=1e-5, atol=1e-6)


class Counting:
    """A plugin-style recognizer without ``score_prefixes``: the harness must score each prefix."""

    name = "counting"
    config: dict = {}
    default_scorer = "default"
    lengths: list = []

    def exposes(self, action_space):
        return frozenset()

    def fit(self, demos, env_factory, *, seed, cache_key=None):
        self.goals = list(demos)

    def score(self, observed, scorer=None):
        Counting.lengths.append(len(observed.acts))
        return {g: float(i == len(observed.acts) % len(self.goals)) for i, g in enumerate(self.goals)}


def test_recognizers_without_prefix_scoring_are_asked_per_prefix():
    rec = Counting()
    rec.fit(TRAIN, None, seed=0)
    Counting.lengths = []
    observed = observe(TEST[TASK.goals[0]][0], 1.0, "prefix")
    scores = prefix_scores(capabilities(rec, "counting"), observed, None, TASK.goals)
    assert Counting.lengths == list(range(1, len(observed.acts) + 1))
    assert scores.argmax(axis=1).tolist() == [k % 6 for k in range(1, len(observed.acts) + 1)]


@pytest.mark.parametrize("protocol, levels", [("prefix", (0.1, 0.3, 0.5, 0.85, 1.0)), ("subset", (1.0,))])
def test_online_equals_offline_at_the_same_k(protocol, levels):
    spec = RecognizerSpec("bc", FAST["bc"], ("mse", "loglik"))
    planned = plan(TASK, spec, TASK.make_env().action_space)
    offline, _ = run_mode("offline", TASK, planned, 0, levels, protocol, DEMOS)
    online, _ = run_mode("online", TASK, planned, 0, (), protocol, DEMOS)
    assert {r.scorer for r in online} == {"mse", "loglik"}
    for row in online:
        curve = json.loads(row.curve)
        for r in (r for r in offline if r.scorer == row.scorer):
            i = curve["fractions"].index(r.observability)
            assert curve["f1"][i] == pytest.approx(r.f1, abs=1e-6)
            assert curve["accuracy"][i] == pytest.approx(r.accuracy, abs=1e-6)


def test_online_rows_are_deterministic_and_consistent():
    spec = RecognizerSpec("graql", FAST["graql"])
    planned = plan(TASK, spec, TASK.make_env().action_space)
    timing = ("fit_seconds_per_goal", "score_us_per_prefix")
    first, second = (run_mode("online", TASK, planned, 1, (), "subset")[0] for _ in range(2))
    strip = [{k: v for k, v in dataclasses.asdict(r).items() if k not in timing} for r in first]
    assert strip == [{k: v for k, v in dataclasses.asdict(r).items() if k not in timing} for r in second]
    (row,) = first
    assert row.n_trajectories == sum(len(t) for t in TEST.values())
    assert 0 < row.convergence <= 1 and 0 <= row.never <= 1 and 0 <= row.step_accuracy <= 1
    assert len(json.loads(row.curve)["accuracy"]) == len(GRID)


def test_online_runs_are_stored_resumed_and_aggregated(tmp_path):
    with ResultsStore(tmp_path / "r.sqlite") as store:
        records = evaluate(TASK.id, [("graql", FAST["graql"])], seeds=2, mode="online", store=store)
        assert len(store.select(OnlineRow)) == 2 and store.rows() == []
        again = evaluate(TASK.id, [("graql", FAST["graql"])], seeds=2, mode="online", store=store)
    assert again == records
    (record,) = records
    assert record.n_seeds == 2 and record.seeds == [0, 1]
    assert record.accuracy_curve_low[-1] <= record.accuracy_curve[-1] <= record.accuracy_curve_high[-1]
    assert record.convergence_ci95_low <= record.convergence_mean <= record.convergence_ci95_high


def test_online_takes_no_levels():
    with pytest.raises(grail_bench.UserError, match="no observability"):
        evaluate(TASK.id, ["bc"], seeds=1, mode="online", observability=[0.3])


@pytest.mark.parametrize("args, message", [
    (["--online", "-o", "0.1,0.3"], "--online scores every prefix"),
    (["--online", "--open-set"], "choose one mode: --online, --open-set"),
    (["--open-set", "--task", "GRAIL/MiniGrid-Biased-v0"], "needs at least 3 candidate goals"),
])
def test_bad_combinations_are_one_line_and_exit_2(tmp_path, args, message):
    store = tmp_path / "r.sqlite"
    result = CliRunner().invoke(app, ["run", "-r", "bc", "--store", str(store), "--no-progress", *args])
    assert result.exit_code == 2
    assert message in result.output and len(result.output.strip().splitlines()) == 1
    assert not store.exists() or ResultsStore(store).select(OnlineRow) == []


def test_cli_online_run_then_leaderboard_plot(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))
    store, plot, md = tmp_path / "r.sqlite", tmp_path / "online.png", tmp_path / "online.md"
    runner = CliRunner()
    result = runner.invoke(app, ["run", "-t", TASK.id, "-r", "bc", "--set", "bc.n_epochs=3", "--online",
                                 "--seeds", "2", "--store", str(store), "--no-progress"])
    assert result.exit_code == 0, result.output
    assert "online recognition" in result.output
    result = runner.invoke(app, ["leaderboard", "--online", "--store", str(store), "--plot", str(plot),
                                 "--markdown", str(md), "--no-ceiling"])
    assert result.exit_code == 0, result.output
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| MiniGrid-Suboptimal-6Goals-v1 | subset | bc/mse | 2 |" in md.read_text()
    result = runner.invoke(app, ["leaderboard", "--open-set", "--store", str(store)])
    assert result.exit_code == 2 and "no open-set results" in result.output
    result = runner.invoke(app, ["leaderboard", "--store", str(store), "--plot", str(plot)])
    assert result.exit_code == 2 and "--plot needs --ablation or --online" in result.output


def test_ceiling_curve_is_the_prefix_protocols_bayes_ceiling():
    from grail_bench.harness.ceiling import bayes_ceiling, ceiling_curve

    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    fractions = [0.1, 0.5, 1.0]
    expected = [bayes_ceiling(task, "prefix", p, rounding="ceil").accuracy for p in fractions]
    assert ceiling_curve(task.id, {}, "subset", fractions) == pytest.approx(expected)
    floor = [bayes_ceiling(task, "prefix", p, rounding="floor").accuracy for p in fractions]
    assert ceiling_curve(task.id, {}, "subset+floor", fractions) == pytest.approx(floor) != expected  # the label's
    assert ceiling_curve(task.id, {}, task.protocol_label, fractions) == pytest.approx(expected)  # the task's: ceil
    assert expected[0] < expected[1] <= expected[2] == 1.0
    assert ceiling_curve("GRAIL/PandaReach-Optimal-v0", {}, "subset", fractions) is None  # no ceiling there


class _Recording(SerialExecutor):
    """Runs in this process and keeps what it was given."""

    def __init__(self) -> None:
        self.items: list = []

    def map_unordered(self, fn, items):
        self.items += items
        return super().map_unordered(fn, items)


def test_leaderboard_computes_online_ceiling_curves_on_its_executor(tmp_path, monkeypatch):
    from grail_bench.harness.ceiling import ceiling_curve
    from grail_bench.report.leaderboard import build

    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    spec = RecognizerSpec("graql", FAST["graql"])
    rows = run_mode("online", TASK, plan(TASK, spec, TASK.make_env().action_space), 1, (), "subset")[0]
    executor = _Recording()
    board = build([], ceiling_samples=60, studies={"online": rows}, executor=executor)
    (key,) = board.studies["online"].curves
    assert len(executor.items) == len(GRID)  # every fraction's ceiling went to the executor, each once
    assert {item[2] for item in executor.items} == {"prefix"}
    curve, again = board.studies["online"].curves[key], _Recording()
    params = board.studies["online"].records[0].task_params
    assert curve == ceiling_curve(TASK.id, params, "subset", GRID, samples=60, executor=again)
    assert again.items == []  # cached by the first pass
    assert len(curve) == len(GRID) and curve[-1] >= curve[0]


def test_a_prefix_of_a_states_only_observation_hides_its_last_state_as_an_offline_one_does():
    from grail_bench.core.trajectory import Trajectory

    from grail_bench.harness.modes.online import head

    nan = np.full(3, np.nan)
    observed = Trajectory(obs=np.arange(8.0).reshape(4, 2), acts=nan, infos=None, terminal=False)
    prefix = head(observed, 2)
    assert np.array_equal(prefix.obs[:2], [[0, 1], [2, 3]]) and np.isnan(prefix.obs[2]).all()
    assert observed.obs[2, 0] == 4.0  # the observation itself is left as it was
    pairs = Trajectory(obs=observed.obs, acts=np.zeros(3), infos=None, terminal=False)
    assert np.array_equal(head(pairs, 2).obs, [[0, 1], [2, 3], [4, 5]])
