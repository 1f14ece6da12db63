"""Tests of the dataset runner on grail-bench's built-in problems written in the dataset's layout.

    .venv/bin/python -m pytest -q leaderboard/symbolic_dataset/test_run.py      (grail-bench's virtualenv)
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pytest

from grail_bench.domains.symbolic.generator import write_dataset

sys.path.insert(0, str(Path(__file__).parent))

from run import main, markdown, run, summary  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("dataset")
    write_dataset(folder, names=["grid"], levels=[30, 100], seed=0)
    return folder


def _by_cell(records):
    return {(r["level"], r["recognizer"]): r for r in summary(records)}


def test_a_whole_optimal_plan_is_recognised_by_every_recognizer(dataset):
    records, skipped = run(dataset, ["grid"], [100], None, 0, 20_000, None)
    assert not skipped and {r.status for r in records} == {"ok"}
    cells = _by_cell(records)
    for name in ("h_gc", "h_uniq", "prp"):
        assert cells[(100, name)]["accuracy"] == 1.0 and cells[(100, name)]["problems"] == 3
        assert 1.0 <= cells[(100, name)]["spread"] <= 3.0


def test_same_seed_same_sample_and_answers(dataset):
    def answers(seed):
        records, _ = run(dataset, ["grid"], [30, 100], 2, seed, 20_000, 1)
        return [replace(r, seconds=0.0) for r in records]

    first = answers(3)
    assert first == answers(3)
    assert sum(r.recognizer == "prp" for r in first) == 2  # one problem per level
    assert sum(r.recognizer == "h_gc" for r in first) == 4


def test_a_search_past_its_node_limit_counts_as_an_unsolved_miss(dataset):
    records, _ = run(dataset, ["grid"], [100], None, 0, 1, None)
    prp = [r for r in records if r.recognizer == "prp"]
    assert {r.status for r in prp} == {"node-limit"} and not any(r.correct for r in prp)
    cell = _by_cell(records)[(100, "prp")]
    assert cell["accuracy"] == 0.0 and cell["node_limit"] == 3
    table = markdown(summary(records)).splitlines()
    assert table[-1].startswith("| grid | 100 | 3 |") and "| 0.0 | – |" in table[-1]  # prp: 0 %, no spread
    assert table[-1].endswith("| 3 | 3 |")  # prp problems, prp unsolved


def test_an_unreadable_archive_is_skipped_with_its_error(dataset, tmp_path, capsys):
    broken = tmp_path / "grid" / "100"
    broken.mkdir(parents=True)
    for archive in (dataset / "grid" / "100").iterdir():
        (broken / archive.name).write_bytes(archive.read_bytes())
    (broken / "grid_hyp-9_100.tar.bz2").write_bytes(b"not an archive")
    records, skipped = run(tmp_path, ["grid"], [100], None, 0, 20_000, 0)
    assert len(skipped) == 1 and "not a readable tar archive" in skipped[0]["error"]
    assert {r.recognizer for r in records} == {"h_gc", "h_uniq"}
    assert main([str(tmp_path), "--domains", "grid", "--levels", "10"]) == 2
    assert "does not exist" in capsys.readouterr().err
