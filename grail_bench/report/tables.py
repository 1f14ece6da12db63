"""Terminal (rich) and Markdown renderings of everything beside the boards: the task, recognizer and
protocol listings, ceilings, fit diagnostics, timings, the scorer ablation, the modes' tables, budget studies
and calibration.

Each table is built from rows computed elsewhere (:mod:`grail_bench.report.rows`, the modes' records);
nothing here computes a statistic or a ceiling.
"""

from __future__ import annotations

from typing import Any, Sequence

from rich.table import Table

from grail_bench.harness.modes import Mode
from grail_bench.task.observation import level_text


def timing_table(records: Sequence[Any]) -> Table:
    """Terminal table of fit and scoring times per recognizer and scorer (means over seeds and levels)."""
    table = Table(title="timings (mean over seeds)")
    for col in ("recognizer", "scorer", "fit s/goal", "score µs/observation"):
        table.add_column(col)
    pairs = dict.fromkeys((r.recognizer, r.scorer) for r in records)
    for name, scorer in pairs:
        mine = [r for r in records if (r.recognizer, r.scorer) == (name, scorer)]
        table.add_row(name, scorer, f"{mine[0].fit_seconds_per_goal:.2f}",
                      f"{sum(r.score_us_per_observation for r in mine) / len(mine):.0f}")
    return table


def _ablation_cells(r: dict[str, Any], levels: list[float]) -> list[str]:
    return [f"{r['f1'][lv][0]:.2f} ± {r['f1'][lv][1]:.2f}" if lv in r["f1"] else "–" for lv in levels]


def _calibration(r: dict[str, Any]) -> tuple[str, str, str]:
    cal = r.get("calibration")
    if not cal:
        return "–", "–", "–"
    ece = r.get("ece")
    return (f"{sum(b for b, _ in cal) / len(cal):.3f}", f"{sum(n for _, n in cal) / len(cal):.3f}",
            "–" if ece is None else f"{ece:.3f}")


def ablation_table(rows: list[dict[str, Any]]) -> Table:
    """Terminal table of :func:`grail_bench.report.rows.ablation_rows`."""
    levels = sorted({lv for r in rows for lv in r["f1"]})
    table = Table(title="scorer ablation: F1 (mean ± std) and scoring time")
    for col in ("task", "recognizer", "scorer", *[f"F1 @ {level_text(lv)}" for lv in levels], "µs / observation",
                "Brier / NLL / ECE"):
        table.add_column(col)
    for r in rows:
        brier, nll, ece = _calibration(r)
        table.add_row(r["task"], r["recognizer"], r["scorer"], *_ablation_cells(r, levels), f"{r['score_us']:.0f}",
                      "–" if brier == "–" else f"{brier} / {nll} / {ece}")
    return table


