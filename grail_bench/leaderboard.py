"""Paper-style tables from the results store: terminal (rich) and Markdown.

One table per domain and regime, like the paper's Table 2: a row per goal
count and observability level, a column per recognizer (``name/scorer`` when a
recognizer was run with several scorers), cells ``mean ± std`` of F1 over
seeds, the best mean of each row in bold. Values the paper reports can be
shown beside ours from a CSV (``task,recognizer,observability,f1``).
"""

from __future__ import annotations

import csv
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

from rich.table import Table

PAPER_NAMES = {"bc": "BC-GRAIL", "gail": "GAIL-GRAIL", "airl": "AIRL-GRAIL", "graql": "GRAQL", "draco": "DRACO"}


@dataclass
class Board:
    """One table: a domain and regime, its rows and columns."""

    title: str
    columns: list[str]
    rows: list[tuple[int, float]] = field(default_factory=list)
    cells: dict[tuple[int, float, str], dict[str, Any]] = field(default_factory=dict)
    reported: dict[tuple[int, float, str], str] = field(default_factory=dict)


def _task_facts(task_id: str) -> tuple[str, int]:
    """``("minigrid / optimal", n_goals)`` for a task (its ID if no longer registered)."""
    from grail_bench.task import make_task

    try:
        task = make_task(task_id)
    except Exception:  # noqa: BLE001 - a stored task whose card is gone still gets a table
        return task_id, 0
    return f"{task.domain} / {task.regime}", len(task.goals)


def column_label(record: dict[str, Any], multi_scorer: set[str], multi_config: set[tuple[str, str]]) -> str:
    label = record["recognizer"]
    if label in multi_scorer:
        label += f"/{record['scorer']}"
    if (record["recognizer"], record["scorer"]) in multi_config:
        label += f" [{record['config_hash'][:6]}]"
    return label


def read_reference(path: str | Path) -> dict[tuple[str, str, float], str]:
    """Reported values: ``{(task, recognizer, observability): "0.93 ± 0.20"}``."""
    out = {}
    with open(path, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(line for line in fh if not line.startswith("#")):
            try:
                out[(row["task"], row["recognizer"], round(float(row["observability"]), 6))] = row["f1"].strip()
            except (KeyError, ValueError) as exc:
                raise ValueError(f"{path}: malformed reference row {row}: {exc}") from None
    return out


def build_boards(records: Iterable[dict[str, Any]], reference: dict[tuple[str, str, float], str] | None = None) -> list[Board]:
    """Group aggregated records into tables (see module docstring)."""
    records = list(records)
    scorers, configs = defaultdict(set), defaultdict(set)
    for r in records:
        scorers[r["recognizer"]].add(r["scorer"])
        configs[(r["task"], r["recognizer"], r["scorer"])].add(r["config_hash"])
    multi_scorer = {k for k, v in scorers.items() if len(v) > 1}
    multi_config = {(k[1], k[2]) for k, v in configs.items() if len(v) > 1}

    boards: dict[str, Board] = {}
    for r in records:
        title, n_goals = _task_facts(r["task"])
        board = boards.setdefault(title, Board(title=title, columns=[]))
        label = column_label(r, multi_scorer, multi_config)
        if label not in board.columns:
            board.columns.append(label)
        row = (n_goals, r["observability"])
        if row not in board.rows:
            board.rows.append(row)
        board.cells[(*row, label)] = r
        if reference:
            reported = reference.get((r["task"], r["recognizer"], round(r["observability"], 6)))
            if reported:
                board.reported[(*row, label)] = reported
    for board in boards.values():
        board.rows.sort()
        board.columns.sort()
    return [boards[k] for k in sorted(boards)]


def _best(board: Board, row: tuple[int, float]) -> float | None:
    means = [board.cells[(*row, c)]["f1_mean"] for c in board.columns if (*row, c) in board.cells]
    return max(means) if means else None


def _cell(board: Board, row: tuple[int, float], column: str) -> tuple[str, bool]:
    record = board.cells.get((*row, column))
    if record is None:
        return "–", False
    text = f"{record['f1_mean']:.2f} ± {record['f1_std']:.2f}"
    return text, record["f1_mean"] == _best(board, row)


def rich_tables(boards: list[Board]) -> list[Table]:
    """Terminal tables (best mean per row in bold)."""
    tables = []
    for board in boards:
        table = Table(title=f"F1 (mean ± std over seeds): {board.title}")
        table.add_column("goals", justify="right")
        table.add_column("obs", justify="right")
        for c in board.columns:
            table.add_column(c, justify="center")
            if board.reported:
                table.add_column(f"{c} (paper)", justify="center", style="dim")
        for row in board.rows:
            cells = []
            for c in board.columns:
                text, best = _cell(board, row, c)
                cells.append(f"[bold]{text}[/]" if best else text)
                if board.reported:
                    cells.append(board.reported.get((*row, c), "–"))
            table.add_row(str(row[0]), f"{row[1]:.0%}", *cells)
        tables.append(table)
    return tables


def markdown(boards: list[Board], records: list[dict[str, Any]]) -> str:
    """The leaderboard as Markdown, with seeds and timings under each table."""
    lines = ["# grail-bench leaderboard", "",
             "F1 of each recognizer, mean ± std over seeds (best of each row in bold).",
             "Columns marked *(paper)* are the values the GRAIL paper (AAMAS 2026) reports, transcribed",
             "from its tables and text; they were not produced by grail-bench.", ""]
    for board in boards:
        header = ["goals", "obs"]
        for c in board.columns:
            header.append(c)
            if board.reported:
                header.append(f"{PAPER_NAMES.get(c.split('/')[0], c)} *(paper)*")
        lines += [f"## {board.title}", "", "| " + " | ".join(header) + " |",
                  "|" + "---|" * len(header)]
        for row in board.rows:
            cells = [str(row[0]), f"{row[1]:.0%}"]
            for c in board.columns:
                text, best = _cell(board, row, c)
                cells.append(f"**{text}**" if best else text)
                if board.reported:
                    cells.append(board.reported.get((*row, c), "–"))
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["## Runs and timings", "",
              "| task | recognizer | scorer | seeds | fit s/goal | score µs/observation | ties |",
              "|---|---|---|---|---|---|---|"]
    seen = set()
    for r in records:
        key = (r["task"], r["recognizer"], r["scorer"], r["config_hash"])
        if key in seen:
            continue
        seen.add(key)
        same = [x for x in records if (x["task"], x["recognizer"], x["scorer"], x["config_hash"]) == key]
        score_us = sum(x["score_us_per_observation"] for x in same) / len(same)
        ties = sum(x["tie_rate"] for x in same) / len(same)
        lines.append(f"| {r['task']} | {r['recognizer']} | {r['scorer']} | {r['n_seeds']} | "
                     f"{r['fit_seconds_per_goal']:.2f} | {score_us:.0f} | {ties:.1%} |")
    return "\n".join(lines) + "\n"
