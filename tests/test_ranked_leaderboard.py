"""The terminal leaderboard ranks first (domain summaries before anything else), filters by task glob, domain and
method, leaves out the rows of tasks under test-time shifts unless asked, shows the claims only for a store that
ran their tasks, and keeps the ceilings it computes in the store."""

from __future__ import annotations

import json

import pytest
from conftest import stored_config
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.harness import ceiling as ceiling_module
from grail_bench.harness.ceiling import Cell, ceilings_for
from grail_bench.harness.ceiling_cache import CeilingCache
from grail_bench.harness.store import ResultRow, ResultsStore
from grail_bench.report.claims import claim_tasks
from grail_bench.report.configs import method_of
from grail_bench.report.filters import shifted
from grail_bench.task.overrides import TaskOverrides

MINIGRID, POINT_MAZE = "GRAIL/MiniGrid-Optimal-12Goals-v0", "GRAIL/PointMaze-Optimal-v0"
SUMMARY = "F1 per method, IQM over seeds and strata"


def _rows(task_id: str, name: str, f1: float, task_params: dict | None = None) -> list[ResultRow]:
    """Three seeds of ``name`` at its defaults under its own scorer, at every level of the task (run with
    ``task_params``)."""
    task = grail_bench.make_task(task_id)
    scorer = method_of(name)[1]
    config, hashed = stored_config(task_id, name, task_params=task_params)
    return [ResultRow(task_id, name, scorer, hashed, seed, level, task.protocol_label, f1, f1, f1, f1 + 0.01 * seed,
                      6, 0, 1.0, 10.0, config, "{}") for seed in range(3) for level in task.observability]


@pytest.fixture
def store(tmp_path):
    path = tmp_path / "mine.sqlite"
    with ResultsStore(path) as s:
        s.add(_rows(MINIGRID, "bc", 0.8) + _rows(MINIGRID, "graql", 0.4) + _rows(POINT_MAZE, "bc", 0.6))
    return path


def leaderboard(store, *args):
    result = CliRunner().invoke(app, ["leaderboard", "--store", str(store), "--no-ceiling", *args],
                                env={"COLUMNS": "160"})
    return result.exit_code, result.output


def test_the_domain_summaries_come_first_and_the_boards_only_when_asked(store):
    assert {MINIGRID, POINT_MAZE}.isdisjoint(claim_tasks())
    code, out = leaderboard(store)
    assert code == 0, out
    assert out.lstrip().startswith(SUMMARY)
    assert out.count(SUMMARY) == 2  # minigrid and point_maze
    assert "BC-GRAIL" in out and "GRAQL" in out and "0.81 [0.80, 0.82]" in out  # bc's IQM of its seeds
    assert "F1 (mean ± std over seeds)" not in out  # no per-task board by default
    assert "headline claims" not in out  # none of the claims' tasks is in this store
    code, out = leaderboard(store, "--boards")
    assert code == 0, out
    assert out.index(SUMMARY) < out.index("F1 (mean ± std over seeds)")


@pytest.mark.parametrize("args, shown, hidden", [
    (["--task", "GRAIL/MiniGrid-*"], ["minigrid", "GRAQL"], ["point_maze"]),
    (["--task", "PointMaze-*"], ["point_maze"], ["minigrid", "GRAQL"]),
    (["--domain", "point_maze"], ["point_maze"], ["minigrid"]),
    (["--domain", "MiniGrid"], ["minigrid"], ["point_maze"]),
    (["--method", "graql"], ["GRAQL"], ["BC-GRAIL", "point_maze"]),
    (["--method", "BC-GRAIL", "--task", MINIGRID], ["BC-GRAIL"], ["GRAQL", "point_maze"]),
])
def test_filters_filter(store, args, shown, hidden):
    code, out = leaderboard(store, *args)
    assert code == 0, out
    titles = [line for line in out.splitlines() if SUMMARY in line]
    for word in shown:
        assert word in out
    for word in hidden:
        assert word not in out, word
    assert titles


