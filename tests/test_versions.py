"""Task versions mean one thing: fingerprints, the shipped table, old versions, and rows stored before a bump."""

from __future__ import annotations

import dataclasses
import json

import gymnasium as gym
import pytest

import grail_bench  # noqa: F401 - registers the GRAIL/ IDs
from grail_bench.harness.modes.offline import ResultRow
from grail_bench.harness.store import ResultsStore
from grail_bench.task import make_task
from grail_bench.task.registration import shipped_tasks
from grail_bench.task.versions import changed, fingerprint, parse_table, resolve_id, shipped_table

OLD, NEW = "GRAIL/MiniGrid-Suboptimal-v0", "GRAIL/MiniGrid-Suboptimal-v1"


def test_every_shipped_task_means_the_fingerprint_its_version_records():
    problems = changed(shipped_tasks().values())
    assert not problems, "\n".join(problems)
    assert set(shipped_table().fingerprints) == set(shipped_tasks())


def test_a_changed_definition_under_the_same_version_fails_with_the_fix():
    task = make_task(NEW)
    table = parse_table(f'[fingerprints]\n"{NEW}" = "{fingerprint(task)}"\n')
    assert changed([task], table) == []
    edited = task.with_overrides(turn_prob=0.5)
    [line] = changed([edited], table)
    assert NEW in line and "bump the ID's version" in line and "tasks/versions.toml" in line


def test_fingerprint_is_deterministic_and_covers_parameters_and_the_generator(monkeypatch):
    task = make_task(NEW)
    assert fingerprint(task) == fingerprint(make_task(NEW)) and len(fingerprint(task)) == 12
    assert fingerprint(task.with_overrides(route_choice="fixed")) != fingerprint(task)
    assert fingerprint(dataclasses.replace(task, description="other words")) == fingerprint(task)
    assert fingerprint(task) == fingerprint(make_task(OLD).with_overrides(turn_prob=1.0))  # the same task
    before = fingerprint(task)
    monkeypatch.setattr(type(task.spec), "generator_version", 2, raising=False)
    assert fingerprint(task) != before


def test_the_old_version_stays_makeable_with_its_old_parameters():
    assert make_task(OLD).params["turn_prob"] == 0.3
    assert make_task(NEW).params["turn_prob"] == 1.0
    with pytest.warns(DeprecationWarning, match="v1"):
        env = gym.make(OLD)
    assert env.unwrapped.task.params["turn_prob"] == 0.3
    env.close()


def _row(task: str, params: dict, seed: int = 0) -> ResultRow:
    return ResultRow(task=task, recognizer="bc", scorer="mse", config_hash=json.dumps(params, sort_keys=True),
                     seed=seed, observability=0.1, protocol="subset", accuracy=0.5, precision=0.5, recall=0.5,
                     f1=0.5, n_observations=6, n_ties=0, fit_seconds_per_goal=0.1, score_us_per_observation=1.0,
                     config=json.dumps({"task": {"params": params}}), versions="{}")


OLD_RUN = {"turn_pattern": "left-right", "turn_prob": 0.3}  # stored 2026-11-22, before route_choice existed
FIXED_RUN = {"route_choice": "fixed", "turn_pattern": "left-right", "turn_prob": 1.0}  # 2026-11-23 to 25
NEW_RUN = {"route_choice": "uniform", "turn_pattern": "left-right", "turn_prob": 1.0}


def test_rows_stored_under_v0_are_read_as_the_version_their_parameters_say():
    assert resolve_id(OLD, OLD_RUN) == OLD
    assert resolve_id(OLD, FIXED_RUN) == NEW and resolve_id(OLD, NEW_RUN) == NEW
    assert resolve_id("GRAIL/MiniGrid-Optimal-v0", {"route_choice": "fixed"}) == "GRAIL/MiniGrid-Optimal-v0"
    with ResultsStore() as store:
        store.add([_row(OLD, OLD_RUN), _row(OLD, FIXED_RUN), _row(OLD, NEW_RUN), _row(NEW, NEW_RUN, seed=1)])
        assert sorted((r.task, r.seed) for r in store.rows()) == [(OLD, 0), (NEW, 0), (NEW, 0), (NEW, 1)]
        assert len(store.rows(task=NEW)) == 3
        assert [json.loads(r.config)["task"]["params"] for r in store.rows(task=OLD)] == [OLD_RUN]
        # the file keeps the IDs the rows were stored under
        assert store._conn.execute("SELECT COUNT(*) FROM results WHERE task = ?", (OLD,)).fetchone()[0] == 3


def test_new_rows_carry_their_tasks_fingerprint(tmp_path):
    from grail_bench.harness.api import evaluate
    from grail_bench.harness.planning import RecognizerSpec

    with ResultsStore(tmp_path / "r.sqlite") as store:
        evaluate(NEW, [RecognizerSpec("bc", {"n_epochs": 1})], seeds=1, store=store, observability=[0.5],
                 task_params={"n_demos": 3, "n_train": 2})
        stored = {r.task_fingerprint for r in store.rows()}
    assert stored == {fingerprint(make_task(NEW, n_demos=3, n_train=2))}
