"""Paper-style tables from the results store: terminal (rich) and Markdown.

One table per domain, regime and observation protocol, like the paper's
Table 2: a row per goal count and observability level, a column per recognizer
(``name/scorer`` when a recognizer was run with several scorers), cells
``mean ± std`` of F1 over seeds, the best mean of each row in bold. Values the
paper reports can be shown beside ours from a CSV
(``task,recognizer,observability,f1``), on the rows of each task's default
protocol only. Where a task has a Bayes ceiling (MiniGrid), each row shows it
and each cell its normalised F1, ``(F1 - chance) / (ceiling - chance)``.
"""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterable, Sequence

from rich.table import Table

from grail_bench.errors import UserError


Row = tuple[int, str, str, float]  # (goals, task, protocol, observability)
MARKS = {"inside": "=", "above": "▲", "below": "▼"}  # our mean against the paper's 95 % interval


@dataclass(frozen=True)
class Reported:
    """A value the paper reports: its text and, where the appendix gives it, its 95 % interval."""

    text: str
    ci95: tuple[float, float] | None = None

    def place(self, mean: float) -> str | None:
        """``"inside"``, ``"above"`` or ``"below"`` the interval (None without one)."""
        if self.ci95 is None:
            return None
        low, high = self.ci95
        return "below" if mean < low - 1e-9 else "above" if mean > high + 1e-9 else "inside"

    def __str__(self) -> str:
        return self.text + (f" [{self.ci95[0]:.2f}, {self.ci95[1]:.2f}]" if self.ci95 else "")


@dataclass
class Board:
    """One table: a domain and regime, its rows and columns."""

    title: str
    columns: list[str]
    rows: list[Row] = field(default_factory=list)
    cells: dict[tuple[int, str, str, float, str], dict[str, Any]] = field(default_factory=dict)
    reported: dict[tuple[int, str, str, float, str], Reported] = field(default_factory=dict)
    ceilings: dict[Row, Any] = field(default_factory=dict)  # Row -> grail_bench.evaluation.ceiling.Ceiling


@lru_cache(maxsize=None)
def _paper_method(recognizer: str) -> tuple[str, str | None]:
    """``(published name, published scorer)`` from the recognizer's metadata (its own name and no scorer if
    it is not registered here)."""
    from grail_bench.recognizers.registry import UnknownRecognizerError, recognizer_info

    try:
        info = recognizer_info(recognizer)
    except UnknownRecognizerError:
        return recognizer, None
    return info.paper_name, info.default_scorer


def _task(task_id: str, params: dict[str, Any] | None = None):
    """The registered task (with the parameters a run used), or None for a stored task whose card is gone."""
    from gymnasium.error import Error as GymError

    from grail_bench.task import make_task

    try:
        return make_task(task_id, **(params or {}))
    except (GymError, UserError):
        return None


def column_label(record: dict[str, Any], variants: dict[tuple[str, str], list[str] | None]) -> str:
    """``recognizer/scorer`` (just the recognizer for plugins without scorers).

    A recognizer run with several configurations gets one column per
    configuration, named by the settings that tell them apart (``sac_steps=60000``)
    or, when only the task's parameters differ, by the configuration hash.
    """
    label = record["recognizer"]
    if record["scorer"] != "default":
        label += f"/{record['scorer']}"
    key = (record["recognizer"], record["scorer"])
    if key in variants:
        keys = variants[key]
        config = record.get("recognizer_config") or {}
        if keys:
            label += " " + " ".join(f"{k}={json.dumps(config.get(k))}" for k in keys)
        else:
            label += f" [{record['config_hash'][:6]}]"
    return label


