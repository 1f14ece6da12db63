"""Time to the first summary of ``grail-bench leaderboard`` on the published store (``make bench``), built from
``leaderboard/published`` as ``leaderboard/store.sh`` builds it.

The command runs as a user runs it (a process of its own, imports included); the time is taken when its first
line of output (the first domain summary's title) arrives, before the claims and the rest are drawn. A first,
untimed round describes the recognizers once (kept in the cache folder; later runs do not import them), as any
user's first run after installing does. The line count of the whole default output and the median CPU seconds
(user + sys) of a whole run, less sensitive to a loaded machine than the time, are stored as extra info.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

import pytest

PUBLISHED = Path(__file__).resolve().parents[2] / "leaderboard" / "published"


@pytest.fixture(scope="module")
def published_copy(tmp_path_factory):
    from grail_bench.harness import published
    from grail_bench.harness.store import ResultsStore

    copy = tmp_path_factory.mktemp("published") / "results.sqlite"
    with ResultsStore(copy) as store:
        published.load(PUBLISHED, store, check=False)
    return copy


def test_time_to_first_summary_on_the_published_store(benchmark, published_copy):
    """Timed: from starting the command to its first line; each run's remaining output is read (and its lines
    counted) before the next round starts, untimed."""
    running: list[subprocess.Popen] = []
    lines: list[int] = []
    cpu: list[float] = []

    def finish() -> None:
        while running:
            proc = running.pop()
            lines.append(1 + sum(1 for _ in proc.stdout))
            assert proc.wait() == 0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append(after.ru_utime + after.ru_stime - sum(cpu) - start)

    def first_summary() -> None:
        proc = subprocess.Popen([sys.executable, "-m", "grail_bench", "leaderboard", "--store", str(published_copy)],
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                env={**os.environ, "COLUMNS": "80"})
        running.append(proc)
        assert "F1 per method" in proc.stdout.readline()

    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = used.ru_utime + used.ru_stime  # the children's CPU so far (the store's copy made none)
    benchmark.pedantic(first_summary, setup=finish, rounds=3, warmup_rounds=1, iterations=1)
    finish()
    benchmark.extra_info["output_lines"] = lines[-1]
    benchmark.extra_info["cpu_seconds_median"] = round(statistics.median(cpu[1:]), 2)  # the warm-up left out
