"""Every figure grail-bench draws, from records, with one matplotlib set-up (Agg, headless).

* ``f1_vs_observability``: F1 against the observed fraction, one panel per
  task with several levels, one line per recognizer (its own scorer) and the
  95 % interval over seeds as a band (the paper's Figure 4 family).
* ``panda_regimes``: PandaReach F1 per regime and method (Figure 5).
* ``scoring_time``: scoring microseconds per observation, per method and
  scorer (Figure 6).
* ``training_time``: training seconds per goal, per method (the efficiency section).
* ``model_size``: kilobytes of one goal's stored model, per method (the storage table).
* ``ablation``: F1 and scoring time per scorer; ``online``: accuracy against the observed fraction.
* ``shifts``: F1 against a test-time shift's size, one family's canonical configurations; ``regimes``: the
  cross-regime grid as heatmaps, a panel per canonical configuration.

Figures are returned as matplotlib figures and written by :func:`save` (PNG
and SVG) or embedded in the web page by :func:`svg` (text as text, stable IDs).
"""

from __future__ import annotations

import io
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from grail_bench.core.atomic import write_files, write_with
from grail_bench.report.boards import domain_of, own_scorer_records, short_name
from grail_bench.report.shifts import regime_order, row_label
from grail_bench.task.observation import level_text

Records = Sequence[Any]
#: Settings of every SVG the page embeds: text as text (smaller, selectable) and stable element IDs.
SVG_STYLE = {"svg.fonttype": "none", "svg.hashsalt": "grail-bench"}