def config_variants(records: Sequence[dict[str, Any]]) -> dict[tuple[str, str], list[str] | None]:
    """The recognizer settings that tell apart the configurations of each ``(recognizer, scorer)``.

    Only pairs run with more than one configuration on some task appear; their
    value is the sorted list of differing settings, or None when those settings
    do not separate the runs (they differ in task parameters) and only the hash can.
    """
    groups: dict[tuple[str, str, str], dict[str, dict[str, str]]] = defaultdict(dict)
    for r in records:
        config = {k: json.dumps(v, sort_keys=True) for k, v in (r.get("recognizer_config") or {}).items()}
        groups[(r["task"], r["recognizer"], r["scorer"])][r["config_hash"]] = config
    keys: dict[tuple[str, str], set[str] | None] = {}
    for (_, rec, scorer), by_hash in groups.items():
        if len(by_hash) < 2 or keys.get((rec, scorer), set()) is None:
            continue
        names = {k for c in by_hash.values() for k in c}
        differing = {k for k in names if len({c.get(k) for c in by_hash.values()}) > 1}
        separated = len({tuple(c.get(k) for k in sorted(differing)) for c in by_hash.values()}) == len(by_hash)
        keys[(rec, scorer)] = (keys.get((rec, scorer)) or set()) | differing if separated else None
    return {pair: sorted(k) if k else None for pair, k in keys.items()}


