"""Tables and plots of online and open-set records (``run --online``, ``run --open-set``, ``leaderboard --online``).

The records come from :func:`grail_bench.evaluation.online.aggregate_online`
and :func:`grail_bench.evaluation.open_set.aggregate_open_set`. Each table is
built once as header and rows of text, then shown with rich or written as
Markdown.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from rich.table import Table

Records = list[dict[str, Any]]
Grid = tuple[list[str], list[list[str]]]


def _label(record: dict[str, Any]) -> str:
    return f"{record['recognizer']}/{record['scorer']}"


def _interval(key: str, percent: bool = False) -> Callable[[dict[str, Any]], str]:
    """``mean [low, high]`` of a record's metric, the interval clipped to [0, 1]."""
    fmt = "{:.0%}" if percent else "{:.2f}"

    def text(record: dict[str, Any]) -> str:
        mean, low, high = (record[f"{key}_{part}"] for part in ("mean", "ci95_low", "ci95_high"))
        return f"{fmt.format(mean)} [{fmt.format(max(low, 0.0))}, {fmt.format(min(high, 1.0))}]"

    return text


@dataclass(frozen=True)
class Column:
    """One column of a table: its header, a cell's text and the value it sorts by."""

    header: str
    text: Callable[[dict[str, Any]], str]
    value: Callable[[dict[str, Any]], Any]


def _task(r: dict[str, Any]) -> str:
    return r["task"].removeprefix("GRAIL/")


_LEAD = [Column("task", _task, _task), Column("protocol", lambda r: r["protocol"], lambda r: r["protocol"])]
_WHO = [Column("recognizer/scorer", _label, _label), Column("seeds", lambda r: str(r["n_seeds"]), lambda r: r["n_seeds"])]
ONLINE_COLUMNS = _LEAD + _WHO + [
    Column("convergence (of T)", _interval("convergence", percent=True), lambda r: r["convergence_mean"]),
    Column("never", lambda r: f"{r['never_mean']:.0%}", lambda r: r["never_mean"]),
    Column("step accuracy", _interval("step_accuracy"), lambda r: r["step_accuracy_mean"]),
    Column("F1 AUC", _interval("f1_auc"), lambda r: r["f1_auc_mean"]),
    Column("µs / prefix", lambda r: f"{r['score_us_per_prefix']:.1f}", lambda r: r["score_us_per_prefix"]),
]
OPEN_SET_COLUMNS = _LEAD + [
    Column("obs", lambda r: f"{r['observability']:.0%}", lambda r: r["observability"]),
] + _WHO + [
    Column("AUROC", _interval("auroc"), lambda r: r["auroc_mean"]),
    Column("F1 (+ none)", _interval("f1"), lambda r: r["f1_mean"]),
    Column("accuracy", lambda r: f"{r['accuracy_mean']:.2f}", lambda r: r["accuracy_mean"]),
    Column("unknown found", lambda r: f"{r['unknown_recall_mean']:.0%}", lambda r: r["unknown_recall_mean"]),
    Column("false alarms", lambda r: f"{r['false_alarm_mean']:.0%}", lambda r: r["false_alarm_mean"]),
]


def grid(records: Records, columns: list[Column]) -> Grid:
    """Header and the rows of text of a table (one row per record)."""
    return [c.header for c in columns], [[c.text(r) for c in columns] for r in records]


def online_grid(records: Records) -> Grid:
    """One row per task, protocol, recognizer and scorer."""
    return grid(records, ONLINE_COLUMNS)


def open_set_grid(records: Records) -> Grid:
    """One row per task, protocol, level, recognizer and scorer."""
    return grid(records, OPEN_SET_COLUMNS)


def rich_table(grid: Grid, title: str) -> Table:
    header, rows = grid
    table = Table(title=title)
    for col in header:
        table.add_column(col)
    for row in rows:
        table.add_row(*row)
    return table


