"""The leaderboard as one static web page: ``grail-bench leaderboard --html DIR``.

The page (``DIR/index.html``) is rendered from the results store through a
Jinja2 template and needs nothing but a browser: no server, no network, CSS
and a small sorting/filtering script inline, figures inline as SVG, readable
with scripts off. Beside it, ``records.json`` holds the records behind every
cell (also embedded in the page).

Tables follow :mod:`grail_bench.leaderboard` (one per domain, regime and
protocol; a row per task and observability; a column per recognizer and
scorer). Each cell shows the mean F1 over seeds with a 95 % bootstrap interval
(:mod:`grail_bench.evaluation.robust`); the cells whose intervals overlap the
best one's are all marked, rather than one winner by a hair. Each domain gets
an aggregate (IQM with a bootstrap stratified by task and level) and the
probability of improvement between its recognizers. Online and open-set runs,
when the store has them, get a table each (and the online accuracy curves).
"""

from __future__ import annotations

import io
import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

from grail_bench.evaluation.robust import (
    Interval, pooled_iqm, pooled_mean, probability_of_improvement_ci, stratified_bootstrap, tied_best,
)
from grail_bench.leaderboard import (
    MARKS, Board, Reported, build_boards, column_label, config_variants, short_name, timing_rows,
)
from grail_bench.store import OnlineRow, OpenSetRow, ResultRow

Record = dict[str, Any]


@dataclass
class Cell:
    """One table cell: a record's F1 and everything shown beside it."""

    record: int
    recognizer: str
    mean: float
    interval: Interval
    iqm: float
    std: float
    seeds: int
    runs: list[int]  # the invocations that stored its rows
    paper: Reported | None = None
    place: str | None = None
    normalised: float | None = None
    best: bool = False

    @property
    def mark(self) -> str:
        return MARKS[self.place] if self.place else ""


@dataclass
class Section:
    """One table of the page."""

    id: str
    title: str
    domain: str
    regime: str
    columns: list[tuple[str, str]]  # (label, recognizer)
    rows: list[dict[str, Any]] = field(default_factory=list)
    figure: str | None = None


def _domain_regime(board: Board) -> tuple[str, str]:
    from grail_bench.leaderboard import _task

    task = _task(board.rows[0][1])
    return (task.domain, task.regime) if task else (board.title, "")


def _runs(rows: Sequence[ResultRow]) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """Distinct provenance stamps (one per invocation), numbered, with the package versions of their rows."""
    runs: list[dict[str, Any]] = []
    index: dict[str, int] = {}
    for r in rows:
        key = r.provenance or f"versions:{r.versions}"
        if key in index:
            continue
        index[key] = len(runs)
        entry = json.loads(r.provenance) if r.provenance else {"command": None}
        try:
            entry["versions"] = json.loads(r.versions)
        except ValueError:
            entry["versions"] = {}
        entry["id"] = len(runs)
        runs.append(entry)
    return runs, index


def _svg(fig: Any) -> str:
    import matplotlib.pyplot as plt

    buf = io.StringIO()
    fig.tight_layout()
    fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None, "Format": None, "Type": None})
    plt.close(fig)
    text = buf.getvalue()
    return text[text.index("<svg"):]


def _figure(section: Section, cells: dict[tuple, Cell], own: set[int]) -> str | None:
    """F1 against observability per task of a section, a line and interval band per own-scorer column.

    ``own`` holds the record indices run under their recognizer's own scorer.
    """
    from grail_bench.figures import _pyplot

    tasks = sorted({row["task"] for row in section.rows})
    levels = {t: sorted({row["obs"] for row in section.rows if row["task"] == t}) for t in tasks}
    tasks = [t for t in tasks if len(levels[t]) > 1]
    if not tasks:
        return None
    plt = _pyplot()
    # Text as text (smaller, selectable) and stable element IDs (same rows, same page).
    with plt.rc_context({"svg.fonttype": "none", "svg.hashsalt": "grail-bench"}):
        fig, axes = plt.subplots(1, len(tasks), figsize=(3.4 * len(tasks), 2.8), squeeze=False)
        for ax, task in zip(axes.flat, tasks):
            for i, (label, _) in enumerate(section.columns):
                line = [(lv, cells[(task, lv, label, section.id)]) for lv in levels[task]
                        if (task, lv, label, section.id) in cells]
                line = [(lv, c) for lv, c in line if c.record in own]
                if not line:
                    continue
                x = [100 * lv for lv, _ in line]
                ax.plot(x, [c.mean for _, c in line], marker="o", color=f"C{i % 10}", label=label)
                ax.fill_between(x, [c.interval.low for _, c in line], [c.interval.high for _, c in line],
                                color=f"C{i % 10}", alpha=0.2)
            ax.set_title(short_name(task), fontsize=9)
            ax.set_xlabel("observed (%)")
            ax.set_ylim(0, 1.05)
        axes.flat[0].set_ylabel("F1")
        axes.flat[0].legend(fontsize=7)
        return _svg(fig)