def read_reference(path: str | Path) -> dict[tuple[str, str, float], Reported]:
    """Reported values by ``(task, recognizer, observability)``.

    The CSV has columns ``task,recognizer,observability,f1`` and optionally
    ``ci95`` (``[low; high]``).
    """
    out = {}
    with open(path, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(line for line in fh if not line.startswith("#")):
            try:
                ci_text = (row.get("ci95") or "").strip().strip("[]")
                ci = tuple(float(v) for v in ci_text.split(";")) if ci_text else None
                if ci is not None and (len(ci) != 2 or ci[0] > ci[1]):
                    raise UserError(f"ci95 must be [low; high], got {row['ci95']!r}")
                out[(row["task"], row["recognizer"], round(float(row["observability"]), 6))] = Reported(
                    row["f1"].strip(), ci)
            except (KeyError, ValueError, AttributeError) as exc:
                raise UserError(f"{path}: malformed reference row {row}: {exc}") from None
    return out


def build_boards(records: Iterable[dict[str, Any]], reference: dict[tuple[str, str, float], str] | None = None,
                 ceiling_samples: int | None = 2000) -> list[Board]:
    """Group aggregated records into tables (see module docstring).

    Args:
        records: Aggregated records (:func:`grail_bench.evaluation.runner.aggregate`).
        reference: Reported values to show beside ours.
        ceiling_samples: Monte Carlo samples of the Bayes ceilings (computed
            once, then cached on disk); None shows no ceilings.
    """
    from grail_bench.evaluation.ceiling import cached_ceiling

    records = list(records)
    tasks = {t: _task(t) for t in {r["task"] for r in records}}
    params_by_row = defaultdict(list)  # the task parameters each row's runs used
    for r in records:
        params_by_row[(r["task"], r["protocol"], r["observability"])].append(r.get("task_params") or {})
    variants = config_variants(records)

    boards: dict[str, Board] = {}
    for r in records:
        task = tasks[r["task"]]
        title = f"{task.domain} / {task.regime}" if task else r["task"]
        title += f" ({r['protocol']})"
        board = boards.setdefault(title, Board(title=title, columns=[]))
        label = column_label(r, variants)
        if label not in board.columns:
            board.columns.append(label)
        row = (len(task.goals) if task else 0, r["task"], r["protocol"], r["observability"])
        if row not in board.rows:
            board.rows.append(row)
            used = params_by_row[(r["task"], r["protocol"], r["observability"])]
            # A row whose runs used different task parameters has no single ceiling.
            run_task = _task(r["task"], used[0]) if task is not None and all(p == used[0] for p in used) else None
            if run_task is not None and ceiling_samples is not None:
                ceiling = cached_ceiling(run_task, r["protocol"], r["observability"], samples=ceiling_samples)
                if ceiling is not None:
                    board.ceilings[row] = ceiling
        board.cells[(*row, label)] = r
        paper_protocol = task is not None and r["protocol"] == task.protocol
        if reference and paper_protocol and _paper_method(r["recognizer"])[1] in (r["scorer"], None):
            reported = reference.get((r["task"], r["recognizer"], round(r["observability"], 6)))
            if reported:
                board.reported[(*row, label)] = reported
    for board in boards.values():
        board.rows.sort()
        board.columns.sort()
    return [boards[k] for k in sorted(boards)]


def _has_reported(board: Board, column: str) -> bool:
    return any(key[-1] == column for key in board.reported)


def short_name(task_id: str) -> str:
    """``GRAIL/MiniGrid-Optimal-4Goals-v0`` -> ``MiniGrid-Optimal-4Goals``."""
    name = task_id.removeprefix("GRAIL/")
    return name.rsplit("-v", 1)[0] if "-v" in name else name


def _best(board: Board, row: Row) -> float | None:
    means = [board.cells[(*row, c)]["f1_mean"] for c in board.columns if (*row, c) in board.cells]
    return max(means) if means else None


def _cell(board: Board, row: Row, column: str, ci: bool = False) -> tuple[str, bool]:
    from grail_bench.evaluation.ceiling import normalised

    record = board.cells.get((*row, column))
    if record is None:
        return "–", False
    text = f"{record['f1_mean']:.2f} ± {record['f1_std']:.2f}"
    if ci:
        text += f" ({record['f1_ci95_low']:.2f}–{record['f1_ci95_high']:.2f})"
    reported = board.reported.get((*row, column))
    place = reported.place(record["f1_mean"]) if reported else None
    if place:
        text += f" {MARKS[place]}"
    ceiling = board.ceilings.get(row)
    if ceiling is not None:
        norm = normalised(record["f1_mean"], ceiling.accuracy, ceiling.chance)
        text += f" [{norm:.2f}]" if norm is not None else ""
    return text, record["f1_mean"] == _best(board, row)


def _ceiling_text(board: Board, row: Row) -> str:
    ceiling = board.ceilings.get(row)
    if ceiling is None:
        return "–"
    return f"{ceiling.accuracy:.2f}" + (f" ± {ceiling.stderr:.2f}" if ceiling.method == "monte-carlo" else "")


def _grid(board: Board, paper_label: Any = str, ci: bool = False) -> tuple[list[str], list[list[tuple[str, bool]]]]:
    """The table model both renderers draw: a header and, per row, ``(text, best)`` cells."""
    header = ["task", "goals", "obs", "ceiling"]
    for c in board.columns:
        header.append(c)
        if _has_reported(board, c):
            header.append(paper_label(c))
    rows = []
    for row in board.rows:
        cells = [(short_name(row[1]), False), (str(row[0]), False), (f"{row[3]:.0%}", False),
                 (_ceiling_text(board, row), False)]
        for c in board.columns:
            cells.append(_cell(board, row, c, ci))
            if _has_reported(board, c):
                cells.append((str(board.reported.get((*row, c), "–")), False))
        rows.append(cells)
    return header, rows


def rich_tables(boards: list[Board]) -> list[Table]:
    """Terminal tables (best mean per row in bold)."""
    tables = []
    for board in boards:
        header, rows = _grid(board, lambda c: f"{c} (paper)")
        table = Table(title=f"F1 (mean ± std over seeds) [normalised F1]: {board.title}")
        for name in header:
            table.add_column(name, justify="center", style="dim" if name.endswith("(paper)") else None)
        for cells in rows:
            table.add_row(*(f"[bold]{text}[/]" if best else text for text, best in cells))
        tables.append(table)
    return tables


def placement_counts(boards: list[Board]) -> dict[str, int]:
    """How many of our cells fall inside, above and below the paper's 95 % intervals."""
    counts = {place: 0 for place in MARKS}
    for board in boards:
        for key, reported in board.reported.items():
            place = reported.place(board.cells[key]["f1_mean"])
            if place:
                counts[place] += 1
    return counts


def markdown(boards: list[Board], records: list[dict[str, Any]], ci: bool = False,
             title: str = "grail-bench leaderboard") -> str:
    """The leaderboard as Markdown, with seeds and timings under each table.

    Args:
        ci: Also show each cell's 95 % Student-t interval over seeds (the paper's appendix format).
        title: The document's heading.
    """
    lines = [f"# {title}", "",
             "F1 of each recognizer, mean ± std over seeds" + (" (95 % CI over seeds)" if ci else "")
             + " (best of each row in bold). Where the task has a",
             "Bayes ceiling (the best accuracy any recognizer can reach under that protocol and level; ± its",
             "Monte Carlo standard error), the cell adds the normalised F1 in brackets,",
             "(F1 - chance) / (ceiling - chance).",
             "Columns marked *(paper)* are the values the GRAIL paper (AAMAS 2026) reports, transcribed",
             "from its tables and text; they were not produced by grail-bench, and are shown on the rows",
             "of each task's default protocol only.", ""]
    counts = placement_counts(boards)
    if any(counts.values()):
        lines += [f"Against the paper's 95 % intervals (appendix tables): our mean is inside (=) in {counts['inside']} "
                  f"cells, above (▲) in {counts['above']}, below (▼) in {counts['below']}.", ""]
    for board in boards:
        header, rows = _grid(board, lambda c: f"{_paper_method(c.split('/')[0])[0]} *(paper)*", ci)
        lines += [f"## {board.title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(f"**{text}**" if best else text for text, best in cells) + " |"
                  for cells in rows]
        lines.append("")
    lines += ["## Runs, timings and ranking", "",
              "Top-2: share of observations whose true goal is among the 2 best scored; mean rank of the true",
              "goal (1 = best); both averaged over levels and protocols (– where rows stored before they were",
              "recorded take part).", "",
              "| task | column | seeds | fit s/goal | score µs/observation | ties | top-2 | mean rank |",
              "|---|---|---|---|---|---|---|---|"]
    for t in timing_rows(records):
        ranking = " | ".join("–" if t[k] is None else f"{t[k]:.2f}" for k in ("top2", "mean_rank"))
        lines.append(f"| {t['task']} | {t['column']} | {t['seeds']} | {t['fit_seconds_per_goal']:.2f} | "
                     f"{t['score_us_per_observation']:.0f} | {t['tie_rate']:.1%} | {ranking} |")
    return "\n".join(lines) + "\n"


def timing_rows(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per task and column: seeds, training seconds per goal, and the means over levels of the scoring µs per
    observation, tie rate, top-2 accuracy and mean rank (``None`` when a level lacks them)."""
    variants = config_variants(records)
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        groups[(r["task"], r["recognizer"], r["scorer"], r["config_hash"])].append(r)
    return [{"task": same[0]["task"], "column": column_label(same[0], variants), "recognizer": same[0]["recognizer"],
             "seeds": same[0]["n_seeds"],
             "fit_seconds_per_goal": same[0]["fit_seconds_per_goal"],
             "score_us_per_observation": sum(x["score_us_per_observation"] for x in same) / len(same),
             "tie_rate": sum(x["tie_rate"] for x in same) / len(same),
             **{key: _level_mean(same, f"{key}_mean") for key in ("top2", "mean_rank")}} for same in groups.values()]


def _level_mean(records: list[dict[str, Any]], key: str) -> float | None:
    values = [r.get(key) for r in records]
    return None if any(v is None for v in values) else sum(values) / len(values)


def ablation_rows(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per task and protocol, recognizer and scorer: F1 at each level and mean scoring time.

    Only recognizers run with more than one scorer on a task are included
    (the paper's Figures 4 and 5).
    """
    scorers = defaultdict(set)
    for r in records:
        scorers[(r["task"], r["protocol"], r["recognizer"])].add(r["scorer"])
    out: dict[tuple, dict[str, Any]] = {}
    for r in records:
        if len(scorers[(r["task"], r["protocol"], r["recognizer"])]) < 2:
            continue
        task = f"{r['task']} ({r['protocol']})"  # protocols are compared apart
        row = out.setdefault((task, r["recognizer"], r["scorer"]), {
            "task": task, "recognizer": r["recognizer"], "scorer": r["scorer"], "f1": {}, "score_us": []})
        row["f1"][r["observability"]] = (r["f1_mean"], r["f1_std"])
        row["score_us"].append(r["score_us_per_observation"])
        if r.get("brier_mean") is not None:
            row.setdefault("calibration", []).append((r["brier_mean"], r["nll_mean"]))
    for row in out.values():
        row["score_us"] = sum(row["score_us"]) / len(row["score_us"])
        row["f1_overall"] = sum(m for m, _ in row["f1"].values()) / len(row["f1"])
    return [out[k] for k in sorted(out)]


def ablation_table(rows: list[dict[str, Any]]) -> Table:
    """Terminal table of :func:`ablation_rows`."""
    levels = sorted({lv for r in rows for lv in r["f1"]})
    table = Table(title="scorer ablation: F1 (mean ± std) and scoring time")
    for col in ("task", "recognizer", "scorer"):
        table.add_column(col)
    for lv in levels:
        table.add_column(f"F1 @ {lv:.0%}", justify="center")
    table.add_column("µs / observation", justify="right")
    table.add_column("Brier / NLL", justify="center")
    for r in rows:
        cal = r.get("calibration")
        cal_text = (f"{sum(b for b, _ in cal) / len(cal):.3f} / {sum(n for _, n in cal) / len(cal):.3f}"
                    if cal else "–")
        cells = [f"{r['f1'][lv][0]:.2f} ± {r['f1'][lv][1]:.2f}" if lv in r["f1"] else "–" for lv in levels]
        table.add_row(r["task"], r["recognizer"], r["scorer"], *cells, f"{r['score_us']:.0f}", cal_text)
    return table


def ablation_markdown(rows: list[dict[str, Any]]) -> str:
    """:func:`ablation_rows` as a Markdown table."""
    levels = sorted({lv for r in rows for lv in r["f1"]})
    header = ["task", "recognizer", "scorer", *[f"F1 @ {lv:.0%}" for lv in levels], "µs / observation", "Brier", "NLL"]
    lines = ["# Scorer ablation", "",
             "F1 (mean ± std over seeds) of each recognizer under each scorer, from the same fitted policies,",
             "and the mean time to score one observation against all goals. Brier score and NLL are those of",
             "the posterior over goals that the `loglik` scorer yields.", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        cal = r.get("calibration")
        brier = f"{sum(b for b, _ in cal) / len(cal):.3f}" if cal else "–"
        nll = f"{sum(n for _, n in cal) / len(cal):.3f}" if cal else "–"
        cells = [f"{r['f1'][lv][0]:.2f} ± {r['f1'][lv][1]:.2f}" if lv in r["f1"] else "–" for lv in levels]
        lines.append(f"| {r['task']} | {r['recognizer']} | {r['scorer']} | " + " | ".join(cells)
                     + f" | {r['score_us']:.0f} | {brier} | {nll} |")
    return "\n".join(lines) + "\n"


def ablation_plot(rows: list[dict[str, Any]], path: str | Path) -> None:
    """Grouped bars per task: F1 (mean over levels) and scoring time, by recognizer and scorer."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    tasks = sorted({r["task"] for r in rows})
    colours = {name: f"C{i}" for i, name in enumerate(sorted({r["scorer"] for r in rows}))}  # one per scorer
    fig, axes = plt.subplots(len(tasks), 2, figsize=(11, 3.2 * len(tasks)), squeeze=False)
    for ax_f1, ax_time, task in zip(axes[:, 0], axes[:, 1], tasks):
        mine = [r for r in rows if r["task"] == task]
        recs = sorted({r["recognizer"] for r in mine})
        scorers = sorted({r["scorer"] for r in mine})
        width = 0.8 / len(scorers)
        for i, scorer in enumerate(scorers):
            xs, f1s, times = [], [], []
            for j, rec in enumerate(recs):
                hit = [r for r in mine if r["recognizer"] == rec and r["scorer"] == scorer]
                if hit:
                    xs.append(j + i * width)
                    f1s.append(hit[0]["f1_overall"])
                    times.append(hit[0]["score_us"])
            ax_f1.bar(xs, f1s, width, label=scorer, color=colours[scorer])
            ax_time.bar(xs, times, width, label=scorer, color=colours[scorer])
        for ax, ylabel in ((ax_f1, "F1 (mean over observability)"), (ax_time, "scoring µs / observation")):
            ax.set_xticks(np.arange(len(recs)) + 0.4 - width / 2, recs)
            ax.set_ylabel(ylabel)
            ax.set_title(task, fontsize=9)
        ax_f1.set_ylim(0, 1.05)
        ax_time.legend(fontsize=8, loc="lower right", framealpha=0.9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
