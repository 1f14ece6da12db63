"""Boards as typed rows and cells keyed by (row, label), and their terminal rendering at 80 columns."""

from __future__ import annotations

import dataclasses

import pytest
from conftest import offline_record
from rich.console import Console

from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report import leaderboard
from grail_bench.report.boards import BoardRow
from grail_bench.report.reference import Reported
from grail_bench.report.text import LEGEND, rich_tables

TASK = "GRAIL/MiniGrid-Optimal-4Goals-v0"
METHODS = {"bc": ("mse", 0.9), "gail": ("mse", 0.7), "airl": ("mse", 0.65), "graql": ("kl", 0.8),
           "draco": ("wasserstein", 0.75), "demonstrator": ("mse", 0.99)}


def record(rec: str, level: float, settings: dict | None = None) -> OfflineRecord:
    """A record of ``rec`` with ``settings`` on :data:`TASK`, its configuration and hash as planning stores them."""
    scorer, f1 = METHODS[rec]
    return offline_record(TASK, rec, level, f1, scorer=scorer, settings=settings)


@pytest.fixture(scope="module")
def board() -> leaderboard.Leaderboard:
    records = [record(rec, lv) for rec in METHODS for lv in (0.1, 0.3)]
    records += [record("gail", lv, {"total_timesteps": 40000}) for lv in (0.1, 0.3)]
    reference = {(TASK, "bc", 0.1): Reported("0.73 ± 0.33", (0.49, 0.90))}
    return leaderboard.build([], reference, None, records=records)


def test_rows_are_typed_and_cells_keyed_by_row_and_label(board):
    (main,) = board.boards
    first = main.rows[0]
    assert first == BoardRow(4, TASK, "subset", 0.1) and first.name == "MiniGrid-Optimal-4Goals"
    assert first.stratum == ("MiniGrid-Optimal-4Goals", "subset", 0.1) and main.rows == sorted(main.rows)
    with pytest.raises(dataclasses.FrozenInstanceError):
        first.observability = 0.5  # type: ignore[misc]
    assert main.cell(first, "BC-GRAIL").recognizer == "bc" and main.cell(first, "nothing") is None
    assert main.columns[-1] == "Demonstrator (perfect imitation)" and main.is_reference(main.columns[-1])
    assert main.best(first) == 0.9  # the demonstrator's 0.99 is a reference, not a winner
    assert [b.columns for b in board.variants] == [["GAIL-GRAIL · total_timesteps 40 000"]]


def test_terminal_boards_fit_80_columns_without_cutting_names(board):
    console = Console(width=80, record=True, color_system=None)
    for table in rich_tables(board.boards + board.variants):
        console.print(table)
    text = console.export_text()
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "…" not in text and "GRAIL/" not in text
    words = {w.rstrip(":") for w in text.split()}
    for b in board.boards + board.variants:
        for label in b.columns:
            assert set(label.split()) <= words  # every word of every name whole
    flat = " ".join(text.split())
    assert LEGEND.split(";")[0] in flat  # "[0.83] = normalised F1, (F1 - chance) / (ceiling - chance)"
    assert "0.73 ± 0.33" in flat and "(reference)" in flat


def test_terminal_boards_use_the_width_they_have(board):
    wide = Console(width=250, record=True, color_system=None)
    for table in rich_tables(board.boards):
        wide.print(table)
    header = next(line for line in wide.export_text().splitlines() if "BC-GRAIL" in line)
    assert "GAIL-GRAIL" in header and "DRACO" in header  # one column per method when they fit