def pyplot() -> Any:
    """matplotlib's pyplot on the Agg backend (the only place that chooses it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _layout(fig: Any) -> None:
    """Lay ``fig`` out tightly, unless it has a layout of its own (constrained, for a legend outside its panels)."""
    if fig.get_layout_engine() is None:
        fig.tight_layout()


def save(fig: Any, out: Path, stem: str) -> list[Path]:
    """Write ``fig`` as ``out/stem.png`` and ``out/stem.svg``, close it, return the paths."""
    plt = pyplot()
    paths = [out / f"{stem}.png", out / f"{stem}.svg"]
    _layout(fig)
    try:
        write_files({paths[0]: lambda tmp: fig.savefig(tmp, dpi=110, format="png"),
                     paths[1]: lambda tmp: fig.savefig(tmp, format="svg")})
    finally:
        plt.close(fig)
    return paths


def save_png(fig: Any, path: Path) -> Path:
    """Write ``fig`` as one PNG (its folder created), close it, return the path."""
    plt = pyplot()
    path = Path(path)
    _layout(fig)
    try:
        write_with(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    finally:
        plt.close(fig)
    return path


def svg(draw: Callable[[], Any]) -> str:
    """The SVG text of the figure ``draw()`` makes under :data:`SVG_STYLE` (for inline use), closed after."""
    plt = pyplot()
    with plt.rc_context(SVG_STYLE):
        fig = draw()
        buf = io.StringIO()
        _layout(fig)
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None, "Format": None, "Type": None})
    plt.close(fig)
    text = buf.getvalue()
    return text[text.index("<svg"):]


def f1_vs_observability(records: Records, out: Path) -> list[Path]:
    """Figure 4 family (see module docstring); nothing when no task has several levels."""
    mine = own_scorer_records(records)
    levels = defaultdict(set)
    for r in mine:
        levels[r.task].add(r.observability)
    tasks = sorted(t for t, lv in levels.items() if len(lv) > 1)
    if not tasks:
        return []
    plt = pyplot()
    cols = min(3, len(tasks))
    rows = -(-len(tasks) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    recognizers = sorted({r.recognizer for r in mine})
    colours = {name: f"C{i}" for i, name in enumerate(recognizers)}
    for ax, task in zip(axes.flat, tasks):
        for name in recognizers:
            line = sorted((r for r in mine if r.task == task and r.recognizer == name), key=lambda r: r.observability)
            if not line:
                continue
            x = [r.observability * 100 for r in line]
            ax.plot(x, [r.f1.mean for r in line], marker="o", color=colours[name], label=name)
            ax.fill_between(x, [r.f1.ci95[0] for r in line], [r.f1.ci95[1] for r in line],
                            color=colours[name], alpha=0.2)
        ax.set_title(short_name(task), fontsize=9)
        ax.set_xlabel("observed (%)")
        ax.set_ylabel("F1")
        ax.set_ylim(0, 1.05)
    for ax in list(axes.flat)[len(tasks):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=8)
    return save(fig, out, "f1_vs_observability")


def _bars(ax: Any, groups: list[str], series: dict[str, dict[str, float]], errors: dict[str, dict[str, float]] | None,
          ylabel: str, log: bool = False) -> None:
    """Grouped bars: ``series[name][group]`` -> height."""
    names = sorted(series)
    width = 0.8 / max(1, len(names))
    for i, name in enumerate(names):
        xs = [j + i * width for j, g in enumerate(groups) if g in series[name]]
        heights = [series[name][g] for g in groups if g in series[name]]
        err = [errors[name][g] for g in groups if g in series[name]] if errors else None
        ax.bar(xs, heights, width, yerr=err, label=name, color=f"C{i}", capsize=2)
    ax.set_xticks(np.arange(len(groups)) + 0.4 - width / 2, groups, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    ax.legend(fontsize=8)


def panda_regimes(records: Records, out: Path) -> list[Path]:
    """Figure 5: PandaReach F1 per regime (task) and method; nothing without PandaReach rows."""
    mine = [r for r in own_scorer_records(records) if domain_of(r.task) == "PandaReach"]
    if not mine:
        return []
    plt = pyplot()
    tasks = sorted({r.task for r in mine})
    groups = [short_name(t).removeprefix("PandaReach-") for t in tasks]
    f1, std = defaultdict(dict), defaultdict(dict)
    for r in mine:
        group = short_name(r.task).removeprefix("PandaReach-")
        f1[r.recognizer][group] = r.f1.mean
        std[r.recognizer][group] = r.f1.std
    fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(groups) + 2), 3.8))
    _bars(ax, groups, f1, std, "F1")
    ax.set_ylim(0, 1.1)
    ax.set_title(f"PandaReach, {level_text(min(r.observability for r in mine))} observed", fontsize=9)
    return save(fig, out, "panda_regimes")


def _per_domain(records: Records, value: Callable[[Any], float | None], label: Callable[[Any], str],
                ylabel: str, stem: str, out: Path, log: bool = False) -> list[Path]:
    """One bar panel per domain: the mean of ``value`` per method label."""
    means: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in records:
        v = value(r)
        if v is not None:
            means[domain_of(r.task)][label(r)].append(v)
    if not means:
        return []
    plt = pyplot()
    domains = sorted(means)
    fig, axes = plt.subplots(1, len(domains), figsize=(4.5 * len(domains), 3.6), squeeze=False)
    for ax, domain in zip(axes.flat, domains):
        labels = sorted(means[domain])
        heights = [float(np.mean(means[domain][k])) for k in labels]
        ax.bar(range(len(labels)), heights, color=[f"C{i}" for i in range(len(labels))])
        ax.set_xticks(range(len(labels)), labels, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(ylabel)
        ax.set_title(domain, fontsize=9)
        if log:
            ax.set_yscale("log")
    return save(fig, out, stem)


def scoring_time(records: Records, out: Path) -> list[Path]:
    """Figure 6: scoring µs per observation per method and scorer (mean over tasks and levels)."""
    return _per_domain(records, lambda r: r.score_us_per_observation, lambda r: f"{r.recognizer}/{r.scorer}",
                       "scoring µs / observation", "scoring_time", out)


def training_time(records: Records, out: Path) -> list[Path]:
    """Training seconds per goal per method (mean over tasks and seeds)."""
    return _per_domain(own_scorer_records(records), lambda r: r.fit_seconds_per_goal, lambda r: r.recognizer,
                       "training s / goal", "training_time", out, log=True)


def model_size(sizes: dict[tuple[str, str], float], out: Path) -> list[Path]:
    """Kilobytes of one goal's stored model per method and domain (from :func:`grail_bench.report.reproduce.model_sizes`)."""
    if not sizes:
        return []
    plt = pyplot()
    domains = sorted({d for d, _ in sizes})
    fig, axes = plt.subplots(1, len(domains), figsize=(4.0 * len(domains), 3.4), squeeze=False)
    for ax, domain in zip(axes.flat, domains):
        names = sorted(n for d, n in sizes if d == domain)
        ax.bar(range(len(names)), [sizes[(domain, n)] / 1024 for n in names],
               color=[f"C{i}" for i in range(len(names))])
        ax.set_xticks(range(len(names)), names, fontsize=8)
        ax.set_ylabel("KB per goal model")
        ax.set_title(domain, fontsize=9)
    return save(fig, out, "model_size")


