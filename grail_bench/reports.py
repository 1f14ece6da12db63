"""Tables and plots of online and open-set records (``run --online``, ``run --open-set``, ``leaderboard --online``).

The records come from :func:`grail_bench.evaluation.online.aggregate_online`
and :func:`grail_bench.evaluation.open_set.aggregate_open_set`. Each table is
built once as header and rows of text, then shown with rich or written as
Markdown.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.table import Table

Records = list[dict[str, Any]]
Grid = tuple[list[str], list[list[str]]]


def _label(record: dict[str, Any]) -> str:
    return f"{record['recognizer']}/{record['scorer']}"


def _interval(record: dict[str, Any], key: str, percent: bool = False) -> str:
    """``mean [low, high]`` of a record's metric, the interval clipped to [0, 1]."""
    mean, low, high = (record[f"{key}_{part}"] for part in ("mean", "ci95_low", "ci95_high"))
    fmt = "{:.0%}" if percent else "{:.2f}"
    return f"{fmt.format(mean)} [{fmt.format(max(low, 0.0))}, {fmt.format(min(high, 1.0))}]"


def online_grid(records: Records) -> Grid:
    """One row per task, protocol, recognizer and scorer."""
    header = ["task", "protocol", "recognizer/scorer", "seeds", "convergence (of T)", "never", "step accuracy",
              "F1 AUC", "µs / prefix"]
    rows = [[r["task"].removeprefix("GRAIL/"), r["protocol"], _label(r), str(r["n_seeds"]),
             _interval(r, "convergence", percent=True), f"{r['never_mean']:.0%}", _interval(r, "step_accuracy"),
             _interval(r, "f1_auc"), f"{r['score_us_per_prefix']:.1f}"] for r in records]
    return header, rows


def open_set_grid(records: Records) -> Grid:
    """One row per task, protocol, level, recognizer and scorer."""
    header = ["task", "protocol", "obs", "recognizer/scorer", "seeds", "AUROC", "F1 (+ none)", "accuracy",
              "unknown found", "false alarms"]
    rows = [[r["task"].removeprefix("GRAIL/"), r["protocol"], f"{r['observability']:.0%}", _label(r),
             str(r["n_seeds"]), _interval(r, "auroc"), _interval(r, "f1"), f"{r['accuracy_mean']:.2f}",
             f"{r['unknown_recall_mean']:.0%}", f"{r['false_alarm_mean']:.0%}"] for r in records]
    return header, rows


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
                "stays correct (100 % when it is wrong at the end, counted in *never*). Step accuracy: the share "
                "of prefixes predicted correctly. F1 AUC: area under macro F1 against the observed fraction.")
OPEN_SET_TITLE = "open set (one goal held out per seed)"
OPEN_SET_INTRO = ("Mean over seeds [95 % interval]. AUROC: known against held-out goal, observations ranked by "
                  "their best score. F1 over the known goals plus *none of these*, answered when the best score "
                  "is below the 5 % quantile of the training demonstrations' best scores.")


def online_plot(records: Records, path: str | Path) -> Path:
    """Accuracy against the observed fraction, one panel per task and protocol, one line per
    recognizer/scorer with its 95 % interval over seeds as a band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    panels = sorted({(r["task"], r["protocol"]) for r in records})
    labels = sorted({_label(r) for r in records})
    colours = {label: f"C{i}" for i, label in enumerate(labels)}
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
        ax.set_title(f"{task.removeprefix('GRAIL/')} ({protocol})", fontsize=9)
        ax.set_xlabel("observed (% of the trajectory)")
        ax.set_ylabel("accuracy")
        ax.set_ylim(0, 1.05)
        ax.legend(fontsize=7, loc="lower right")
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
