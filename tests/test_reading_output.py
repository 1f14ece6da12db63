"""What a user reading results sees: progress in a log, long labels at 80 columns, observations under the task's
own protocol, a results page of their own tasks without the paper's claims, and what a normalised F1 above 1 is."""

from __future__ import annotations

import io

import numpy as np
from conftest import offline_record
from rich.console import Console

import grail_bench
from grail_bench.core.progress import LineProgress, progress
from grail_bench.report import leaderboard
from grail_bench.report.claims import claim_tasks
from grail_bench.report.html import write_site
from grail_bench.report.layout import stacked
from grail_bench.report.text import LEGEND
from grail_bench.task.observation import observe


def test_progress_in_a_log_is_whole_lines():
    stream = io.StringIO()
    with LineProgress("GRAIL/MiniGrid-Biased-v0 (offline)", 3, stream=stream, every=0.0) as bar:
        for _ in range(3):
            bar.advance()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 3 and lines[-1].startswith("GRAIL/MiniGrid-Biased-v0 (offline): 3/3, 0:00:00 elapsed, done")
    assert "eta 0:00:00" in lines[0] and "…" not in stream.getvalue() and "━" not in stream.getvalue()
    assert isinstance(progress("x", 2), LineProgress)  # pytest's stderr is no terminal


def test_a_long_task_label_leaves_the_values_visible_at_80_columns():
    label = 'MiniGrid-Optimal (problem="/home/user/some/very/long/path/to/the/problems/p01.pddl")'
    console = Console(width=80, record=True, color_system=None)
    with console.capture() as captured:
        console.print(stacked("F1", ["task", "obs", "BC-GRAIL"], [[label, "10%", "0.50 ± 0.10 [0.83]"]]))
    text = captured.get()
    assert "BC-GRAIL: 0.50 ± 0.10 [0.83]" in text and "obs: 10%" in text
    assert "MiniGrid-Optimal (problem=" in text and "…" in text
    assert max(len(line) for line in text.splitlines()) <= 80


def test_observe_defaults_to_the_tasks_own_protocol():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    assert task.protocol == "subset"
    demo = task.generate_demos(0)[task.goals[0]][0]
    by_task = observe(demo, 0.5, rng=np.random.default_rng(1), task=task)
    subset = observe(demo, 0.5, "subset", np.random.default_rng(1))
    prefix = observe(demo, 0.5, "prefix")
    assert np.array_equal(by_task.acts, subset.acts) and not np.array_equal(by_task.obs, prefix.obs)
    assert np.array_equal(task.observe(demo, 0.5, np.random.default_rng(1)).obs, subset.obs)
    assert np.array_equal(observe(demo, 0.5).obs, prefix.obs)  # no task: prefix, as before


def test_a_page_of_ones_own_tasks_shows_no_paper_claims(tmp_path):
    task = "GRAIL/MiniGrid-Optimal-12Goals-v0"
    assert task not in claim_tasks()
    records = [offline_record(task, "bc", 0.1, [0.5, 0.6, 0.7]), offline_record(task, "graql", 0.1, [0.3, 0.4, 0.5])]
    board = leaderboard.build([], None, None, records=records)
    index = write_site(board, tmp_path / "site")[0].read_text()
    assert "Headline claims" not in index and 'href="#claims"' not in index and "not measured" not in index
    assert "published data" not in index


def test_the_legend_says_what_a_normalised_f1_above_1_is():
    assert "above 1" in LEGEND and "accuracy ceiling" in LEGEND


def test_summaries_computed_together_are_those_computed_one_by_one():
    from grail_bench.stats.metrics import summarize, summarize_many

    rng = np.random.default_rng(0)
    groups = [list(np.round(rng.random(n), 2)) for n in (1, 2, 3, 5, 10, 10, 10, 13) for _ in range(40)]
    groups += [[0.5] * 10, [1.0, 1.0]]
    assert summarize_many(groups) == [summarize(g) for g in groups]