def write_all(records: Records, out: Path, models: dict[tuple[str, str], float]) -> list[Path]:
    """Every figure this module draws, into ``out``; returns the files written."""
    return (f1_vs_observability(records, out) + panda_regimes(records, out) + scoring_time(records, out)
            + training_time(records, out) + model_size(models, out))


def ablation(rows: Sequence[Any]) -> Any:
    """Grouped bars per task: F1 (mean over levels) and scoring time, by recognizer and scorer (a figure).

    ``rows`` are :func:`grail_bench.report.rows.ablation_rows`.
    """
    plt = pyplot()
    tasks = sorted({r.task for r in rows})
    colours = {name: f"C{i}" for i, name in enumerate(sorted({r.scorer for r in rows}))}  # one per scorer
    fig, axes = plt.subplots(len(tasks), 2, figsize=(11, 3.2 * len(tasks)), squeeze=False)
    for ax_f1, ax_time, task in zip(axes[:, 0], axes[:, 1], tasks):
        mine = [r for r in rows if r.task == task]
        recs = sorted({r.recognizer for r in mine})
        scorers = sorted({r.scorer for r in mine})
        width = 0.8 / len(scorers)
        for i, scorer in enumerate(scorers):
            xs, f1s, times = [], [], []
            for j, rec in enumerate(recs):
                hit = [r for r in mine if r.recognizer == rec and r.scorer == scorer]
                if hit:
                    xs.append(j + i * width)
                    f1s.append(hit[0].f1_overall)
                    times.append(hit[0].score_us)
            ax_f1.bar(xs, f1s, width, label=scorer, color=colours[scorer])
            ax_time.bar(xs, times, width, label=scorer, color=colours[scorer])
        for ax, ylabel in ((ax_f1, "F1 (mean over observability)"), (ax_time, "scoring µs / observation")):
            ax.set_xticks(np.arange(len(recs)) + 0.4 - width / 2, recs)
            ax.set_ylabel(ylabel)
            ax.set_title(task, fontsize=9)
        ax_f1.set_ylim(0, 1.05)
        ax_time.legend(fontsize=8, loc="lower right", framealpha=0.9)
    return fig


def online(records: Records, ceilings: dict[tuple[str, str], list[float] | None] | None = None) -> Any:
    """Accuracy against the observed fraction, one panel per task and protocol, one line per
    recognizer/scorer with its 95 % interval over seeds as a band (a figure).

    Args:
        records: Online records (:func:`grail_bench.harness.modes.online.aggregate`).
        ceilings: Per (task, protocol), the Bayes ceiling at the records' fractions, drawn dashed where known.
    """
    plt = pyplot()
    label = lambda r: f"{r.recognizer}/{r.scorer}"  # noqa: E731
    panels = sorted({(r.task, r.protocol) for r in records})
    colours = {name: f"C{i % 10}" for i, name in enumerate(sorted({label(r) for r in records}))}
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.4 * cols, 3.3 * rows), squeeze=False)
    for ax, (task, protocol) in zip(axes.flat, panels):
        mine = [r for r in records if (r.task, r.protocol) == (task, protocol)]
        for r in mine:
            x = np.asarray(r.fractions) * 100
            colour = colours[label(r)]
            ax.plot(x, r.accuracy_curve, color=colour, label=f"{label(r)} ({r.n_seeds} seeds)")
            ax.fill_between(x, r.accuracy_curve_low, r.accuracy_curve_high,
                            color=colour, alpha=0.2)
        ceiling = (ceilings or {}).get((task, protocol))
        if ceiling is not None:
            x = [100 * f for f in mine[0].fractions]
            ax.plot(x, ceiling, color="black", linestyle="--", linewidth=1, label="Bayes ceiling (bound)")
        ax.set_title(f"{task.removeprefix('GRAIL/')} ({protocol})", fontsize=9)
        ax.set_xlabel("observed (% of the trajectory)")
        ax.set_ylabel("accuracy")
        ax.set_ylim(0, 1.05)
        ax.legend(fontsize=7, loc="lower right")
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    return fig


