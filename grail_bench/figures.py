"""The paper's figures from aggregated records (PNG and SVG, matplotlib's Agg backend).

* ``f1_vs_observability``: F1 against the observed fraction, one panel per
  task with several levels, one line per recognizer (its own scorer) and the
  95 % interval over seeds as a band (the paper's Figure 3 family).
* ``panda_regimes``: PandaReach F1 per regime and method (Figure 4).
* ``scoring_time``: scoring microseconds per observation, per method and
  scorer (Figure 5).
* ``training_time``: training seconds per goal, per method (the efficiency section).
* ``model_size``: kilobytes of one goal's stored model, per method (the storage table).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

import numpy as np

Records = list[dict[str, Any]]


def own_scorer_records(records: Records) -> Records:
    """Each recognizer's rows under its own (the paper's) scorer."""
    from grail_bench.errors import UserError
    from grail_bench.recognizers.registry import recognizer_info

    own = {}
    for name in {r["recognizer"] for r in records}:
        try:
            own[name] = recognizer_info(name).default_scorer
        except UserError:  # a plugin no longer installed: keep whatever it was stored under
            own[name] = None
    return [r for r in records if own[r["recognizer"]] in (None, r["scorer"])]


def _domain(task_id: str) -> str:
    """``GRAIL/PandaReach-Gaussian-0.1-v0`` -> ``PandaReach``."""
    return task_id.removeprefix("GRAIL/").split("-", 1)[0]


def _short(task_id: str) -> str:
    from grail_bench.leaderboard import short_name

    return short_name(task_id)


def _save(fig: Any, out: Path, stem: str) -> list[Path]:
    import matplotlib.pyplot as plt

    paths = [out / f"{stem}.png", out / f"{stem}.svg"]
    fig.tight_layout()
    fig.savefig(paths[0], dpi=110)
    fig.savefig(paths[1])
    plt.close(fig)
    return paths


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def f1_vs_observability(records: Records, out: Path) -> list[Path]:
    """Figure 3 family (see module docstring); nothing when no task has several levels."""
    mine = own_scorer_records(records)
    levels = defaultdict(set)
    for r in mine:
        levels[r["task"]].add(r["observability"])
    tasks = sorted(t for t, lv in levels.items() if len(lv) > 1)
    if not tasks:
        return []
    plt = _pyplot()
    cols = min(3, len(tasks))
    rows = -(-len(tasks) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    recognizers = sorted({r["recognizer"] for r in mine})
    colours = {name: f"C{i}" for i, name in enumerate(recognizers)}
    for ax, task in zip(axes.flat, tasks):
        for name in recognizers:
            line = sorted((r for r in mine if r["task"] == task and r["recognizer"] == name),
                          key=lambda r: r["observability"])
            if not line:
                continue
            x = [r["observability"] * 100 for r in line]
            ax.plot(x, [r["f1_mean"] for r in line], marker="o", color=colours[name], label=name)
            ax.fill_between(x, np.clip([r["f1_ci95_low"] for r in line], 0, 1),
                            np.clip([r["f1_ci95_high"] for r in line], 0, 1),
                            color=colours[name], alpha=0.2)
        ax.set_title(_short(task), fontsize=9)
        ax.set_xlabel("observed (%)")
        ax.set_ylabel("F1")
        ax.set_ylim(0, 1.05)
    for ax in list(axes.flat)[len(tasks):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=8)
    return _save(fig, out, "f1_vs_observability")


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
    """Figure 4: PandaReach F1 per regime (task) and method; nothing without PandaReach rows."""
    mine = [r for r in own_scorer_records(records) if _domain(r["task"]) == "PandaReach"]
    if not mine:
        return []
    plt = _pyplot()
    tasks = sorted({r["task"] for r in mine})
    groups = [_short(t).removeprefix("PandaReach-") for t in tasks]
    f1, std = defaultdict(dict), defaultdict(dict)
    for r in mine:
        group = _short(r["task"]).removeprefix("PandaReach-")
        f1[r["recognizer"]][group] = r["f1_mean"]
        std[r["recognizer"]][group] = r["f1_std"]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(groups) + 2), 3.8))
    _bars(ax, groups, f1, std, "F1")
    ax.set_ylim(0, 1.1)
    ax.set_title(f"PandaReach, {min(r['observability'] for r in mine):.0%} observed", fontsize=9)
    return _save(fig, out, "panda_regimes")


def _per_domain(records: Records, value: Callable[[dict[str, Any]], float | None], label: Callable[[dict], str],
                ylabel: str, stem: str, out: Path, log: bool = False) -> list[Path]:
    """One bar panel per domain: the mean of ``value`` per method label."""
    means: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in records:
        v = value(r)
        if v is not None:
            means[_domain(r["task"])][label(r)].append(v)
    if not means:
        return []
    plt = _pyplot()
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
    return _save(fig, out, stem)


def scoring_time(records: Records, out: Path) -> list[Path]:
    """Figure 5: scoring µs per observation per method and scorer (mean over tasks and levels)."""
    return _per_domain(records, lambda r: r["score_us_per_observation"], lambda r: f"{r['recognizer']}/{r['scorer']}",
                       "scoring µs / observation", "scoring_time", out)


def training_time(records: Records, out: Path) -> list[Path]:
    """Training seconds per goal per method (mean over tasks and seeds)."""
    return _per_domain(own_scorer_records(records), lambda r: r["fit_seconds_per_goal"], lambda r: r["recognizer"],
                       "training s / goal", "training_time", out, log=True)


def model_size(sizes: dict[tuple[str, str], float], out: Path) -> list[Path]:
    """Kilobytes of one goal's stored model per method and domain (from :func:`grail_bench.reproduce.model_sizes`)."""
    if not sizes:
        return []
    plt = _pyplot()
    domains = sorted({d for d, _ in sizes})
    fig, axes = plt.subplots(1, len(domains), figsize=(4.0 * len(domains), 3.4), squeeze=False)
    for ax, domain in zip(axes.flat, domains):
        names = sorted(n for d, n in sizes if d == domain)
        ax.bar(range(len(names)), [sizes[(domain, n)] / 1024 for n in names],
               color=[f"C{i}" for i in range(len(names))])
        ax.set_xticks(range(len(names)), names, fontsize=8)
        ax.set_ylabel("KB per goal model")
        ax.set_title(domain, fontsize=9)
    return _save(fig, out, "model_size")


def write_all(records: Records, out: Path, models: dict[tuple[str, str], float]) -> list[Path]:
    """Every figure this module draws, into ``out``; returns the files written."""
    return (f1_vs_observability(records, out) + panda_regimes(records, out) + scoring_time(records, out)
            + training_time(records, out) + model_size(models, out))