def ablation_markdown(rows: list[dict[str, Any]]) -> str:
    """:func:`grail_bench.report.rows.ablation_rows` as a Markdown table."""
    levels = sorted({lv for r in rows for lv in r["f1"]})
    header = ["task", "recognizer", "scorer", *[f"F1 @ {level_text(lv)}" for lv in levels], "µs / observation", "Brier", "NLL",
              "ECE"]
    lines = ["# Scorer ablation", "",
             "F1 (mean ± std over seeds) of each recognizer under each scorer, from the same fitted policies,",
             "and the mean time to score one observation against all goals. Brier score, NLL and the expected",
             "calibration error (ECE: 10 equal confidence bins, every level and seed pooled) are those of the",
             "posterior over goals that the `loglik` scorer yields.", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        brier, nll, ece = _calibration(r)
        lines.append(f"| {r['task']} | {r['recognizer']} | {r['scorer']} | " + " | ".join(_ablation_cells(r, levels))
                     + f" | {r['score_us']:.0f} | {brier} | {nll} | {ece} |")
    return "\n".join(lines) + "\n"


def mode_grid(records: Sequence[Any], mode: Mode) -> tuple[list[str], list[list[str]]]:
    """Header and the rows of text of a mode's table (one row per record, the mode's columns)."""
    return [c.header for c in mode.columns], [[c.text(r) for c in mode.columns] for r in records]


def mode_table(records: Sequence[Any], mode: Mode) -> Table:
    """A mode's records as a terminal table."""
    header, rows = mode_grid(records, mode)
    table = Table(title=mode.title)
    for col in header:
        table.add_column(col)
    for row in rows:
        table.add_row(*row)
    return table


def mode_markdown(records: Sequence[Any], mode: Mode) -> str:
    """A mode's records as a Markdown document (title, what the table shows, the table)."""
    header, rows = mode_grid(records, mode)
    lines = [f"# {mode.title}", "", mode.intro, "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def tasks_table(tasks: Sequence[Any]) -> Table:
    """Every task with its domain, regime, goals, demonstration counts, levels and protocol."""
    table = Table(title="GRAIL/ tasks")
    table.add_column("task", no_wrap=True, style="bold")
    for col in ("domain", "regime", "goals", "demos/goal (train/test)", "observability", "protocol"):
        table.add_column(col)
    for task in tasks:
        goals = " ".join("(" + ",".join(f"{c:g}" for c in g) + ")" for g in task.goals)
        table.add_row(task.id, task.domain, task.regime, goals,
                      f"{task.n_demos} ({task.n_train}/{task.n_demos - task.n_train})",
                      ", ".join(level_text(p) for p in task.observability), task.protocol_label)
    return table


def names_table(title: str, rows: Sequence[tuple[str, str]], second: str) -> Table:
    """A two-column listing (name in bold, then what provides or describes it)."""
    table = Table(title=title)
    table.add_column("name", style="bold")
    table.add_column(second)
    for name, text in rows:
        table.add_row(name, text)
    return table


def protocols_table(rows: Sequence[tuple[str, bool, str]]) -> Table:
    """The observation protocols: name, whether it leaks the goal, what a recognizer observes."""
    table = Table(title="observation protocols (entry-point group grail_bench.protocols)")
    table.add_column("name", style="bold")
    table.add_column("leaks the goal")
    table.add_column("what a recognizer observes")
    for name, leaks, text in rows:
        table.add_row(name, "yes" if leaks else "no", text)
    return table


def ceiling_table(task_id: str, ceilings: Sequence[Any]) -> Table:
    """Bayes ceilings of one task (one row per protocol and level)."""
    kind = "Pairs-only ceiling" if any(c.pairs_only for c in ceilings) else "Bayes ceiling"
    table = Table(title=f"{kind} (accuracy): {task_id}")
    for col in ("protocol", "obs", "ceiling", "std. error", "chance", "method"):
        table.add_column(col)
    for c in ceilings:
        table.add_row(c.protocol, level_text(c.observability), f"{c.accuracy:.3f}",
                      f"{c.stderr:.3f}" if c.method == "monte-carlo" else "exact", f"{c.chance:.3f}",
                      c.method + (f" ({c.samples} samples)" if c.samples else ""))
    return table


def goal_label(goal: Sequence[float]) -> str:
    """``(7,1)``: a goal as the tables name it."""
    return "(" + ",".join(f"{c:g}" for c in goal) + ")"


def diagnostics_table(diagnostics: Any, title: str) -> Table:
    """Per goal: greedy rollout reached and its length, the demonstrations' length, agreement with its own
    training and held-out demonstrations, and its held-out actions' probability under its own and under the best
    other goal's policy."""
    table = Table(title=title)
    for col in ("goal", "reached", "rollout", "demos", "agreement train", "held-out", "own p", "best other p",
                "other goal"):
        table.add_column(col, justify="right")
    labels = [goal_label(g) for g in diagnostics.goals]
    for i, label in enumerate(labels):
        row = diagnostics.imitation[i]
        others = [(v, j) for j, v in enumerate(row) if j != i and v is not None]
        best, j = max(others) if others else (None, None)
        reached = diagnostics.reached[i]
        table.add_row(label, "–" if reached is None else "yes" if reached else "no",
                      "–" if diagnostics.rollout_length[i] is None else str(diagnostics.rollout_length[i]),
                      f"{diagnostics.demo_length[i]:.1f}", _num(diagnostics.agreement_train[i]),
                      _num(diagnostics.agreement_held_out[i]), _num(row[i]), _num(best),
                      labels[j] if j is not None else "–")
    return table


def _num(value: float | None) -> str:
    return "–" if value is None or value != value else f"{value:.2f}"


def budgets_markdown(curves: Sequence[dict[str, Any]], title: str) -> str:
    """Budget studies as Markdown: per task and recognizer, F1 at each value with its interval and fit cost."""
    lines = [f"# {title}: budget studies", "",
             "F1 (mean over seeds, [95 % t-interval]) of each recognizer under its own scorer at one observability",
             "level, against one training budget or the training demonstrations per goal, with the fit's seconds",
             "per goal. Plateau: the smallest value whose mean F1 reaches the 95 % interval of the best value's",
             "(the rule that picks a default budget). A scaling study (n_goals) runs tasks of growing goal sets",
             "instead; its exponent b is the log-log slope of the whole fit's seconds (s/goal x goals) against",
             "the goal count: 1 is linear (one model per goal), 0 flat.", ""]
    for c in curves:
        lines += [f"## {c['recognizer']}: {c['param']} on {c['task'].removeprefix('GRAIL/')} "
                  f"({c['protocol']}, {level_text(c['observability'])} observed)", ""]
        if "exponent" in c:
            lines += [f"Fit cost exponent: b = {_num(c['exponent'])}.", ""]
        else:
            lines += [f"Plateau: {c['param']} = {c['plateau']}.", ""]
        lines += [f"| {c['param']} | seeds | F1 | 95 % interval | fit s/goal |", "|---|---|---|---|---|"]
        for p in c["points"]:
            mark = " (plateau)" if p["value"] == c.get("plateau") else ""
            lines.append(f"| {p['value']}{mark} | {p['n_seeds']} | {p['f1_mean']:.2f} | "
                         f"[{max(0.0, p['f1_ci95_low']):.2f}, {min(1.0, p['f1_ci95_high']):.2f}] | "
                         f"{p['fit_seconds_per_goal']:.2f} |")
        lines.append("")
    return "\n".join(lines)


def calibration_markdown(rows: Sequence[dict[str, Any]]) -> str:
    """:func:`grail_bench.report.rows.calibration_rows` as Markdown."""
    lines = ["# Calibration", "",
             "Recognizers that give a posterior over goals (the `loglik` scorer: the softmax of summed",
             "log-likelihoods), per domain, every observation of every task, level and seed pooled: Brier score",
             "and NLL (means), and the expected calibration error (ECE) of the top-label confidence over 10 equal",
             "bins; `reliability.png` draws the bins.", "",
             "| domain | recognizer/scorer | records | Brier | NLL | ECE |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['domain']} | {r['column']} | {r['records']} | {_num(r['brier'])} | {_num(r['nll'])} | "
                     f"{_num(r['ece'])} |")
    return "\n".join(lines) + "\n"
