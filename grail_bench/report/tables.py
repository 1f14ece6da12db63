"""Terminal (rich) and Markdown renderings of everything beside the boards: the task, recognizer and
protocol listings, ceilings, fit diagnostics, timings, the scorer ablation, the modes' tables, budget studies
and calibration.

Each table is built from rows computed elsewhere (:mod:`grail_bench.report.rows`, the modes' records);
nothing here computes a statistic or a ceiling. Terminal tables fit the console's width
(:class:`grail_bench.report.layout.Fitted`): every task and recognizer name shows whole, and a legend under a
table says what bracketed or marked values are.
"""

from __future__ import annotations

import textwrap
from typing import Any, Sequence

from rich.table import Table
from rich.text import Text

from grail_bench.harness.modes import Mode
from grail_bench.report.escape import md
from grail_bench.report.layout import Fitted, grid_table, stacked
from grail_bench.report.rows import AblationRow, BudgetCurve, CalibrationRow, timing_rows
from grail_bench.report.shifts import RegimeCell, ShiftCurve, figure_stems, regime_order, row_label
from grail_bench.task.observation import level_text

TASK_PREFIX = "GRAIL/"


def timing_table(records: Sequence[Any]) -> Fitted:
    """Terminal table of fit and scoring times per recognizer and scorer (means over seeds and levels)."""
    header = ["recognizer", "scorer", "fit s/goal", "score µs/observation"]
    rows = []
    for name, scorer in dict.fromkeys((r.recognizer, r.scorer) for r in records):
        mine = [r for r in records if (r.recognizer, r.scorer) == (name, scorer)]
        rows.append([name, scorer, f"{mine[0].fit_seconds_per_goal:.2f}",
                     f"{sum(r.score_us_per_observation for r in mine) / len(mine):.0f}"])
    title = "timings (mean over seeds)"
    return Fitted(grid_table(title, header, rows), stacked(title, header, rows, keys=2))


def _ablation_cells(r: AblationRow, levels: list[float]) -> list[str]:
    return [f"{r.f1[lv][0]:.2f} ± {r.f1[lv][1]:.2f}" if lv in r.f1 else "–" for lv in levels]


def _calibration(r: AblationRow) -> tuple[str, str, str]:
    if r.brier is None:
        return "–", "–", "–"
    return f"{r.brier:.3f}", f"{r.nll:.3f}", "–" if r.ece is None else f"{r.ece:.3f}"


def ablation_table(rows: Sequence[AblationRow]) -> Fitted:
    """Terminal table of :func:`grail_bench.report.rows.ablation_rows`."""
    levels = sorted({lv for r in rows for lv in r.f1})
    header = ["task", "recognizer", "scorer", *[f"F1 @ {level_text(lv)}" for lv in levels], "µs / observation",
              "Brier / NLL / ECE"]
    grid = []
    for r in rows:
        brier, nll, ece = _calibration(r)
        grid.append([r.task.removeprefix(TASK_PREFIX), r.recognizer, r.scorer, *_ablation_cells(r, levels),
                     f"{r.score_us:.0f}", "–" if brier == "–" else f"{brier} / {nll} / {ece}"])
    title = "scorer ablation: F1 (mean ± std over seeds) and scoring time"
    caption = "Brier / NLL / ECE: of the posterior over goals (the loglik scorer; – without one)."
    return Fitted(grid_table(title, header, grid, caption), stacked(title, header, grid, keys=3, caption=caption))


