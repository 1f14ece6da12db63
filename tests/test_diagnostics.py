"""Fit diagnostics: what they measure, where they are stored and shown, and that they change no result."""

from __future__ import annotations

import dataclasses
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import FAST

import grail_bench
from grail_bench.core.rl import empty_policy
from grail_bench.harness import diagnostics
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.executors import make_executor
from grail_bench.harness.modes import ResultRow
from grail_bench.harness.planning import RecognizerSpec
from grail_bench.harness.store import ResultsStore
from grail_bench.harness.sweep import Request, run_sweep
from grail_bench.recognizers import make_recognizer
from grail_bench.recognizers.policy import PolicyRecognizer, spaces_of
from grail_bench.task.observation import ObservationSpec

BIASED = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
OPTIMAL = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
BIN = Path(sys.executable).parent


class Untrained(PolicyRecognizer):
    """One freshly initialised PPO policy per goal: random policies, nothing learned."""

    name = "untrained"

    def __init__(self, scorer: str | None = None) -> None:
        super().__init__(scorer)

    def new_policy(self, goal, env_factory):
        return empty_policy("ppo", *spaces_of(env_factory, goal))

    def train_policy(self, goal, demos, env_factory, seed):
        return self.new_policy(goal, env_factory), {}


def test_random_policies_agree_at_chance_and_reach_nothing():
    train, test = OPTIMAL.split(OPTIMAL.generate_demos(0))
    chance = []
    for seed in range(3):
        rec = Untrained()
        rec.fit(train, OPTIMAL.env_factory(), seed=seed)
        d = rec.diagnose(train, test, OPTIMAL.env_factory())
        assert d.reached == (False,) * 4 and d.rollout_length == (60,) * 4  # wanders for the whole episode
        chance += list(d.agreement_train) + list(d.agreement_held_out)
        assert np.allclose(d.imitation, 0.25, atol=0.1)  # near-uniform action probabilities everywhere
    assert 0.05 < np.mean(chance) < 0.5  # four actions: chance is about one in four (greedy on random logits)


def test_bc_imitation_matrix_of_a_biased_task_is_diagonal_dominant_and_reaches_its_goals():
    train, test = BIASED.split(BIASED.generate_demos(0))
    rec = make_recognizer("bc", n_epochs=100)
    rec.fit(train, BIASED.env_factory(), seed=0)
    d = rec.diagnose(train, test, BIASED.env_factory())
    m = np.array(d.imitation)
    assert all(m[i, i] > max(np.delete(m[i], i)) for i in range(len(m)))
    assert d.reached == (True, True) and d.rollout_length == (11, 11) and d.demo_length == (11.0, 11.0)
    assert d.agreement_train == (1.0, 1.0) and d.agreement_held_out == (1.0, 1.0)
    assert len(d.curves[0]["loss"]) == 50 and d.curves[0]["loss"][-1] < d.curves[0]["loss"][0]  # thinned, falling


def _sweep(store_path, executor=None, recognizers=("bc", "graql")):
    req = Request(OPTIMAL.id, tuple(RecognizerSpec(n, FAST[n]) for n in recognizers), (0, 1),
                  ObservationSpec("subset", "ceil", (0.3,)))
    with ResultsStore(store_path) as store:
        run_sweep([req], store, executor)
        return store.select(FitRow), store.select(ResultRow)


def test_diagnostics_are_stored_and_identical_serial_parallel_and_from_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))
    serial, rows = _sweep(tmp_path / "a.sqlite")
    assert len(serial) == 4 and {f.mode for f in serial} == {"offline"}  # 2 recognizers x 2 seeds
    again, _ = _sweep(tmp_path / "b.sqlite")  # every model now from the cache
    executor = make_executor("local", 2)
    try:
        parallel, _ = _sweep(tmp_path / "c.sqlite", executor)
    finally:
        executor.close()
    strip = lambda fits: [dataclasses.replace(f, provenance=None) for f in fits]  # noqa: E731
    assert strip(serial) == strip(again) == strip(parallel)
    bc = next(f for f in serial if f.recognizer == "bc").parsed()
    assert set(bc.curves[0]) == {"loss"} and bc.goals == OPTIMAL.goals  # curves kept through the cache
    graql = next(f for f in serial if f.recognizer == "graql").parsed()
    assert set(graql.curves[0]) == {"return"} and all(graql.reached)


