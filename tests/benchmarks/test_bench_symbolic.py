"""Seconds per recognition problem on the built-in symbolic tasks (``make bench``): prp, landmarks, BC-GRAIL, GRAQL.

Run alone: ``.venv/bin/python -m pytest tests/benchmarks/test_bench_symbolic.py --benchmark-only``. Each recognizer
is fitted once per task (its default settings) on the task's training demonstrations; ``score`` is then timed on
one test demonstration of the task's first goal observed at 30 % under the task's own protocol (``subset``, seeded).
prp memoises its costs per observed sequence, so each of its rounds starts from a fresh memo (``fitted()``): the
timing is that of a new recognition problem. Fits are timed too: BC-GRAIL and GRAQL train one model per goal;
prp reads the grounded model and landmarks extracts every goal's landmarks (their whole per-problem preparation).
Pereira et al.'s published recognition times are not stored here: their table was not read.
"""

from __future__ import annotations

import numpy as np
import pytest

import grail_bench
from grail_bench.recognizers import make_recognizer
from grail_bench.task.observation import observe

TASKS = ("GRAIL/Symbolic-Blocks-Optimal-v0", "GRAIL/Symbolic-Grid-Optimal-v0", "GRAIL/Symbolic-Logistics-Optimal-v0")
NAMES = ("prp", "landmarks", "bc", "graql")
LEVEL = 0.3


def _setup(task_id: str):
    task = grail_bench.make_task(task_id)
    train, test = task.split(task.generate_demos(seed=0))
    observed = observe(test[task.goals[0]][0], LEVEL, task.protocol, np.random.default_rng(0), task.rounding)
    return task, train, observed


SETUPS = {task_id: _setup(task_id) for task_id in TASKS}


@pytest.fixture(scope="module")
def fitted():
    """Every recognizer fitted once on every task (this also pays torch's one-off imports before any timing)."""
    out = {}
    for task_id, (task, train, _) in SETUPS.items():
        for name in NAMES:
            out[(task_id, name)] = make_recognizer(name)
            out[(task_id, name)].fit(train, task.make_env, seed=0)
    return out


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("task_id", TASKS)
def test_score_30_percent(benchmark, fitted, task_id, name):
    task, _, observed = SETUPS[task_id]
    benchmark.group = f"symbolic score at 30 %: {task_id}"
    rec = fitted[(task_id, name)]
    if name == "prp":
        scores = benchmark.pedantic(rec.score, args=(observed,), setup=rec.fitted, rounds=10)
    else:
        scores = benchmark(rec.score, observed)
    assert set(scores) == set(task.goals) and all(np.isfinite(list(scores.values())))
    benchmark.extra_info["observed_actions"] = len(observed.acts)
    benchmark.extra_info["goals"] = len(task.goals)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("task_id", TASKS)
def test_fit(benchmark, fitted, task_id, name):
    """A whole uncached fit of the task's goals; seconds per goal stored as extra info."""
    task, train, _ = SETUPS[task_id]
    benchmark.group = f"symbolic fit: {task_id}"
    rounds = 3 if name in ("bc", "graql") else 10
    benchmark.pedantic(lambda: make_recognizer(name).fit(train, task.make_env, seed=0), rounds=rounds, iterations=1)
    benchmark.extra_info["seconds_per_goal"] = benchmark.stats.stats.median / len(task.goals)