def _summary(domain: str, sections: list[Section], cells: dict[tuple, Cell], records: list[Record], own: set[int],
             reps: int, seed: int) -> dict[str, Any]:
    """IQM per own-scorer column across the domain's (task, protocol, level) strata, and P(improvement)."""
    strata: dict[str, dict[tuple, list[float]]] = defaultdict(dict)
    for section in sections:
        for row in section.rows:
            for label, _ in section.columns:
                cell = cells.get((row["task"], row["obs"], label, section.id))
                if cell is not None and cell.record in own:
                    strata[label][(row["task"], section.id, row["obs"])] = records[cell.record]["f1_values"]
    names = sorted(strata)
    iqms = {n: stratified_bootstrap(strata[n], pooled_iqm, reps=reps, seed=seed) for n in names}
    means = {n: pooled_mean(strata[n]) for n in names}
    best = tied_best(iqms)
    poi = {(a, b): probability_of_improvement_ci(strata[a], strata[b], reps=reps, seed=seed)
           for a in names for b in names if a != b and set(strata[a]) & set(strata[b])}
    recognizer = {label: rec for section in sections for label, rec in section.columns}
    return {"domain": domain, "names": names, "iqm": iqms, "mean": means, "best": best, "poi": poi,
            "strata": {n: len(strata[n]) for n in names}, "recognizer": recognizer}


def _studies(online: Sequence[OnlineRow], open_set: Sequence[OpenSetRow],
             ceiling_samples: int | None) -> list[dict[str, Any]]:
    """The tables (and the online figure) of the runs beyond the paper's protocol, when there are any."""
    from grail_bench.evaluation.online import aggregate_online
    from grail_bench.evaluation.open_set import aggregate_open_set
    from grail_bench import reports

    studies = []
    for sid, rows, aggregate, columns, title, intro in (
            ("online", online, aggregate_online, reports.ONLINE_COLUMNS, reports.ONLINE_TITLE, reports.ONLINE_INTRO),
            ("open-set", open_set, aggregate_open_set, reports.OPEN_SET_COLUMNS, reports.OPEN_SET_TITLE,
             reports.OPEN_SET_INTRO)):
        records = aggregate(rows)
        if not records:
            continue
        figure = None
        if sid == "online":
            import matplotlib.pyplot as plt

            with plt.rc_context({"svg.fonttype": "none", "svg.hashsalt": "grail-bench"}):
                figure = _svg(reports.online_figure(records, reports.online_ceilings(records, ceiling_samples)))
        studies.append({
            "id": sid, "title": title, "intro": intro, "figure": figure,
            "header": [(c.header, isinstance(c.value(records[0]), str)) for c in columns],
            "rows": [{"recognizer": r["recognizer"], "cells": [(c.text(r), c.value(r)) for c in columns]}
                     for r in records]})
    return studies