def test_a_filter_matching_nothing_is_one_line(store):
    code, out = leaderboard(store, "--task", "GRAIL/Nope-*")
    assert code == 2 and "match --task GRAIL/Nope-*" in out and out.strip().count("\n") == 0
    code, out = leaderboard(store, "--method", "draco")
    assert code == 2 and "match --method draco" in out


def test_tasks_and_list_take_the_filters_and_print_full_ids():
    result = CliRunner().invoke(app, ["tasks", "--task", "MiniGird-*"], env={"COLUMNS": "200"})
    assert result.exit_code == 2 and "--task 'MiniGird-*' matches no task" in result.output
    result = CliRunner().invoke(app, ["tasks", "--task", "GRAIL/MiniGrid-Biased*"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "GRAIL/MiniGrid-Biased-v0" in result.output and "GRAIL/MiniGrid-Biased-4Goals-v0" in result.output
    assert "Optimal" not in result.output
    result = CliRunner().invoke(app, ["list", "--domain", "point_maze", "--method", "bc"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "GRAIL/PointMaze-Optimal-v0" in result.output and "MiniGrid" not in result.output
    names = {line.split("│")[1].strip() for line in result.output.splitlines() if line.startswith("│")}
    assert "bc" in names and "graql" not in names


class Memory:
    """A ceiling cache as the store keeps it, in a dict."""

    def __init__(self):
        self.entries = {}

    def get(self, digests):
        return {d: self.entries[d] for d in digests if d in self.entries}

    def put(self, entries):
        self.entries |= entries
        return True


def test_ceilings_are_cached_in_the_store_and_computed_again_when_the_task_changes(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    cell = Cell("GRAIL/MiniGrid-Biased-v0", TaskOverrides.of({}), "prefix", 0.2)
    store = CeilingCache(tmp_path / "mine.sqlite")
    with ResultsStore(tmp_path / "mine.sqlite") as results:
        results.create()
    first = ceilings_for([cell], samples=50, store=store)
    assert len(store.get(store_digests := [*_digests(store)])) == 1 == len(store_digests)

    def refuse(*args, **kwargs):
        raise AssertionError("a cached ceiling was computed again")

    monkeypatch.setattr(ceiling_module, "_cell_ceiling", refuse)
    monkeypatch.setattr(ceiling_module, "_read", lambda key, path: None)  # not from the cache folder: the store
    assert ceilings_for([cell], samples=50, store=store) == first
    other = Cell("GRAIL/MiniGrid-Biased-v0", TaskOverrides.of({"routes": ["EN", "SE"]}), "prefix", 0.2)
    with pytest.raises(AssertionError, match="computed again"):
        ceilings_for([other], samples=50, store=store)


def _digests(cache: CeilingCache) -> list[str]:
    import sqlite3

    return [d for (d,) in sqlite3.connect(cache.path).execute("SELECT digest FROM ceilings")]


def test_the_store_cache_leaves_a_store_it_cannot_write_unchanged(tmp_path):
    missing = CeilingCache(tmp_path / "none" / "x.sqlite")
    assert missing.get(["a"]) == {} and missing.put({"a": json.dumps({})}) is False


def test_the_claims_table_has_a_row_per_claim_and_method_with_its_best_variant_beside_it():
    from rich.console import Console

    from grail_bench.report.claims import ClaimResult
    from grail_bench.report.text import claims_table

    nan = float("nan")
    results = [ClaimResult("A holds", "Table 3", "BC-GRAIL", "mean F1", 0.9, 0.85, 0.95, "holds"),
               ClaimResult("A holds", "Table 3", "BC-GRAIL · n_epochs 25", "mean F1", 0.7, 0.6, 0.8, "partly"),
               ClaimResult("A holds", "Table 3", "BC-GRAIL · occupancy", "mean F1", 0.95, 0.9, 1.0, "holds"),
               ClaimResult("A holds", "Table 3", "GRAQL", "mean F1", 0.4, 0.3, 0.5, "does not hold"),
               ClaimResult("B elsewhere", "Table 4", "BC-GRAIL", "mean F1 (0 of 3 run)", nan, nan, nan, "not measured")]

    def text(all_variants):
        console = Console(width=200, record=True, color_system=None)
        with console.capture() as captured:
            console.print(claims_table(results, all_variants))
        return captured.get()

    out = text(False)
    rows = [line for line in out.splitlines() if "BC-GRAIL" in line or "GRAQL" in line]
    assert len(rows) == 2  # one per canonical method of the measured claim
    assert "occupancy: 0.95 [0.90, 1.00] holds" in rows[0]  # the best named variant beside its method
    assert "n_epochs" not in out and "B elsewhere" not in out
    assert "Not listed: 1 of the paper's claims" in " ".join(out.split())
    every = text(True)
    assert "BC-GRAIL · n_epochs 25" in every and "BC-GRAIL · occupancy" in every


SHIFTED_NOTE = "rows of tasks under test-time shifts are not shown"


@pytest.fixture
def shifted_store(tmp_path):
    """bc on a task unshifted, and GRAQL on the same task under a test-time slip only."""
    path = tmp_path / "shifted.sqlite"
    with ResultsStore(path) as s:
        s.add(_rows(MINIGRID, "bc", 0.8) + _rows(MINIGRID, "graql", 0.4, {"test_slip": 0.3}))
    return path


@pytest.mark.parametrize("args", [[], ["--task", MINIGRID]])
def test_the_rows_of_shifted_tasks_are_left_out_unless_asked(shifted_store, tmp_path, args):
    markdown, site = tmp_path / "board.md", tmp_path / "site"
    code, out = leaderboard(shifted_store, *args, "--markdown", str(markdown), "--html", str(site))
    assert code == 0, out
    assert "BC-GRAIL" in out and "GRAQL" not in out and "test_slip" not in out
    n_shifted = len(grail_bench.make_task(MINIGRID).observability) * 3
    assert f"{n_shifted} {SHIFTED_NOTE}" in " ".join(out.split())
    assert _table_rows(markdown, "BC-GRAIL") and not _table_rows(markdown, "GRAQL")
    assert "test_slip" not in markdown.read_text() and f"{n_shifted} {SHIFTED_NOTE}" in markdown.read_text()
    index = (site / "index.html").read_text()
    assert "test_slip" not in index and SHIFTED_NOTE in index and "GRAQL" not in (site / "minigrid.html").read_text()
    code, out = leaderboard(shifted_store, *args, "--shifted", "--markdown", str(markdown))
    assert code == 0, out
    assert "GRAQL" in out and SHIFTED_NOTE not in " ".join(out.split())
    assert _table_rows(markdown, "GRAQL") and "test_slip=0.3" in markdown.read_text()
    assert SHIFTED_NOTE not in markdown.read_text()


def _table_rows(markdown, method: str) -> list[str]:
    return [line for line in markdown.read_text().splitlines() if line.startswith("|") and f" {method}" in line]


def test_a_selection_of_shifted_rows_alone_says_how_to_show_them(shifted_store):
    code, out = leaderboard(shifted_store, "--method", "graql")
    assert code == 2 and "all of tasks under test-time shifts; --shifted shows them" in " ".join(out.split())
    code, out = leaderboard(shifted_store, "--method", "graql", "--shifted")
    assert code == 0 and "GRAQL" in out


@pytest.mark.parametrize("task_id, params, expected", [
    ("GRAIL/MiniGrid-Boltzmann-v0", None, False),  # a regime of its own, not a shift
    ("GRAIL/MiniGrid-Optimal-v0", {"test_slip": 0.0}, False),  # the default: the unshifted task
    ("GRAIL/MiniGrid-Optimal-v0", {"test_regime": "boltzmann"}, True),
    ("GRAIL/PointMaze-Optimal-v0", {"test_action_scale": 0.5}, True),
])
def test_a_row_is_shifted_when_its_task_has_test_parameters(task_id, params, expected):
    assert shifted(_rows(task_id, "bc", 0.5, params)[0]) is expected
