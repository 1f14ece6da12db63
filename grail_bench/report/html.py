"""The leaderboard as one static web page: ``grail-bench leaderboard --html DIR``.

The page (``DIR/index.html``) is rendered from a
:class:`~grail_bench.report.leaderboard.Leaderboard` through a Jinja2
template and needs nothing but a browser: no server, no network, CSS and a
small sorting/filtering script inline, figures inline as SVG, readable with
scripts off. Beside it, ``records.json`` holds the records behind every cell
(also embedded in the page).

Tables follow the boards (one per domain, regime and protocol; a row per task
and observability; a column per recognizer and scorer). Each cell shows the
mean F1 over seeds with a 95 % bootstrap interval
(:mod:`grail_bench.stats.robust`); the cells whose intervals overlap the best
one's are all marked, rather than one winner by a hair. Each domain gets an
aggregate (IQM with a bootstrap stratified by task, protocol and level, over
the strata every compared recognizer ran) and the probability of improvement
between its recognizers. Every other mode with runs gets a table (and the
online accuracy curves).
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any, Sequence

from grail_bench.harness.ceiling import normalised
from grail_bench.report import plots
from grail_bench.report.boards import (
    Board,
    column_label,
    config_variants,
    own_scorer_records,
    row_name,
)
from grail_bench.report.leaderboard import Leaderboard
from grail_bench.report.reference import MARKS, Reported
from grail_bench.report.rows import calibration_rows, timing_rows
from grail_bench.report.summary import domain_summaries, profile_figure_data
from grail_bench.report.text import comparison_lines
from grail_bench.stats.robust import (
    Interval,
    pooled_mean,
    stratified_bootstrap,
    tied_best,
)
from grail_bench.task import find_task


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
    verdict: str | None = None
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
    task = find_task(board.rows[0][1])
    return (task.domain, task.regime) if task else (board.title, "")


def _runs(rows: Sequence[Any]) -> tuple[list[dict[str, Any]], dict[str, int]]:
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


def _figure(section: Section, cells: dict[tuple, Cell], own: set[int]) -> str | None:
    """F1 against observability per task of a section, a line and interval band per own-scorer column."""
    tasks = sorted({row["key"] for row in section.rows})
    levels = {t: {row["obs"] for row in section.rows if row["key"] == t} for t in tasks}
    tasks = [t for t in tasks if len(levels[t]) > 1]
    if not tasks:
        return None
    lines = []
    for label, _ in section.columns:
        points = [(task, lv, c.mean, c.interval.low, c.interval.high) for (task, lv, lab, sid), c in cells.items()
                  if lab == label and sid == section.id and c.record in own and task in tasks]
        lines.append((label, points))
    return plots.svg(lambda: plots.section_lines(tasks, lines))


def _studies(board: Leaderboard) -> list[dict[str, Any]]:
    """The tables (and the online figure) of the other modes' runs, when there are any."""
    out = []
    for name, study in board.studies.items():
        records, mode = study.records, study.mode
        figure = plots.svg(lambda: plots.online(records, study.curves)) if name == "online" else None
        out.append({
            "id": name, "title": mode.title, "intro": mode.intro, "figure": figure,
            "header": [(c.header, isinstance(c.value(records[0]), str)) for c in mode.columns],
            "rows": [{"recognizer": r.recognizer, "cells": [(c.text(r), c.value(r)) for c in mode.columns]}
                     for r in records]})
    return out