def section_lines(tasks: Sequence[str], lines: Sequence[tuple[str, list]]) -> Any:
    """F1 against observability per task: one line and interval band per column (a figure of the web page).

    Args:
        tasks: Panels, in order (their titles).
        lines: ``(label, points)`` per column, each point ``(task, level, mean, low, high)``.
    """
    plt = pyplot()
    fig, axes = plt.subplots(1, len(tasks), figsize=(3.4 * len(tasks), 2.8), squeeze=False)
    for ax, task in zip(axes.flat, tasks):
        for i, (name, points) in enumerate(lines):
            mine = sorted(p for p in points if p[0] == task)
            if not mine:
                continue
            x = [100 * p[1] for p in mine]
            ax.plot(x, [p[2] for p in mine], marker="o", color=f"C{i % 10}", label=name)
            ax.fill_between(x, [p[3] for p in mine], [p[4] for p in mine], color=f"C{i % 10}", alpha=0.2)
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("observed (%)")
        ax.set_ylim(0, 1.05)
    axes.flat[0].set_ylabel("F1")
    axes.flat[0].legend(fontsize=7)
    return fig


def heatmap(matrix: Sequence[Sequence[float | None]], labels: Sequence[str], title: str, xlabel: str, ylabel: str,
            digits: int = 2) -> Any:
    """A labelled heatmap of a square matrix, each cell annotated (a figure)."""
    plt = pyplot()
    size = 1.0 + 0.55 * len(labels)
    fig, ax = plt.subplots(figsize=(size + 1.2, size))
    image = _heat(ax, matrix, labels, labels, digits)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    fig.colorbar(image, ax=ax, shrink=0.8)
    return fig


def _heat(ax: Any, matrix: Sequence[Sequence[float | None]], rows: Sequence[str], columns: Sequence[str],
          digits: int = 2, vmax: float | None = None) -> Any:
    """Draw a matrix (None: an empty cell) on ``ax`` as an annotated heatmap; returns the image."""
    values = np.array([[np.nan if v is None else v for v in row] for row in matrix], dtype=float)
    image = ax.imshow(values, cmap="Blues", vmin=0, vmax=vmax)
    top = vmax if vmax is not None else (np.nanmax(values) if np.isfinite(values).any() else 1.0)
    for (i, j), v in np.ndenumerate(values):
        if not np.isnan(v):
            ax.text(j, i, f"{v:.{digits}f}", ha="center", va="center", fontsize=7,
                    color="white" if v > 0.6 * top else "black")
    ax.set_xticks(range(len(columns)), columns, rotation=35, ha="right", fontsize=8)
    ax.set_yticks(range(len(rows)), rows, fontsize=8)
    return image


#: At most this many panels in a row of a shift or regime figure.
PANELS_PER_ROW = 4
#: A categorical shift's label longer than this is drawn as its level (``level 1``); SHIFTS.md names it in full.
SHORT_LABEL = 24


