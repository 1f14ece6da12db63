"""Observation protocols, per-cell random streams, goal-keyed seeds and the store's schema migration."""

from __future__ import annotations

import math
import dataclasses
import sqlite3
from dataclasses import asdict

import numpy as np
import pytest
from conftest import run_mode

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.core.seeding import cell_rng, goal_seed
from grail_bench.core.trajectory import Trajectory
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.harness.store import SCHEMA_VERSION, ResultsStore
from grail_bench.task.observation import BUILTIN, get_protocol, n_observed, observe, parse_label, protocol_label


def demo(T: int = 10, horizon: int = 20) -> Trajectory:
    """Step t has state t and action t % 4; the goal is reached at step T - 1, then the agent stays."""
    infos = np.array([{"is_success": t >= T - 1} for t in range(horizon)])
    return Trajectory(obs=np.arange(horizon + 1)[:, None] * np.ones((1, 3), int), acts=np.arange(horizon) % 4,
                      infos=infos, terminal=True)


@pytest.mark.parametrize("fraction, length, ceil_k, floor_k",
                         [(0.1, 10, 1, 1), (0.25, 10, 3, 2), (0.3, 10, 3, 3), (0.05, 10, 1, 1), (0.35, 11, 4, 3),
                          (1.0, 7, 7, 7)])
def test_k_rounds_up_or_down_and_stays_in_bounds(fraction, length, ceil_k, floor_k):
    assert n_observed(fraction, length, "ceil") == ceil_k
    assert n_observed(fraction, length, "floor") == floor_k  # gr_libs' int(p * T), at least 1


@pytest.mark.parametrize("name", ["subset", "horizon-subset"])
@pytest.mark.parametrize("rounding", ["ceil", "floor"])
def test_subsets_are_ordered_and_within_their_span(name, rounding):
    span = 10 if name == "subset" else 20
    rng = np.random.default_rng(3)
    for fraction in (0.1, 0.25, 0.5, 1.0):
        observed = observe(demo(), fraction, name, rng, rounding)
        steps = observed.obs[:-1, 0]
        assert len(steps) == len(observed.acts) == n_observed(fraction, span, rounding)
        assert np.all(np.diff(steps) > 0) and steps.min() >= 0 and steps.max() < span
        assert observed.obs[-1, 0] == steps[-1] + 1  # the state after the last observed pair
        assert observed.acts.tolist() == (steps % 4).tolist()
        assert observed.infos is None


def test_prefixes_are_the_first_k_pairs():
    assert observe(demo(), 0.3, "prefix").obs[:-1, 0].tolist() == [0, 1, 2]
    assert observe(demo(), 0.3, "horizon-prefix").obs[:-1, 0].tolist() == list(range(6))
    assert observe(demo(), 0.3, "prefix", rounding="floor").obs[:-1, 0].tolist() == [0, 1, 2]


def test_only_horizon_protocols_leak_the_goal():
    # Past the goal (step 9 here) the agent sits on the goal cell; path protocols never look there.
    assert {n for n, p in BUILTIN.items() if p.leaks_goal} == {"horizon-subset", "horizon-prefix"}
    rng = np.random.default_rng(0)
    seen_after_goal = {name: any(observe(demo(), 0.9, name, rng).obs[:-1, 0].max() > 9 for _ in range(20))
                       for name in BUILTIN}
    assert seen_after_goal == {"subset": False, "prefix": False, "horizon-subset": True, "horizon-prefix": True}


def test_unknown_and_deprecated_names():
    with pytest.raises(ValueError, match="unknown observation protocol 'middle'"):
        observe(demo(), 0.5, "middle")
    with pytest.raises(ValueError, match="needs an rng"):
        observe(demo(), 0.5, "subset")
    with pytest.warns(DeprecationWarning, match="'random' is deprecated"):
        assert get_protocol("random").name == "subset"
    assert parse_label(protocol_label("subset", "floor"))[:2] == ("subset", "floor")
    assert protocol_label("prefix") == "prefix"


def test_cell_streams_depend_only_on_their_cell():
    a = cell_rng(0, 0.2, "subset").random(4)
    assert np.array_equal(a, cell_rng(0, 0.2, "subset").random(4))
    for other in (cell_rng(1, 0.2, "subset"), cell_rng(0, 0.3, "subset"), cell_rng(0, 0.2, "subset+floor")):
        assert not np.array_equal(a, other.random(4))


def _metrics(rows):
    timing = {"fit_seconds_per_goal", "score_us_per_observation", "versions"}
    return [{k: v for k, v in asdict(r).items() if k not in timing} for r in rows]


def test_levels_together_or_one_at_a_time_give_identical_rows():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    spec = plan(task, RecognizerSpec("graql", {"episodes": 150}), task.make_env().action_space)
    demos = task.generate_demos(0)
    together, _ = run_mode("offline", task, spec, 0, [0.1, 0.2, 0.3], "subset", demos)
    apart = [row for level in (0.3, 0.1, 0.2) for row in run_mode("offline", task, spec, 0, [level], "subset", demos)[0]]
    key = lambda r: r["observability"]  # noqa: E731
    assert sorted(_metrics(together), key=key) == sorted(_metrics(apart), key=key)
    assert {r.protocol for r in together} == {"subset"}