def build_page(rows: Sequence[ResultRow], reference: dict | None = None, ceiling_samples: int | None = 2000,
               reps: int = 2000, seed: int = 0, online: Sequence[OnlineRow] = (),
               open_set: Sequence[OpenSetRow] = ()) -> dict[str, Any]:
    """Everything the template shows, from stored rows.

    Args:
        rows: Stored rows (every seed; records are aggregated here).
        reference: Reported values (:func:`grail_bench.leaderboard.read_reference`).
        ceiling_samples: Monte Carlo samples of the Bayes ceilings; None shows none.
        reps: Bootstrap replicates of every interval.
        seed: Seed of every bootstrap (same seed, same page).
        online: Stored online rows, shown in a table and a figure of their own.
        open_set: Stored open-set rows, shown in a table of their own.
    """
    from grail_bench.evaluation.ceiling import normalised
    from grail_bench.evaluation.runner import aggregate
    from grail_bench.figures import own_scorer_records

    rows = list(rows)
    records = aggregate(rows)
    runs, run_index = _runs(rows)
    runs_of: dict[tuple, set[int]] = defaultdict(set)  # the runs behind each record
    for r in rows:
        key = (r.task, r.recognizer, r.scorer, r.config_hash, r.protocol, r.observability)
        runs_of[key].add(run_index[r.provenance or f"versions:{r.versions}"])
    variants = config_variants(records)
    position = {id(r): i for i, r in enumerate(records)}
    boards = build_boards(records, reference, ceiling_samples)

    sections: list[Section] = []
    cells: dict[tuple, Cell] = {}
    by_domain: dict[str, list[Section]] = defaultdict(list)
    for n, board in enumerate(boards):
        domain, regime = _domain_regime(board)
        section = Section(f"s{n}", board.title, domain, regime,
                          [(c, next(r["recognizer"] for k, r in board.cells.items() if k[-1] == c))
                           for c in board.columns])
        for row in board.rows:
            ceiling = board.ceilings.get(row)
            shown: dict[str, Cell] = {}
            for label, _ in section.columns:
                record = board.cells.get((*row, label))
                if record is None:
                    continue
                interval = stratified_bootstrap({0: record["f1_values"]}, pooled_mean, reps=reps, seed=seed)
                reported = board.reported.get((*row, label))
                key = (record["task"], record["recognizer"], record["scorer"], record["config_hash"],
                       record["protocol"], record["observability"])
                cell = Cell(position[id(record)], record["recognizer"], record["f1_mean"], interval,
                            record["f1_iqm"], record["f1_std"], record["n_seeds"], sorted(runs_of[key]), reported,
                            reported.place(record["f1_mean"]) if reported else None,
                            normalised(record["f1_mean"], ceiling.accuracy, ceiling.chance) if ceiling else None)
                shown[label] = cells[(row[1], row[3], label, section.id)] = cell
            for label in tied_best({k: c.interval for k, c in shown.items()}):
                shown[label].best = True
            section.rows.append({"task": row[1], "name": short_name(row[1]), "goals": row[0], "obs": row[3],
                                 "ceiling": ceiling, "cells": [shown.get(label) for label, _ in section.columns]})
        by_domain[domain].append(section)
        sections.append(section)
    own = {position[id(r)] for r in own_scorer_records(records)}  # records under their recognizer's own scorer
    for section in sections:
        section.figure = _figure(section, cells, own)

    summaries = [_summary(d, by_domain[d], cells, records, own, reps, seed) for d in sorted(by_domain)]
    cell_of = {c.record: c for c in cells.values()}
    exported = []
    for i, r in enumerate(records):
        c = cell_of.get(i)
        exported.append({**r, "id": i, "column": column_label(r, variants),
                         "f1_boot95_low": c.interval.low if c else None,
                         "f1_boot95_high": c.interval.high if c else None,
                         "paper_f1": c.paper.text if c and c.paper else None,
                         "paper_place": c.place if c else None,
                         "normalised_f1": c.normalised if c else None,
                         "runs": c.runs if c else []})
    return {"sections": sections, "summaries": summaries, "runs": runs, "records": exported,
            "timings": timing_rows(records), "domains": sorted(by_domain),
            "regimes": sorted({s.regime for s in sections}),
            "recognizers": sorted({r["recognizer"] for r in records}), "reps": reps, "seed": seed,
            "studies": _studies(online, open_set, ceiling_samples),
            "n_seeds": sorted({r["n_seeds"] for r in records})}


def _json_for_script(data: Any) -> str:
    """JSON safe inside a ``<script>`` element."""
    return json.dumps(data, sort_keys=True, default=str).replace("</", "<\\/")


def render(page: dict[str, Any], title: str = "grail-bench leaderboard") -> str:
    """The page's HTML."""
    import jinja2

    from grail_bench import __version__

    env = jinja2.Environment(loader=jinja2.PackageLoader("grail_bench", "templates"),
                             autoescape=jinja2.select_autoescape(["html"]), undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True)
    env.filters["f2"] = lambda v: "–" if v is None else f"{v:.2f}"
    return env.get_template("leaderboard.html").render(
        **page, title=title, version=__version__, records_json=_json_for_script(page["records"]))


def write_site(rows: Iterable[ResultRow], out: str | Path, reference: dict | None = None,
               ceiling_samples: int | None = 2000, title: str = "grail-bench leaderboard",
               online: Sequence[OnlineRow] = (), open_set: Sequence[OpenSetRow] = ()) -> list[Path]:
    """Render the page into ``out`` (``index.html`` and ``records.json``); returns the files written."""
    out = Path(out)
    page = build_page(list(rows), reference, ceiling_samples, online=online, open_set=open_set)
    out.mkdir(parents=True, exist_ok=True)
    index, data = out / "index.html", out / "records.json"
    index.write_text(render(page, title), encoding="utf-8")
    data.write_text(json.dumps(page["records"], indent=1, sort_keys=True, default=str) + "\n", encoding="utf-8")
    return [index, data]