def _grid(plt: Any, n: int, width: float, height: float, extra: float = 0.0) -> tuple[Any, list[Any]]:
    """A figure of ``n`` panels, at most :data:`PANELS_PER_ROW` a row, each ``width`` x ``height`` inches
    (``extra`` inches more for a legend or colour bar), laid out by matplotlib's constrained layout; the unused
    panels hidden."""
    cols = min(PANELS_PER_ROW, n)
    rows = -(-n // cols)
    fig = plt.figure(figsize=(width * cols, height * rows + extra), layout="constrained")
    axes = list(fig.subplots(rows, cols, squeeze=False).flat)
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def shift_ticks(shifts_in: Sequence[Any]) -> list[str]:
    """A categorical axis's labels of a family's values: as the profile wrote them, or, where one is longer than
    :data:`SHORT_LABEL` (a list of walls), ``level 1``, ``level 2``... (the unshifted task kept)."""
    labels = [s.label for s in shifts_in]
    if all(len(label) <= SHORT_LABEL for label in labels):
        return labels
    levels = iter(range(1, len(labels) + 1))
    return [s.label if not s.params else f"level {next(levels)}" for s in shifts_in]


def shifts(curves: Sequence[Any]) -> Any:
    """One family's F1 against its shift: a panel per task and protocol, a line per configuration with its 95 %
    band (references dash-dotted in grey), the Bayes ceiling dashed at the values that have one, one legend
    below the panels (a figure; ``curves`` are one family's
    :func:`grail_bench.report.shifts.shift_curves`, those :func:`grail_bench.report.shifts.drawn` selects)."""
    plt = pyplot()
    panels = sorted({(c.task, c.protocol) for c in curves})
    labels = sorted({c.label for c in curves if not c.reference}) + sorted({c.label for c in curves if c.reference})
    references = {c.label for c in curves if c.reference}
    colours = {label: "0.35" if label in references else f"C{i % 10}" for i, label in enumerate(labels)}
    styles = {label: "-." if label in references else "-" if i < 10 else ":" for i, label in enumerate(labels)}
    ncol = max(1, int(3.5 * min(PANELS_PER_ROW, len(panels)) // 2.6))  # legend columns of ~2.6 in
    fig, axes = _grid(plt, len(panels), 3.5, 2.8, extra=0.3 * -(-(len(labels) + 1) // ncol))
    present = {p.shift for c in curves for p in c.points}
    values = [s for s in curves[0].values if s in present] or list(dict.fromkeys(p.shift for c in curves
                                                                                  for p in c.points))
    order, ticks = {s: k for k, s in enumerate(values)}, dict(zip(values, shift_ticks(values)))
    handles: dict[str, Any] = {}
    for ax, panel in zip(axes, panels):
        mine = [c for c in curves if (c.task, c.protocol) == panel]
        shifts_in = sorted({p.shift for c in mine for p in c.points}, key=order.__getitem__)
        numeric = all(s.x is not None for s in shifts_in)
        where = {s: (s.x if numeric else k) for k, s in enumerate(shifts_in)}
        for c in sorted(mine, key=lambda c: labels.index(c.label)):
            x = [where[p.shift] for p in c.points]
            handles[c.label], = ax.plot(x, [p.result.f1_mean for p in c.points], marker="o", markersize=3,
                                        color=colours[c.label], linestyle=styles[c.label], label=c.label)
            ax.fill_between(x, [p.result.f1_ci95_low for p in c.points], [p.result.f1_ci95_high for p in c.points],
                            color=colours[c.label], alpha=0.15)
        ceiling = {p.shift: p.result.ceiling for c in mine for p in c.points if p.result.ceiling is not None}
        known = [s for s in shifts_in if s in ceiling]
        if known:
            handles["Bayes ceiling (accuracy)"], = ax.plot(
                [where[s] for s in known], [ceiling[s] for s in known], color="black", linestyle="--", linewidth=1,
                label="Bayes ceiling (accuracy)")
        ax.set_title(f"{short_name(panel[0])} ({panel[1]})", fontsize=9)
        ax.set_ylim(0, 1.05)
        ax.tick_params(labelsize=7)
        names = " / ".join(dict.fromkeys(s.label.split("=")[0] for s in shifts_in if s.params))
        if numeric:
            ax.set_xticks([s.x for s in shifts_in], [f"{s.x:g}" for s in shifts_in], fontsize=7)
            ax.set_xlabel(names, fontsize=8)
            if shifts_in[-1].x < shifts_in[0].x:
                ax.invert_xaxis()  # the shift grows to the right
        else:
            ax.set_xticks(range(len(shifts_in)), [ticks[s] for s in shifts_in], fontsize=7)
            renamed = any(ticks[s] != s.label for s in shifts_in)
            ax.set_xlabel(names + (" (levels as in SHIFTS.md)" if renamed else ""), fontsize=8)
        if ax in axes[::PANELS_PER_ROW]:
            ax.set_ylabel("F1 (mean over levels)", fontsize=8)
    fig.suptitle(f"{curves[0].family}: F1 against the shift", fontsize=10)
    fig.legend(list(handles.values()), list(handles), loc="outside lower center", ncol=min(ncol, len(handles)),
               fontsize=8, frameon=False)
    return fig


def regime_rows(cells: Sequence[Any]) -> list[tuple[str, str, tuple[str, int]]]:
    """The rows of the cross-regime figure: ``(training task, label, group)`` grouped by domain and goal count,
    then by training regime; labelled ``2 goals · optimal`` (the domain first where cells span several, the task
    where a group has several of one regime)."""
    groups = sorted({(c.domain, c.goals) for c in cells})
    several = len({d for d, _ in groups}) > 1
    out = []
    for group in groups:
        mine = sorted((c for c in cells if (c.domain, c.goals) == group), key=lambda c: (c.train, c.task))
        tasks = list({c.task: c for c in mine}.values())
        one_each = len({c.train for c in tasks}) == len(tasks)
        prefix = (f"{group[0]} " if several else "") + f"{group[1]} goals · "
        out += [(c.task, prefix + (c.train if one_each else row_label(c)), group) for c in tasks]
    return out


def regimes(cells: Sequence[Any]) -> Any:
    """The cross-regime grid: a heatmap of F1 (mean over levels) per canonical configuration, training task
    (a row, grouped by domain and goal count) by test regime (a column), the unshifted task's cell outlined and
    every value printed (a figure; ``cells`` are :func:`grail_bench.report.shifts.regime_cells`; all
    configurations where none is canonical)."""
    plt = pyplot()
    canonical = [c for c in cells if c.canonical] or list(cells)
    labels = sorted({c.label for c in canonical if not c.reference}) + sorted({c.label for c in canonical
                                                                               if c.reference})
    rows = regime_rows(canonical)
    columns = regime_order(canonical)
    fig, axes = _grid(plt, len(labels), max(2.8, 0.5 * len(columns) + 0.9), max(2.4, 0.26 * len(rows) + 1.1),
                      extra=0.3)
    trains = {c.task: c.train for c in canonical}
    image = None
    for k, (ax, label) in enumerate(zip(axes, labels)):
        mine = {(c.task, c.test): c.result.f1_mean for c in canonical if c.label == label}
        image = _heat(ax, [[mine.get((task, col)) for col in columns] for task, _, _ in rows],
                      [name for _, name, _ in rows], columns, vmax=1.0)
        for row, (task, _, group) in enumerate(rows):
            if trains[task] in columns and (task, trains[task]) in mine:  # the unshifted task: its own regime
                ax.add_patch(plt.Rectangle((columns.index(trains[task]) - 0.5, row - 0.5), 1, 1, fill=False,
                                           edgecolor="black", linewidth=1.5))
            if row and rows[row - 1][2] != group:  # between goal counts
                ax.axhline(row - 0.5, color="0.2", linewidth=2.5, zorder=5)
        ax.set_aspect("auto")
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("test regime", fontsize=8)
        if k % PANELS_PER_ROW:
            ax.tick_params(labelleft=False)
        else:
            ax.set_ylabel("trained on", fontsize=8)
    fig.suptitle("Cross-regime grid: F1 (mean over levels)\noutlined: the unshifted task", fontsize=9)
    if image is not None:
        fig.colorbar(image, ax=axes, shrink=0.6, label="F1")
    return fig


def fit_curves(curves: dict[int, dict[str, Sequence[float]]], labels: Sequence[str]) -> Any | None:
    """One panel per logged training curve, one line per goal (a figure; None without curves)."""
    names = sorted({name for per_goal in curves.values() for name in per_goal})
    if not names:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.0), squeeze=False)
    for ax, name in zip(axes.flat, names):
        for k, per_goal in sorted(curves.items()):
            if per_goal.get(name):
                ax.plot(per_goal[name], label=labels[k], color=f"C{k % 10}")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("training (points in order)")
    axes.flat[0].legend(fontsize=7)
    return fig


def budgets(curves: Sequence[Any]) -> Any:
    """Budget studies: per (recognizer, parameter) a column, F1 with its 95 % band against the value (log scale)
    above, fit seconds per goal below; one line per task (a figure)."""
    plt = pyplot()
    panels = sorted({(c.recognizer, c.param) for c in curves})
    fig, axes = plt.subplots(2, len(panels), figsize=(3.8 * len(panels), 5.6), squeeze=False, sharex="col")
    for col, (recognizer, param) in enumerate(panels):
        top, bottom = axes[0, col], axes[1, col]
        mine = [c for c in curves if (c.recognizer, c.param) == (recognizer, param)]
        for i, c in enumerate(mine):
            x = [p.value for p in c.points]
            label = f"{short_name(c.task)} {level_text(c.observability)}"
            top.plot(x, [p.f1_mean for p in c.points], marker="o", color=f"C{i}", label=label)
            top.fill_between(x, [p.f1_ci95_low for p in c.points], [p.f1_ci95_high for p in c.points], color=f"C{i}", alpha=0.2)
            if c.plateau is not None:
                top.axvline(c.plateau, color=f"C{i}", linestyle=":", linewidth=1)
            bottom.plot(x, [p.fit_seconds_per_goal for p in c.points], marker="o", color=f"C{i}")
        top.set_title(f"{recognizer}: {param}", fontsize=9)
        top.set_ylim(0, 1.05)
        top.set_ylabel("F1")
        bottom.set_ylabel("fit s / goal")
        bottom.set_xlabel(param)
        for ax in (top, bottom):
            ax.set_xscale("log")
        top.legend(fontsize=7)
    return fig


def profiles(data: Sequence[dict[str, Any]]) -> Any:
    """Performance profiles: per domain summary a panel, per recognizer the share of runs above each normalised-F1
    threshold with its 95 % stratified bootstrap band (a figure)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(data), figsize=(4.4 * len(data), 3.4), squeeze=False)
    for ax, d in zip(axes.flat, data):
        for i, (name, (point, low, high)) in enumerate(sorted(d["curves"].items())):
            ax.plot(d["taus"], point, color=f"C{i % 10}", label=name)
            ax.fill_between(d["taus"], low, high, color=f"C{i % 10}", alpha=0.2)
        ax.set_title(f"{d['title']} ({d['strata']} strata)", fontsize=9)
        ax.set_xlabel("normalised F1 threshold τ")
        ax.set_ylabel("share of runs > τ")
        ax.set_ylim(0, 1.05)
        ax.legend(fontsize=7)
    return fig


def reliability(rows: Sequence[Any]) -> Any:
    """Reliability diagrams: per domain, each posterior column's accuracy against its mean confidence per bin,
    the diagonal being perfect calibration (a figure; rows are :func:`grail_bench.report.rows.calibration_rows`)."""
    plt = pyplot()
    domains = sorted({r.domain for r in rows})
    fig, axes = plt.subplots(1, len(domains), figsize=(4.0 * len(domains), 3.6), squeeze=False)
    for ax, domain in zip(axes.flat, domains):
        ax.plot([0, 1], [0, 1], color="grey", linestyle=":", linewidth=1)
        for i, r in enumerate(r for r in rows if r.domain == domain):
            b = np.asarray(r.bins, dtype=float)
            used = b[:, 0] > 0
            ece = "–" if r.ece is None else f"{r.ece:.3f}"
            ax.plot(b[used, 1] / b[used, 0], b[used, 2] / b[used, 0], marker="o", color=f"C{i % 10}",
                    label=f"{r.column} (ECE {ece})")
        ax.set_title(domain, fontsize=9)
        ax.set_xlabel("confidence (posterior of the predicted goal)")
        ax.set_ylabel("accuracy")
        ax.set_xlim(0, 1.02)
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=7)
    return fig