def test_a_goal_has_the_same_demos_and_seed_in_every_goal_set():
    for regime in ("Optimal", "Suboptimal"):
        four = grail_bench.make_task(f"GRAIL/MiniGrid-{regime}-4Goals-v0").generate_demos(3)
        six = grail_bench.make_task(f"GRAIL/MiniGrid-{regime}-6Goals-v0").generate_demos(3)
        for goal in four:
            assert [t.acts.tolist() for t in four[goal]] == [t.acts.tolist() for t in six[goal]]
    assert goal_seed(3, (7, 3)) == goal_seed(3, (7.0, 3.0)) != goal_seed(3, (7, 5))
    with pytest.raises(ValueError, match="non-negative"):
        goal_seed(-1, (7, 3))


def test_default_protocols_of_the_cards():
    assert grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0").protocol == "subset"
    assert grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1").protocol == "subset"
    assert grail_bench.make_task("GRAIL/MiniGrid-Biased-v0").protocol == "prefix"
    assert grail_bench.make_task("GRAIL/PandaReach-Aligned-Optimal-v0").protocol == "subset"


V1_SCHEMA = (  # the results table as grail-bench 0.1.0 (schema 1) wrote it
    "CREATE TABLE results (task TEXT NOT NULL, recognizer TEXT NOT NULL, scorer TEXT NOT NULL, "
    "config_hash TEXT NOT NULL, seed INTEGER NOT NULL, observability REAL NOT NULL, sampling TEXT NOT NULL, "
    "accuracy REAL, precision REAL, recall REAL, f1 REAL, n_observations INTEGER, n_ties INTEGER, "
    "fit_seconds_per_goal REAL, score_us_per_observation REAL, config TEXT, versions TEXT, brier REAL, nll REAL, "
    "created_at TEXT NOT NULL DEFAULT (datetime('now')), "
    "PRIMARY KEY (task, recognizer, scorer, config_hash, seed, observability, sampling))"
)


def test_a_schema_1_store_is_migrated_without_losing_rows(tmp_path):
    path = tmp_path / "old.sqlite"
    conn = sqlite3.connect(path)
    conn.execute(V1_SCHEMA)
    for seed, sampling in ((0, "prefix"), (1, "prefix"), (0, "random")):
        conn.execute("INSERT INTO results VALUES (?, 'bc', 'mse', 'abc', ?, 0.3, ?, 0.5, 0.5, 0.5, 0.5, 6, 0, "
                     "0.1, 10.0, '{}', '{}', NULL, NULL, datetime('now'))", ("GRAIL/T-v0", seed, sampling))
    conn.execute("PRAGMA user_version = 1")
    conn.commit()
    conn.close()
    with ResultsStore(path) as store:
        rows = store.rows()
        assert sorted((r.seed, r.protocol) for r in rows) == [(0, "prefix"), (0, "random"), (1, "prefix")]
        # Legacy random rows stay apart from the new subset cells, so a resumed run redraws them.
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "subset") == set()
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix") == {(0, 0.3), (1, 0.3)}
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == 1  # reading migrates nothing
    with ResultsStore(path) as store:  # the first rows written migrate it
        store.add([dataclasses.replace(rows[0], seed=2)])
    with ResultsStore(path) as store:
        assert len(store.rows()) == 4
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_observability_levels_round_trip_through_k():
    # p * T that lands on an integer must not round up because of floating point (0.14 * 50 = 7.000000000000001).
    assert n_observed(0.14, 50) == 7 and math.ceil(0.14 * 50) == 8


def test_a_goal_gets_the_same_trained_policy_in_every_goal_set():
    from grail_bench.task.observation import observe as see

    fits = {}
    for task_id in ("GRAIL/MiniGrid-Optimal-4Goals-v0", "GRAIL/MiniGrid-Optimal-6Goals-v0"):
        task = grail_bench.make_task(task_id)
        train, test = task.split(task.generate_demos(1))
        rec = grail_bench.make_recognizer("bc", n_epochs=2)
        rec.fit(train, task.env_factory(), seed=1)
        observed = see(test[(7, 3)][0], 1.0, "prefix")
        fits[task_id] = rec.score(observed, "loglik")[(7, 3)]
    assert len(set(fits.values())) == 1, fits


@pytest.mark.parametrize("level", [0, 2, -0.5, 1.0001, float("nan"), "0.5", True])
def test_a_level_outside_zero_to_one_is_refused_in_one_line(level):
    traj = Trajectory(obs=np.zeros((11, 3), dtype=np.int64), acts=np.zeros(10, dtype=np.int64))
    with pytest.raises(UserError, match=r"^observability level must be a number in \(0, 1\], got "):
        observe(traj, level)