def ablation_markdown(rows: Sequence[AblationRow]) -> str:
    """:func:`grail_bench.report.rows.ablation_rows` as a Markdown table."""
    levels = sorted({lv for r in rows for lv in r.f1})
    header = ["task", "recognizer", "scorer", *[f"F1 @ {level_text(lv)}" for lv in levels], "µs / observation",
              "Brier", "NLL", "ECE"]
    lines = ["# Scorer ablation", "",
             "F1 (mean ± std over seeds) of each recognizer under each scorer, from the same fitted policies,",
             "and the mean time to score one observation against all goals. Brier score, NLL and the expected",
             "calibration error (ECE: 10 equal confidence bins, every level and seed pooled) are those of the",
             "posterior over goals that the `loglik` scorer yields.", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        brier, nll, ece = _calibration(r)
        lines.append(f"| {md(r.task)} | {md(r.recognizer)} | {md(r.scorer)} | " + " | ".join(_ablation_cells(r, levels))
                     + f" | {r.score_us:.0f} | {brier} | {nll} | {ece} |")
    return "\n".join(lines) + "\n"


def mode_grid(records: Sequence[Any], mode: Mode) -> tuple[list[str], list[list[str]]]:
    """Header and the rows of text of a mode's table (one row per record, the mode's columns)."""
    return [c.header for c in mode.columns], [[c.text(r) for c in mode.columns] for r in records]


#: The headers of the columns that say which run a mode's row is (stacked together at narrow widths).
RUN_HEADERS = ("task", "protocol", "obs", "recognizer/scorer")


def mode_table(records: Sequence[Any], mode: Mode) -> Fitted:
    """A mode's records as a terminal table, its intro as the legend under it."""
    header, rows = mode_grid(records, mode)
    keys = next((i for i, h in enumerate(header) if h not in RUN_HEADERS), len(header))
    return Fitted(grid_table(mode.title, header, rows, mode.intro),
                  stacked(mode.title, header, rows, keys=max(keys, 1), caption=mode.intro))


def mode_markdown(records: Sequence[Any], mode: Mode) -> str:
    """A mode's records as a Markdown document (title, what the table shows, the table)."""
    header, rows = mode_grid(records, mode)
    lines = [f"# {mode.title}", "", mode.intro, "", "| " + " | ".join(map(md, header)) + " |",
             "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(map(md, row)) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def tasks_table(tasks: Sequence[Any]) -> Fitted:
    """Every task (its full ID, as ``--task`` takes it) with its domain, regime, goals, demonstration counts,
    levels and protocol; at narrower widths the goals under the task's ID, at the narrowest each value on its own
    line."""
    title = f"{TASK_PREFIX} tasks" if all(t.id.startswith(TASK_PREFIX) for t in tasks) else "tasks"
    header = ["task", "domain", "regime", "goals", "demos/goal (train/test)", "observability", "protocol"]
    rows = [[task.id, task.domain, task.regime, " ".join(goal_label(g) for g in task.goals),
             f"{task.n_demos} ({task.n_train}/{task.n_demos - task.n_train})",
             ", ".join(level_text(p) for p in task.observability), task.protocol_label] for task in tasks]
    wide = grid_table(title, header, rows)
    wide.columns[0].no_wrap = True
    medium = Table(title=title, caption="Goals under each task's name; demos per goal: total (train/test).",
                   caption_justify="left")
    medium.add_column("task / goals", no_wrap=True)
    for col in ("domain / regime", "demos", "observed (protocol)"):
        medium.add_column(col)
    width = max([len(r[0]) for r in rows] + [20])
    for name, domain, regime, goals, demos, levels, protocol in rows:
        medium.add_row(Text.assemble((name, "bold"), "\n", ("\n".join(textwrap.wrap(goals, width)), "dim")),
                       f"{domain}\n{regime}", demos, f"{levels} ({protocol})")
    return Fitted(wide, medium, stacked(title, header, rows, key_width=None))  # IDs whole, to copy into --task


def names_table(title: str, rows: Sequence[tuple[str, str]], second: str) -> Table:
    """A two-column listing (name in bold and whole, then what provides or describes it, folded if it must)."""
    table = Table(title=title)
    table.add_column("name", style="bold", no_wrap=True)
    table.add_column(second, overflow="fold")
    for name, text in rows:
        table.add_row(Text(name), Text(text))
    return table


def protocols_table(rows: Sequence[tuple[str, bool, str]]) -> Table:
    """The observation protocols: name, whether it leaks the goal, what a recognizer observes."""
    table = Table(title="observation protocols (entry-point group grail_bench.protocols)")
    table.add_column("name", style="bold", no_wrap=True)
    table.add_column("leaks the goal")
    table.add_column("what a recognizer observes", overflow="fold")
    for name, leaks, text in rows:
        table.add_row(Text(name), "yes" if leaks else "no", Text(text))
    return table


def ceiling_table(task_id: str, ceilings: Sequence[Any]) -> Fitted:
    """Bayes ceilings of one task (one row per protocol and level)."""
    kind = "Pairs-only ceiling" if any(c.pairs_only for c in ceilings) else "Bayes ceiling"
    title = f"{kind} (accuracy): {task_id}"
    header = ["protocol", "obs", "ceiling", "std. error", "chance", "method"]
    rows = [[c.protocol, level_text(c.observability), f"{c.accuracy:.3f}",
             f"{c.stderr:.3f}" if c.method == "monte-carlo" else "exact", f"{c.chance:.3f}",
             c.method + (f" ({c.samples} samples)" if c.samples else "")] for c in ceilings]
    return Fitted(grid_table(title, header, rows, first_style=None), stacked(title, header, rows, keys=2))


def goal_label(goal: Sequence[float]) -> str:
    """``(7,1)``: a goal as the tables name it."""
    return "(" + ",".join(f"{c:g}" for c in goal) + ")"


def diagnostics_table(diagnostics: Any, title: str) -> Fitted:
    """Per goal: greedy rollout reached and its length, the demonstrations' length, agreement with its own
    training and held-out demonstrations, and its held-out actions' probability under its own and under the best
    other goal's policy."""
    header = ["goal", "reached", "rollout", "demos", "agreement train", "held-out", "own p", "best other p",
              "other goal"]
    labels = [goal_label(g) for g in diagnostics.goals]
    rows = []
    for i, label in enumerate(labels):
        row = diagnostics.imitation[i]
        others = [(v, j) for j, v in enumerate(row) if j != i and v is not None]
        best, j = max(others) if others else (None, None)
        reached = diagnostics.reached[i]
        rows.append([label, "–" if reached is None else "yes" if reached else "no",
                     "–" if diagnostics.rollout_length[i] is None else str(diagnostics.rollout_length[i]),
                     f"{diagnostics.demo_length[i]:.1f}", _num(diagnostics.agreement_train[i]),
                     _num(diagnostics.agreement_held_out[i]), _num(row[i]), _num(best),
                     labels[j] if j is not None else "–"])
    wide = grid_table(title, header, rows, first_style=None)
    for column in wide.columns:
        column.justify = "right"
    return Fitted(wide, stacked(title, header, rows))


def _num(value: float | None) -> str:
    return "–" if value is None or value != value else f"{value:.2f}"


def budgets_markdown(curves: Sequence[BudgetCurve], title: str) -> str:
    """Budget studies as Markdown: per task and recognizer, F1 at each value with its interval and fit cost."""
    lines = [f"# {title}: budget studies", "",
             "F1 (mean over seeds, [95 % interval]) of each recognizer under its own scorer at one observability",
             "level, against one training budget or the training demonstrations per goal, with the fit's seconds",
             "per goal. The interval is a seeded percentile bootstrap of the mean over seeds (it stays within the",
             "seeds' F1, so within [0, 1]; with one seed it is the value). Plateau: the smallest value whose mean",
             "F1 reaches the 95 % interval of the best value's (the rule that picks a default budget). A scaling",
             "study (n_goals) runs tasks of growing goal sets instead; its exponent b is the log-log slope of the",
             "whole fit's seconds (s/goal x goals) against the goal count: 1 is linear (one model per goal), 0 flat.",
             ""]
    for c in curves:
        lines += [f"## {md(c.recognizer)}: {md(c.param)} on {md(c.task.removeprefix(TASK_PREFIX))} "
                  f"({md(c.protocol)}, {level_text(c.observability)} observed)", ""]
        if c.scaling:
            lines += [f"Fit cost exponent: b = {_num(c.exponent)}.", ""]
        else:
            lines += [f"Plateau: {c.param} = {c.plateau}." if c.plateau is not None
                      else "Plateau: not determined (only one value has rows).", ""]
        lines += [f"| {md(c.param)} | seeds | F1 | 95 % interval | fit s/goal |", "|---|---|---|---|---|"]
        for p in c.points:
            mark = " (plateau)" if p.value == c.plateau else ""
            lines.append(f"| {md(p.value)}{mark} | {p.n_seeds} | {p.f1_mean:.2f} | [{p.f1_ci95_low:.2f}, "
                         f"{p.f1_ci95_high:.2f}] | {p.fit_seconds_per_goal:.2f} |")
        lines.append("")
    return "\n".join(lines)


def calibration_markdown(rows: Sequence[CalibrationRow]) -> str:
    """:func:`grail_bench.report.rows.calibration_rows` as Markdown."""
    lines = ["# Calibration", "",
             "Recognizers that give a posterior over goals (the `loglik` scorer: the softmax of summed",
             "log-likelihoods), per domain, every observation of every task, level and seed pooled: Brier score",
             "and NLL (means), and the expected calibration error (ECE) of the top-label confidence over 10 equal",
             "bins; `reliability.png` draws the bins.", "",
             "| domain | recognizer/scorer | records | Brier | NLL | ECE |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {md(r.domain)} | {md(r.column)} | {r.records} | {_num(r.brier)} | {_num(r.nll)} | {_num(r.ece)} |")
    return "\n".join(lines) + "\n"


#: How SHIFTS.md and REGIMES.md pool a configuration's levels (:mod:`grail_bench.report.shifts`).
POOLED = ("F1 is pooled over the observability levels: the mean over seeds of each seed's mean F1 over the levels, "
          "with the 95 % interval of that mean (a seeded percentile bootstrap of the seeds, inside the seeds' values; "
          "with one seed the value itself), beside the mean F1 at each level. The ceiling is the Bayes ceiling of the "
          "shifted task (the best expected accuracy any recognizer can reach under the test demonstrations' own "
          "demonstrator and dynamics), the mean over the levels; – where a level has none. It bounds accuracy, not F1. "
          "NLL (mean over levels) and ECE (10 equal confidence bins, every level and seed pooled) are those of the "
          "posterior over goals (the `loglik` scorer; – without one).")


def _signed(value: float | None) -> str:
    return "–" if value is None else f"{value:+.2f}"


def shifts_markdown(curves: Sequence[ShiftCurve], title: str) -> str:
    """:func:`grail_bench.report.shifts.shift_curves` as Markdown: per family, task and protocol, each
    configuration's F1 at each value of the shift, then its drop from the unshifted task."""
    lines = [f"# {title}: test-time shifts", "",
             "Each configuration (recognizer, scorer and settings, as the leaderboard names them) against the size",
             "of a shift of the test demonstrations' dynamics, in the profile's order from the unshifted task to the",
             "largest shift (each family's figure, `shifts-<family>.png`, draws F1 of its canonical configurations,",
             "the demonstrator's among them, or of all where none is; the ceiling dashed). " + POOLED, "",
             "Drop: F1 at the largest shift minus F1 unshifted (negative: F1 falls under the shift; – unless both",
             "have rows).", ""]
    panels: dict[tuple[str, str, str], list[ShiftCurve]] = {}
    for c in curves:
        panels.setdefault((c.family, c.task, c.protocol), []).append(c)
    stems = figure_stems(family for family, _, _ in panels)
    for (family, task, protocol), mine in panels.items():
        levels = sorted({lv for c in mine for lv in c.levels})
        lines += [f"## {md(family)}: {md(task.removeprefix(TASK_PREFIX))} ({md(protocol)}, "
                  f"{', '.join(level_text(lv) for lv in levels)} observed)", "",
                  f"Figure: [`{stems[family]}.png`]({stems[family]}.png)", ""]
        header = ["method", "shift", "seeds", "F1", "95 % interval", *[f"F1 @ {level_text(lv)}" for lv in levels],
                  "ceiling", "NLL", "ECE"]
        lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for c in mine:
            for p in c.points:
                r = p.result
                at = [_num(r.by_level.get(lv)) for lv in levels]
                lines.append(f"| {md(c.label)} | {md(p.shift.label)} | {r.n_seeds} | {r.f1_mean:.2f} | "
                             f"[{r.f1_ci95_low:.2f}, {r.f1_ci95_high:.2f}] | " + " | ".join(at)
                             + f" | {_num(r.ceiling)} | {_num(r.nll)} | {_num(r.ece)} |")
        last = md(mine[0].last.label)
        lines += ["", f"| method | F1 unshifted | F1 at {last} | drop |", "|---|---|---|---|"]
        for c in mine:
            lines.append(f"| {md(c.label)} | {_num(c.unshifted)} | {_num(c.at_last)} | {_signed(c.drop)} |")
        lines.append("")
    return "\n".join(lines)


def regimes_markdown(cells: Sequence[RegimeCell], title: str) -> str:
    """:func:`grail_bench.report.shifts.regime_cells` as Markdown: per domain and goal count the ceilings' matrix
    and each configuration's F1 matrix (training regime by test regime), then every cell in full."""
    lines = [f"# {title}: cross-regime grid", "",
             "Each configuration fitted on one regime's training demonstrations (a row: the task's own regime) and",
             "tested on another regime's demonstrations (a column: `test_regime`); the diagonal, in bold, is the",
             "unshifted task. Matrices per domain and goal count; [`regimes.png`](regimes.png) draws those of the",
             "canonical configurations. " + POOLED, ""]
    groups: dict[tuple[str, int], list[RegimeCell]] = {}
    for c in cells:
        groups.setdefault((c.domain, c.goals), []).append(c)
    for (domain, goals), group in groups.items():
        columns = regime_order(group)
        rows = list(dict.fromkeys(row_label(c) for c in sorted(group, key=lambda c: (c.train, c.task))))
        lines += [f"## {md(domain)}, {goals} goals", ""]
        notes = sorted({f"{c.test}: {c.test_params}" for c in group if c.test_params})
        if notes:
            lines += ["Test regimes' parameters: " + "; ".join(md(n) for n in notes) + ".", ""]

        def matrix(value: Any, mine: Sequence[RegimeCell]) -> list[str]:
            at = {(row_label(c), c.test): c for c in mine}
            out = ["| train \\ test | " + " | ".join(map(md, columns)) + " |", "|" + "---|" * (len(columns) + 1)]
            for row in rows:
                texts = []
                for col in columns:
                    c = at.get((row, col))
                    text = "–" if c is None else value(c)
                    texts.append(f"**{text}**" if c is not None and c.train == c.test and text != "–" else text)
                out.append(f"| {md(row)} | " + " | ".join(texts) + " |")
            return out + [""]

        lines += ["### Bayes ceiling (accuracy, mean over levels)", ""]
        lines += matrix(lambda c: _num(c.result.ceiling), group)
        for label in dict.fromkeys(c.label for c in group):
            lines += [f"### {md(label)}: F1", ""]
            lines += matrix(lambda c: f"{c.result.f1_mean:.2f}", [c for c in group if c.label == label])
    header = ["domain", "goals", "method", "train", "test", "protocol", "seeds", "F1", "95 % interval", "ceiling",
              "NLL", "ECE"]
    lines += ["## Every cell", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for c in cells:
        r = c.result
        lines.append(f"| {md(c.domain)} | {c.goals} | {md(c.label)} | {md(row_label(c))} | {md(c.test)} | "
                     f"{md(c.protocol)} | {r.n_seeds} | {r.f1_mean:.2f} | [{r.f1_ci95_low:.2f}, {r.f1_ci95_high:.2f}] "
                     f"| {_num(r.ceiling)} | {_num(r.nll)} | {_num(r.ece)} |")
    return "\n".join(lines) + "\n"


#: The intervals of TABLES.md (:func:`grail_bench.report.text.markdown` with ``ci``), said under its boards.
BOARD_INTERVALS = ("Intervals: the parenthesised (low–high) of each cell is the 95 % interval of the mean F1 over "
                   "seeds, a seeded percentile bootstrap (2000 resamples of the seeds, seed 0). It stays within "
                   "the seeds' F1, so within [0, 1], and is the value itself with one seed.")


def runs_markdown(records: Sequence[Any], fits: dict | None = None, intervals: bool = False) -> list[str]:
    """The leaderboard's closing section, "Runs, timings and ranking" (:func:`grail_bench.report.rows.timing_rows`
    as Markdown lines), after a note on the boards' intervals when they show them (``intervals``)."""
    lines = [BOARD_INTERVALS, ""] if intervals else []
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
        ranking = " | ".join(_num(v) for v in (t.top2, t.mean_rank, t.set_precision, t.set_recall, t.set_spread))
        lines.append(f"| {md(t.task)} | {md(t.column)} | {t.seeds} | {t.fit_seconds_per_goal:.2f} | "
                     f"{t.score_us_per_observation:.0f} | {t.tie_rate:.1%} | {ranking} | {t.reached or '–'} |")
    return lines