def build_page(board: Leaderboard, reps: int = 2000, seed: int = 0) -> dict[str, Any]:
    """Everything the template shows.

    Args:
        board: The leaderboard (records, boards with ceilings and reported values, other modes).
        reps: Bootstrap replicates of every interval.
        seed: Seed of every bootstrap (same seed, same page).
    """
    records = board.records
    runs, run_index = _runs(board.rows)
    runs_of: dict[tuple, set[int]] = defaultdict(set)  # the runs behind each record
    for r in board.rows:
        key = (r.task, r.recognizer, r.scorer, r.config_hash, r.protocol, r.observability)
        runs_of[key].add(run_index[r.provenance or f"versions:{r.versions}"])
    variants = config_variants(records)
    position = {id(r): i for i, r in enumerate(records)}

    sections: list[Section] = []
    cells: dict[tuple, Cell] = {}
    by_domain: dict[str, list[Section]] = defaultdict(list)
    for n, b in enumerate(board.boards):
        domain, regime = _domain_regime(b)
        section = Section(f"s{n}", b.title, domain, regime,
                          [(c, next(r.recognizer for k, r in b.cells.items() if k[-1] == c)) for c in b.columns])
        for row in b.rows:
            ceiling = b.ceilings.get(row)
            shown: dict[str, Cell] = {}
            for label, _ in section.columns:
                record = b.cells.get((*row, label))
                if record is None:
                    continue
                interval = stratified_bootstrap({0: list(record.f1_values)}, pooled_mean, reps=reps, seed=seed)
                reported = b.reported.get((*row, label))
                verdict = reported.verdict(list(record.f1_values)) if reported else None
                key = (record.task, record.recognizer, record.scorer, record.config_hash, record.protocol,
                       record.observability)
                cell = Cell(position[id(record)], record.recognizer, record.f1_mean, interval, record.f1_iqm,
                            record.f1_std, record.n_seeds, sorted(runs_of[key]), reported,
                            reported.place(record.f1_mean) if reported else None,
                            verdict.verdict if verdict else None,
                            normalised(record.f1_mean, ceiling.accuracy, ceiling.chance) if ceiling else None)
                shown[label] = cells[(row_name(row), row[3], label, section.id)] = cell
            for label in tied_best({k: c.interval for k, c in shown.items()}):
                shown[label].best = True
            section.rows.append({"task": row[1], "key": row_name(row), "name": row_name(row), "goals": row[0],
                                 "obs": row[3],
                                 "ceiling": ceiling, "pairs_only": b.pairs_only.get(row),
                                 "cells": [shown.get(label) for label, _ in section.columns]})
        by_domain[domain].append(section)
        sections.append(section)
    own = {position[id(r)] for r in own_scorer_records(records)}  # records under their recognizer's own scorer
    for section in sections:
        section.figure = _figure(section, cells, own)

    summaries = domain_summaries(board.boards, reps, seed)
    calibration = calibration_rows(records)
    figure_data = profile_figure_data(summaries)
    cell_of = {c.record: c for c in cells.values()}
    exported = []
    for i, r in enumerate(records):
        c = cell_of.get(i)
        exported.append({**r.to_dict(), "id": i, "column": column_label(r, variants),
                         "f1_boot95_low": c.interval.low if c else None,
                         "f1_boot95_high": c.interval.high if c else None,
                         "paper_f1": c.paper.text if c and c.paper else None,
                         "paper_place": c.place if c else None,
                         "paper_verdict": c.verdict if c else None,
                         "normalised_f1": c.normalised if c else None,
                         "runs": c.runs if c else []})
    return {"sections": sections, "summaries": summaries, "runs": runs, "records": exported,
            "timings": timing_rows(records, board.fits), "domains": sorted(by_domain),
            "regimes": sorted({s.regime for s in sections}),
            "recognizers": sorted({r.recognizer for r in records}), "reps": reps, "seed": seed,
            "studies": _studies(board), "n_seeds": sorted({r.n_seeds for r in records}),
            "comparison": comparison_lines(board.boards),
            "profiles_figure": plots.svg(lambda: plots.profiles(figure_data)) if figure_data else None,
            "calibration": calibration,
            "calibration_figure": plots.svg(lambda: plots.reliability(calibration)) if calibration else None,
            "fits": {"|".join(key): summary.to_dict() for key, summary in sorted(board.fits.items())}}


def _json_for_script(data: Any) -> str:
    """JSON safe inside a ``<script>`` element."""
    return json.dumps(data, sort_keys=True, default=str).replace("</", "<\\/")


def render(page: dict[str, Any], title: str = "grail-bench leaderboard") -> str:
    """The page's HTML."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.PackageLoader("grail_bench.report", "templates"),
                             autoescape=jinja2.select_autoescape(["html"]), undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True)
    env.filters["f2"] = lambda v: "–" if v is None else f"{v:.2f}"
    return env.get_template("leaderboard.html").render(
        **page, title=title, version=version("grail-bench"), records_json=_json_for_script(page["records"]),
        fits_json=_json_for_script(page["fits"]))


def write_site(board: Leaderboard, out: str | Path, title: str = "grail-bench leaderboard") -> list[Path]:
    """Render the page into ``out`` (``index.html`` and ``records.json``); returns the files written."""
    out = Path(out)
    page = build_page(board)
    out.mkdir(parents=True, exist_ok=True)
    index, data = out / "index.html", out / "records.json"
    index.write_text(render(page, title), encoding="utf-8")
    data.write_text(json.dumps(page["records"], indent=1, sort_keys=True, default=str) + "\n", encoding="utf-8")
    return [index, data]