def test_results_are_unchanged_by_the_diagnostics(tmp_path, monkeypatch):
    from grail_bench.recognizers.contract import Capabilities

    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))
    _, with_diagnostics = _sweep(tmp_path / "a.sqlite", recognizers=("bc",))
    monkeypatch.setattr(Capabilities, "diagnose", lambda self, *a: None)
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "other-cache"))  # trained afresh
    fits, without = _sweep(tmp_path / "b.sqlite", recognizers=("bc",))
    assert fits == []
    timing = ("fit_seconds_per_goal", "score_us_per_observation", "provenance")
    strip = lambda rs: [{k: v for k, v in dataclasses.asdict(r).items() if k not in timing} for r in rs]  # noqa: E731
    assert strip(with_diagnostics) == strip(without)


def test_confusion_matrices_count_every_observation(tmp_path, monkeypatch):
    from grail_bench.harness.api import evaluate

    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))
    records = evaluate(OPTIMAL.id, [("graql", FAST["graql"])], seeds=3, observability=[0.3])
    (record,) = records
    m = np.array(record.confusion)
    assert m.shape == (4, 4) and m.sum() == 3 * 12 and (m.sum(axis=1) == 9).all()  # 3 test demos x 3 seeds per goal
    assert np.trace(m) / m.sum() == pytest.approx(record.accuracy_mean)


def test_a_schema_5_store_gains_the_fits_table_and_confusion_column(tmp_path):
    from test_store import row

    path = tmp_path / "v5.sqlite"
    with ResultsStore(path) as store:
        store.add([row(seed=s) for s in range(2)])
    conn = sqlite3.connect(path)
    conn.execute("DROP TABLE fits")
    conn.execute("ALTER TABLE results DROP COLUMN confusion")
    conn.execute("PRAGMA user_version = 5")
    conn.commit()
    conn.close()
    with ResultsStore(path) as store:
        assert len(store.rows()) == 2 and all(r.confusion is None for r in store.rows())
        fit = FitRow("GRAIL/T-v0", "bc", "abc", 0, "offline", "{}")
        assert store.add([fit]) == 1 and store.select(FitRow) == [fit]


def test_plugins_without_diagnostics_still_run_and_store_none(tmp_path, toy_plugin, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))
    fits, rows = _sweep(tmp_path / "r.sqlite", recognizers=())  # nothing requested
    assert fits == [] and rows == []
    req = Request(BIASED.id, (RecognizerSpec("toy"),), (0,), ObservationSpec("prefix", "ceil", (0.2,)))
    with ResultsStore(tmp_path / "r.sqlite") as store:
        run_sweep([req], store)
        assert store.select(FitRow) == [] and len(store.rows()) == 1


def test_summaries_count_goals_reached_and_average_over_seeds():
    def fit(seed, reached, m):
        d = grail_bench.FitDiagnostics(goals=((1, 1), (2, 2)), agreement_train=(1.0, 0.5),
                                       agreement_held_out=(None, 0.5), imitation=m, reached=reached,
                                       rollout_length=(3, 9), demo_length=(3.0, 4.0), curves={0: {"loss": [2.0, 1.0]}})
        return FitRow("GRAIL/T-v0", "bc", "h", seed, "offline", diagnostics.to_json(d))

    rows = [fit(0, (True, False), ((0.9, 0.1), (0.2, 0.8))), fit(1, (True, True), ((0.7, 0.3), (0.4, 0.6))),
            dataclasses.replace(fit(2, (False, False), ((0.0, 0.0), (0.0, 0.0))), mode="open-set")]
    (summary,) = diagnostics.summarize(rows).values()
    assert summary.seeds == [0, 1] and summary.reached == [2, 1] and summary.rolled_out == [2, 2]
    assert summary.reached_share == 0.75 and summary.agreement_held_out == [None, 0.5]
    assert np.allclose(summary.imitation, [[0.8, 0.2], [0.3, 0.7]]) and summary.curves == {"0": {"loss": [2.0, 1.0]}}


def test_inspect_shows_a_fit_and_writes_its_files(tmp_path):
    env = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_CACHE": str(tmp_path / "cache")}
    out = subprocess.run([str(BIN / "grail-bench"), "inspect", "-t", BIASED.id, "-r", "bc", "--set",
                          "bc.n_epochs=100", "--seed", "1", "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "(7,1)" in out.stdout and "yes" in out.stdout  # BC at 100 epochs reaches its goals
    data = json.loads((tmp_path / "o" / "diagnostics.json").read_text())
    assert data["recognizer"] == "bc" and data["diagnostics"]["reached"] == [True, True]
    assert sum(map(sum, data["confusion"])) == 3 * 6  # 3 levels x 6 test observations
    for name in ("confusion.png", "imitation.png", "curves.png"):
        assert (tmp_path / "o" / name).stat().st_size > 1000
    bad = subprocess.run([str(BIN / "grail-bench"), "inspect", "-r", "nope"], capture_output=True, text=True,
                         env=env, timeout=600)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "unknown recognizer 'nope'" in bad.stderr
