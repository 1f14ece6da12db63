"""Sweep scaling (``make bench``): the same sweep on 1 and on 2 local workers.

Scaling efficiency is ``median(1 worker) / (2 * median(2 workers))``; the
target is >= 80 % on a 2-core machine. Each round trains from an empty model
cache and stores into a fresh store, so both runs do the same work.
"""

from __future__ import annotations

import itertools

import pytest

from grail_bench.harness.executors import make_executor
from grail_bench.harness.planning import RecognizerSpec
from grail_bench.harness.store import ResultsStore
from grail_bench.harness.sweep import Request, run_sweep
from grail_bench.task.observation import ObservationSpec

# 8 units of about 6 s each (BC and GRAQL at their defaults on 6 goals).
REQUEST = Request("GRAIL/MiniGrid-Optimal-6Goals-v0", (RecognizerSpec("bc"), RecognizerSpec("graql")),
                  (0, 1, 2, 3), ObservationSpec("subset", "ceil", (0.1, 0.2, 0.3)))
_round = itertools.count()


@pytest.mark.parametrize("workers", [1, 2])
def test_sweep_on_local_workers(benchmark, tmp_path, monkeypatch, workers):
    def setup():
        n = next(_round)
        monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / f"cache{n}"))
        return (ResultsStore(tmp_path / f"store{n}.sqlite"),), {}

    def sweep(store):
        executor = make_executor("local", workers)  # pool start-up is part of the cost
        try:
            return run_sweep([REQUEST], store, executor)
        finally:
            executor.close()

    summary = benchmark.pedantic(sweep, setup=setup, rounds=2, iterations=1)
    assert summary.units == 8 and summary.trained == 8 * 6