def markdown_table(grid: Grid, title: str, intro: str) -> str:
    header, rows = grid
    lines = [f"# {title}", "", intro, "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


ONLINE_TITLE = "online recognition (every prefix scored)"
ONLINE_INTRO = ("Mean over seeds [95 % interval]. Convergence: the observed fraction from which the prediction "
                "stays correct (100 % when it is wrong at the end, counted in 'never'). Step accuracy: the share "
                "of prefixes predicted correctly. F1 AUC: area under macro F1 against the observed fraction.")
OPEN_SET_TITLE = "open set (one goal held out per seed)"
OPEN_SET_INTRO = ("Mean over seeds [95 % interval]. AUROC: known against held-out goal, observations ranked by "
                  "their best score. F1 over the known goals plus 'none of these', answered when the best score "
                  "is below the 5 % quantile of the training demonstrations' best scores.")


def online_figure(records: Records, ceilings: dict[tuple[str, str], list[float] | None] | None = None) -> Any:
    """Accuracy against the observed fraction, one panel per task and protocol, one line per
    recognizer/scorer with its 95 % interval over seeds as a band (a matplotlib figure).

    Args:
        ceilings: Per (task, protocol), the Bayes ceiling at the records' fractions
            (:func:`grail_bench.evaluation.online.ceiling_curve`), drawn dashed where known.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    panels = sorted({(r["task"], r["protocol"]) for r in records})
    labels = sorted({_label(r) for r in records})
    colours = {label: f"C{i % 10}" for i, label in enumerate(labels)}
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.4 * cols, 3.3 * rows), squeeze=False)
    for ax, (task, protocol) in zip(axes.flat, panels):
        for r in records:
            if (r["task"], r["protocol"]) != (task, protocol):
                continue
            x = np.asarray(r["fractions"]) * 100
            colour = colours[_label(r)]
            ax.plot(x, r["accuracy_curve"], color=colour, label=f"{_label(r)} ({r['n_seeds']} seeds)")
            ax.fill_between(x, np.clip(r["accuracy_curve_low"], 0, 1), np.clip(r["accuracy_curve_high"], 0, 1),
                            color=colour, alpha=0.2)
        ceiling = (ceilings or {}).get((task, protocol))
        if ceiling is not None:
            x = [100 * f for f in next(r for r in records if (r["task"], r["protocol"]) == (task, protocol))["fractions"]]
            ax.plot(x, ceiling, color="black", linestyle="--", linewidth=1, label="Bayes ceiling (bound)")
        ax.set_title(f"{task.removeprefix('GRAIL/')} ({protocol})", fontsize=9)
        ax.set_xlabel("observed (% of the trajectory)")
        ax.set_ylabel("accuracy")
        ax.set_ylim(0, 1.05)
        ax.legend(fontsize=7, loc="lower right")
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    fig.tight_layout()
    return fig


def online_ceilings(records: Records, samples: int | None,
                    progress: bool = False) -> dict[tuple[str, str], list[float] | None]:
    """The Bayes ceiling curve of every (task, protocol) of online records; none with ``samples=None``.

    Each level is computed once and cached; a Monte Carlo one takes about 5 s on MiniGrid's suboptimal
    tasks, so ``progress`` shows a bar.
    """
    from rich.progress import Progress

    from grail_bench.evaluation.online import ceiling_curve

    if samples is None:
        return {}
    first = {(r["task"], r["protocol"]): r for r in reversed(records)}
    with Progress(disable=not progress, transient=True) as bar:
        job = bar.add_task("Bayes ceilings (computed once, then cached)",
                           total=sum(len(r["fractions"]) for r in first.values()))
        return {key: ceiling_curve(r, samples, lambda: bar.advance(job)) for key, r in sorted(first.items())}


def online_plot(records: Records, path: str | Path,
                ceilings: dict[tuple[str, str], list[float] | None] | None = None) -> Path:
    """:func:`online_figure` written to ``path`` (PNG)."""
    import matplotlib.pyplot as plt

    fig = online_figure(records, ceilings)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
