"""Terminal (rich) and Markdown renderings of the boards (the paper-style F1 tables) and the leaderboard document.

Every table is built once as a header and rows of text (a *grid*), then drawn
by rich or written as Markdown; nothing here computes a statistic or a ceiling.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

from rich.table import Table

from grail_bench.harness.ceiling import Ceiling, normalised
from grail_bench.report.boards import (
    Board,
    Row,
    paper_method,
    placement_counts,
    row_name,
    verdict_counts,
)
from grail_bench.report.reference import MARKS
from grail_bench.report.rows import timing_rows
from grail_bench.task.observation import level_text

Grid = tuple[list[str], list[list[tuple[str, bool]]]]  # header; per row, (text, bold) cells

VERDICT_MARKS = {"consistent": "", "higher": "↑", "lower": "↓"}


def _cell(board: Board, row: Row, column: str, ci: bool = False) -> tuple[str, bool]:
    record = board.cells.get((*row, column))
    if record is None:
        return "–", False
    text = f"{record.f1_mean:.2f} ± {record.f1_std:.2f}"
    if ci:
        text += f" ({record.f1_ci95_low:.2f}–{record.f1_ci95_high:.2f})"
    reported = board.reported.get((*row, column))
    if reported is not None:
        place = reported.place(record.f1_mean)
        verdict = reported.verdict(list(record.f1_values))
        text += f" {MARKS[place]}" if place else ""
        text += VERDICT_MARKS[verdict.verdict] if verdict else ""
    ceiling = board.ceilings.get(row)
    if ceiling is not None:
        norm = normalised(record.f1_mean, ceiling.accuracy, ceiling.chance)
        text += f" [{norm:.2f}]" if norm is not None else ""
    return text, record.f1_mean == board.best(row)


def _ceiling_text(ceiling: Ceiling | None) -> str:
    if ceiling is None:
        return "–"
    return f"{ceiling.accuracy:.2f}" + (f" ± {ceiling.stderr:.2f}" if ceiling.method == "monte-carlo" else "")


def board_grid(board: Board, paper_label: Callable[[str], str] = str, ci: bool = False) -> Grid:
    """The table model both renderers draw: a header and, per row, ``(text, best)`` cells."""
    header = ["task", "goals", "obs", "ceiling"] + (["pairs-only"] if board.pairs_only else [])
    for c in board.columns:
        header.append(c)
        if board.has_reported(c):
            header.append(paper_label(c))
    rows = []
    for row in board.rows:
        cells = [(row_name(row), False), (str(row[0]), False), (level_text(row[3]), False),
                 (_ceiling_text(board.ceilings.get(row)), False)]
        if board.pairs_only:
            cells.append((_ceiling_text(board.pairs_only.get(row)), False))
        for c in board.columns:
            cells.append(_cell(board, row, c, ci))
            if board.has_reported(c):
                cells.append((str(board.reported.get((*row, c), "–")), False))
        rows.append(cells)
    return header, rows


def rich_tables(boards: Sequence[Board]) -> list[Table]:
    """Terminal tables (best mean per row in bold)."""
    tables = []
    for board in boards:
        header, rows = board_grid(board, lambda c: f"{c} (paper)")
        table = Table(title=f"F1 (mean ± std over seeds) [normalised F1]: {board.title}")
        for name in header:
            table.add_column(name, justify="center", style="dim" if name.endswith("(paper)") else None)
        for cells in rows:
            table.add_row(*(f"[bold]{text}[/]" if best else text for text, best in cells))
        tables.append(table)
    return tables


def comparison_lines(boards: Sequence[Board]) -> list[str]:
    """The counts of our cells against the reported values: placement and Welch verdicts (empty without any)."""
    places, verdicts = placement_counts(boards), verdict_counts(boards)
    lines = []
    if any(places.values()):
        lines.append(f"Against the paper's 95 % intervals (appendix tables): our mean is inside (=) in "
                     f"{places['inside']} cells, above (▲) in {places['above']}, below (▼) in {places['below']}.")
    if any(verdicts.values()):
        lines.append(f"Two-sided Welch test of our seeds against the paper's mean and std over its 10 seeds "
                     f"(alpha 0.05): consistent in {verdicts['consistent']} cells, significantly higher (↑) in "
                     f"{verdicts['higher']}, lower (↓) in {verdicts['lower']}.")
    return lines


def markdown(boards: Sequence[Board], records: Sequence[Any], ci: bool = False,
             title: str = "grail-bench leaderboard", fits: dict | None = None) -> str:
    """The leaderboard as Markdown, with seeds, timings and ranking metrics under the tables.

    Args:
        ci: Also show each cell's 95 % Student-t interval over seeds (the paper's appendix format).
        title: The document's heading.
        fits: Fit diagnostics by (task, recognizer, config hash), for the share of fits reaching their goal.
    """
    lines = [f"# {title}", "",
             "F1 of each recognizer, mean ± std over seeds" + (" (95 % CI over seeds)" if ci else "")
             + " (best of each row in bold). Where the task has a",
             "Bayes ceiling (the best accuracy any recognizer can reach under that protocol and level; ± its",
             "Monte Carlo standard error), the cell adds the normalised F1 in brackets,",
             "(F1 - chance) / (ceiling - chance). The pairs-only ceiling is the accuracy of scoring each goal",
             "from the observed pairs through that goal's own demonstrator (as GRAIL, GRAQL and DRACO score,",
             "with perfect policies): how far a method is from what its form allows.",
             "Columns marked *(paper)* are the values the GRAIL paper (AAMAS 2026) reports, transcribed",
             "from its tables and text; they were not produced by grail-bench, and are shown on the rows",
             "of each task's default protocol only.", ""]
    comparison = comparison_lines(boards)
    if comparison:
        lines += [" ".join(comparison), ""]
    for board in boards:
        header, rows = board_grid(board, lambda c: f"{paper_method(c.split('/')[0])[0]} *(paper)*", ci)
        lines += [f"## {board.title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(f"**{text}**" if best else text for text, best in cells) + " |"
                  for cells in rows]
        lines.append("")
    lines += ["## Runs, timings and ranking", "",
              "Top-2: share of observations whose true goal is among the 2 best scored; mean rank of the true",
              "goal (1 = best); both averaged over levels and protocols (– where rows stored before they were",
              "recorded take part). Set: the goals scored within 10 % of the scores' range of the best (the",
              "set-valued answer of the planning-based GR literature); its precision (1/size when it holds the",
              "true goal), recall (whether it does) and spread (its size). Goal reached: of the goal policies",
              "fitted over all seeds, how many reach their goal when rolled out greedily from the task's start",
              "(– where no diagnostics are stored).", "",
              "| task | column | seeds | fit s/goal | score µs/observation | ties | top-2 | mean rank | set precision | "
              "set recall | set spread | goal reached |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for t in timing_rows(records, fits):
        ranking = " | ".join("–" if t[k] is None else f"{t[k]:.2f}"
                             for k in ("top2", "mean_rank", "set_precision", "set_recall", "set_spread"))
        lines.append(f"| {t['task']} | {t['column']} | {t['seeds']} | {t['fit_seconds_per_goal']:.2f} | "
                     f"{t['score_us_per_observation']:.0f} | {t['tie_rate']:.1%} | {ranking} | {t['reached'] or '–'} |")
    return "\n".join(lines) + "\n"
