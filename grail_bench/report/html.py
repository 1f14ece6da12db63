"""The leaderboard as a static web site: ``grail-bench leaderboard --html DIR``.

The pages are rendered from a
:class:`~grail_bench.report.leaderboard.Leaderboard` through Jinja2
templates and need nothing but a browser: no server, no network, CSS and a
small sorting/filtering script inline, figures as SVG files beside them
(``DIR/figures/``, loaded lazily), readable with scripts off. The index
(``DIR/index.html``) opens on the per-domain summaries and the headline claims
checked against the data, then lists each domain's boards, the archived
configurations (with links to their runs), the other modes' tables, the
timings and the runs.

Each domain has a page of its own (``DIR/<domain>.html``): its main boards (one
per regime and protocol; a row per task and observability; a column per
method in its canonical configuration, the demonstrator after them as a
reference), then its named variants, folded. Each cell shows the mean F1 over seeds with a 95 % bootstrap
interval (:mod:`grail_bench.stats.robust`); the method cells whose intervals
overlap the best one's are all marked, rather than one winner by a hair.

To keep every page small (:data:`MAX_PAGE_BYTES`), what only some readers open
lives beside it, measured on the published store: figures are files of their
own (``figures/``, about 0.8 MB inline); a domain's page embeds only what its
main-board cells' details need (:data:`DETAILS`: its confusion matrix, and its
configuration's fit diagnostics with training curves thinned to
:data:`CURVE_POINTS` points and every value to :data:`DIGITS` significant
digits); variant cells show mean and interval only, their details fetched from
``records.json`` (every record in full, archived ones too, with their
configuration hashes, a record a line) and ``fits.json`` (every fit diagnostic) when asked for,
which needs the folder served over HTTP (browsers fetch nothing from a local
file); the timings table lists the canonical configurations (every
configuration's are in the Markdown leaderboard).
"""

from __future__ import annotations

import json
import re
from collections import defaultdict
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any, Sequence

from grail_bench.core.atomic import write_files
from grail_bench.harness.ceiling import normalised
from grail_bench.harness.diagnostics import FitSummary
from grail_bench.report import plots
from grail_bench.report.boards import ArchiveEntry, Board
from grail_bench.report.leaderboard import Leaderboard
from grail_bench.report.reference import MARKS, Reported
from grail_bench.report.rows import calibration_rows, timing_rows
from grail_bench.report.summary import DomainSummary, domain_summaries, profile_figure_data
from grail_bench.report.text import comparison_lines
from grail_bench.stats.robust import Interval, pooled_mean, stratified_bootstrap, tied_best

#: Every published page must stay under this size (records and diagnostics beyond a cell's details live beside
#: them). A domain's boards have a page of their own, so breadth adds pages rather than bytes to one.
MAX_PAGE_BYTES = 3_500_000

#: Training curves embedded for a cell's details are thinned to at most this many points each.
CURVE_POINTS = 40

#: Significant digits of the diagnostics embedded for a cell's details.
DIGITS = 3

#: The tag every page carries in its head, by which a later rendering knows the pages it may replace.
GENERATOR = '<meta name="generator" content="grail-bench">'

#: Where figures are written, beside the page.
FIGURES = "figures"

#: What the page embeds of a main-board cell's record for its details (the rest, and every variant's, is in
#: ``records.json``, fetched when a variant's details are asked for).
DETAILS = ("id", "task", "column", "protocol", "observability", "recognizer", "config_hash", "confusion")


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
    top2: float | None = None
    mean_rank: float | None = None
    paper: Reported | None = None
    place: str | None = None
    verdict: str | None = None
    normalised: float | None = None
    best: bool = False
    reference: bool = False

    @property
    def mark(self) -> str:
        return MARKS[self.place] if self.place else ""


@dataclass
class Column:
    """One configuration's column: its label, recognizer, and whether it is a reference (never ranked)."""

    label: str
    recognizer: str
    reference: bool = False
    reported: bool = False


@dataclass
class Section:
    """One table of the page: a main board, or a domain's variants."""

    id: str
    title: str
    domain: str
    regime: str
    columns: list[Column]
    kind: str = "canonical"
    protocols: bool = False  # a protocol column (variant boards span several)
    rows: list[dict[str, Any]] = field(default_factory=list)
    figure: str | None = None


@dataclass
class DomainPage:
    """One domain's page: its main boards and variants, what its main-board cells' details need (``details``:
    their records' :data:`DETAILS`; ``fits``: their configurations' diagnostics, thinned), the filters' choices and
    its cells' counts against the paper (``comparison``)."""

    domain: str
    file: str
    sections: list[Section]
    variants: list[Section]
    details: list[dict[str, Any]]
    fits: dict[str, dict[str, Any]]
    regimes: list[str]
    recognizers: list[str]
    comparison: list[str]


def _runs(rows: Sequence[Any]) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """Distinct provenance stamps (one per invocation), numbered in the order they were run (then by stamp, so the
    numbers do not depend on the order the store holds its rows; rows stored before stamps last), with the package
    versions of their rows."""
    stamps: dict[str, Any] = {}
    for r in rows:
        stamps.setdefault(r.provenance or f"versions:{r.versions}", r)
    entries = []
    for key, r in stamps.items():
        entry = json.loads(r.provenance) if r.provenance else {"command": None}
        try:
            entry["versions"] = json.loads(r.versions)
        except ValueError:
            entry["versions"] = {}
        date = str(entry.get("date") or "")
        entries.append((not date, date, key, entry))
    entries.sort(key=lambda e: e[:3])
    runs, index = [], {}
    for number, (*_, key, entry) in enumerate(entries):
        entry["id"], index[key] = number, number
        runs.append(entry)
    return runs, index


def _record_key(r: Any) -> tuple:
    return r.task, r.recognizer, r.scorer, r.config_hash, r.protocol, r.observability


def _figure(section: Section) -> Any:
    """F1 against observability per task of a main board, a line and interval band per column (its drawing, or
    None when no task has several levels)."""
    tasks = sorted({row["key"] for row in section.rows})
    levels = {t: {row["obs"] for row in section.rows if row["key"] == t} for t in tasks}
    tasks = [t for t in tasks if len(levels[t]) > 1]
    if not tasks:
        return None
    lines = []
    for i, column in enumerate(section.columns):
        points = [(row["key"], row["obs"], c.mean, c.interval.low, c.interval.high)
                  for row in section.rows if (c := row["cells"][i]) is not None and row["key"] in tasks]
        lines.append((column.label, points))
    return lambda: plots.section_lines(tasks, lines)


class _Figures:
    """The page's figures: each drawn once as SVG text, named by the file it is written to."""

    def __init__(self) -> None:
        self.files: dict[str, str] = {}

    def add(self, name: str, draw: Any) -> str | None:
        """The figure's path relative to the page (None for no drawing)."""
        if draw is None:
            return None
        path = f"{FIGURES}/{name}.svg"
        self.files[path] = plots.svg(draw)
        return path


def _studies(board: Leaderboard, figures: _Figures) -> list[dict[str, Any]]:
    """The tables (and the online figure) of the other modes' runs, when there are any."""
    out = []
    for name, study in board.studies.items():
        records, mode = study.records, study.mode
        figure = figures.add(name, (lambda: plots.online(records, study.curves)) if name == "online" else None)
        out.append({
            "id": name, "title": mode.title, "intro": mode.intro, "figure": figure,
            "header": [(c.header, isinstance(c.value(records[0]), str)) for c in mode.columns],
            "rows": [{"recognizer": r.recognizer, "cells": [(c.text(r), c.value(r)) for c in mode.columns]}
                     for r in records]})
    return out


class _Cells:
    """Builds the page's sections from boards, numbering records as ``records.json`` does."""

    def __init__(self, board: Leaderboard, reps: int, seed: int) -> None:
        self.reps, self.seed = reps, seed
        self.runs, run_index = _runs(board.rows)
        self.runs_of: dict[tuple, set[int]] = defaultdict(set)  # the runs behind each record
        for r in board.rows:
            self.runs_of[_record_key(r)].add(run_index[r.provenance or f"versions:{r.versions}"])
        self.position = {id(r): i for i, r in enumerate(board.records)}
        self.shown: dict[int, Cell] = {}  # by record id: every cell of every board

    def section(self, sid: str, b: Board) -> Section:
        columns = [Column(c, b.recognizer(c), b.is_reference(c), b.has_reported(c)) for c in b.columns]
        section = Section(sid, b.title, b.domain, b.regime, columns, b.kind, len(b.protocols) > 1)
        for row in b.rows:
            ceiling = b.ceilings.get(row)
            shown: dict[str, Cell] = {}
            for column in columns:
                record = b.cell(row, column.label)
                if record is not None:
                    shown[column.label] = self.cell(b, row, column, record, ceiling)
            ranked = {k: c.interval for k, c in shown.items() if not c.reference}
            for label in tied_best(ranked):
                shown[label].best = True
            section.rows.append({"task": row.task, "key": row.name, "name": row.name, "goals": row.goals,
                                 "obs": row.observability, "protocol": row.protocol, "ceiling": ceiling,
                                 "pairs_only": b.pairs_only.get(row),
                                 "cells": [shown.get(c.label) for c in columns]})
        return section

    def cell(self, b: Board, row: Any, column: Column, record: Any, ceiling: Any) -> Cell:
        interval = stratified_bootstrap({0: list(record.f1.values)}, pooled_mean, reps=self.reps, seed=self.seed)
        reported = b.reported.get((row, column.label))
        verdict = reported.verdict(list(record.f1.values)) if reported else None
        cell = Cell(self.position[id(record)], record.recognizer, record.f1.mean, interval, record.f1.iqm,
                    record.f1.std, record.n_seeds, sorted(self.runs_of[_record_key(record)]), record.top2_mean,
                    record.mean_rank_mean, reported, reported.place(record.f1.mean) if reported else None,
                    verdict.verdict if verdict else None,
                    normalised(record.f1.mean, ceiling.accuracy, ceiling.chance) if ceiling else None,
                    reference=column.reference)
        self.shown[cell.record] = cell
        return cell


def _thin(values: list[float], points: int = CURVE_POINTS) -> list[float]:
    """At most ``points`` evenly spaced values of a curve, its first and last kept."""
    if len(values) <= points:
        return values
    step = (len(values) - 1) / (points - 1)
    return [values[round(i * step)] for i in range(points)]


def _round(value: Any) -> Any:
    """Every float in ``value`` (nested lists and dicts) to :data:`DIGITS` significant digits."""
    if isinstance(value, float):
        return float(f"{value:.{DIGITS}g}")
    if isinstance(value, list | tuple):
        return [_round(v) for v in value]
    if isinstance(value, dict):
        return {k: _round(v) for k, v in value.items()}
    return value


def _thin_fit(fit: FitSummary) -> dict[str, Any]:
    """A fit's diagnostics as a cell's details show them: curves thinned, values rounded."""
    data = fit.to_dict()
    data["curves"] = {g: {name: _thin(v) for name, v in curves.items()} for g, curves in fit.curves.items()}
    return _round(data)


def _archive(entries: Sequence[ArchiveEntry], runs_of: dict[tuple, set[int]]) -> list[dict[str, Any]]:
    return [{"config": e.config, "tasks": [t.removeprefix("GRAIL/") for t in e.tasks], "seeds": e.seeds,
             "rows": e.rows, "records": len(e.records),
             "runs": sorted({i for r in e.records for i in runs_of[_record_key(r)]})} for e in entries]


def build_page(board: Leaderboard, reps: int = 2000, seed: int = 0, summaries: Sequence[DomainSummary] | None = None,
               claims: Sequence[Any] | None = None) -> dict[str, Any]:
    """Everything the template shows.

    Args:
        board: The leaderboard (records, boards with ceilings and reported values, other modes).
        reps: Bootstrap replicates of every interval.
        seed: Seed of every bootstrap (same seed, same page).
        summaries: The domain summaries when already computed (else computed here, with ``reps`` and ``seed``).
        claims: The headline claims when already checked (else checked here).
    """
    records = board.records
    cells, figures = _Cells(board, reps, seed), _Figures()
    sections = [cells.section(f"s{n}", b) for n, b in enumerate(board.boards)]
    variants = [cells.section(f"v{n}", b) for n, b in enumerate(board.variants)]
    for section in sections:
        section.figure = figures.add(section.id, _figure(section))
    if summaries is None:
        summaries = domain_summaries(board.boards, reps, seed)
    if claims is None:  # only for a store that ran the claims' tasks: a user's own tasks get no claims section
        from grail_bench.report.claims import claim_tasks, headline_claims

        ran = claim_tasks() & {r.task for r in records}
        claims = headline_claims(records, reps=reps, seed=seed) if ran else []
    calibration = calibration_rows(records)
    figure_data = profile_figure_data(summaries)
    exported = []
    for i, r in enumerate(records):
        c, config = cells.shown.get(i), board.config(r)
        exported.append({**r.to_dict(), "id": i, "column": config.label, "kind": config.kind,
                         "f1_boot95_low": c.interval.low if c else None,
                         "f1_boot95_high": c.interval.high if c else None,
                         "paper_f1": c.paper.text if c and c.paper else None,
                         "paper_place": c.place if c else None,
                         "paper_verdict": c.verdict if c else None,
                         "normalised_f1": c.normalised if c else None,
                         "runs": sorted(cells.runs_of[_record_key(r)])})
    canonical = {c.label for s in sections for c in s.columns}
    domains = sorted({s.domain for s in sections + variants})
    taken: set[str] = set()
    pages = [_domain_page(d, _page_file(d, taken), sections, variants, exported, board.fits,
                          comparison_lines([b for b in board.boards if b.domain == d])) for d in domains]
    return {"sections": sections, "variants": variants, "archive": _archive(board.archive, cells.runs_of),
            "summaries": summaries, "claims": [c for c in claims if c.configuration in canonical],
            "variant_claims": [c for c in claims if c.configuration not in canonical],
            "runs": cells.runs, "records": exported, "pages": pages,
            "timings": [t for t in timing_rows(records, board.fits) if t.column in canonical],
            "domains": domains,
            "recognizers": sorted({r.recognizer for r in records}), "reps": reps, "seed": seed,
            "studies": _studies(board, figures), "n_seeds": sorted({r.n_seeds for r in records}),
            "comparison": comparison_lines(board.boards),
            "profiles_figure": figures.add("profiles", (lambda: plots.profiles(figure_data)) if figure_data else None),
            "calibration": calibration,
            "calibration_figure": figures.add("reliability",
                                              (lambda: plots.reliability(calibration)) if calibration else None),
            "figures": figures.files,
            "fits": {"|".join(key): s.to_dict() for key, s in sorted(board.fits.items())}}


def _page_file(domain: str, taken: set[str]) -> str:
    """A file name for a domain's page, safe whatever the domain is called and unlike the others' (and the
    index's)."""
    stem = re.sub(r"[^a-z0-9_-]+", "-", domain.lower()).strip("-") or "domain"
    name, n = f"{stem}.html", 1
    while name in taken or name == "index.html":
        n += 1
        name = f"{stem}-{n}.html"
    taken.add(name)
    return name


def _domain_page(domain: str, file: str, sections: Sequence[Section], variants: Sequence[Section],
                 exported: Sequence[dict[str, Any]], fits: dict[tuple, FitSummary],
                 comparison: list[str]) -> DomainPage:
    """One domain's :class:`DomainPage`."""
    own, own_variants = [s for s in sections if s.domain == domain], [s for s in variants if s.domain == domain]
    main = sorted({c.record for s in own for row in s.rows for c in row["cells"] if c is not None})
    shown = {(exported[i]["task"], exported[i]["recognizer"], exported[i]["config_hash"]) for i in main}
    return DomainPage(domain, file, own, own_variants, details=[{k: exported[i][k] for k in DETAILS} for i in main],
                      fits={"|".join(key): _thin_fit(fit) for key, fit in sorted(fits.items()) if key in shown},
                      regimes=sorted({s.regime for s in own if s.regime}),
                      recognizers=sorted({c.recognizer for s in own + own_variants for c in s.columns}),
                      comparison=comparison)


def json_for_script(data: Any) -> str:
    """JSON safe inside a ``<script>`` element: ``<``, ``>`` and ``&`` written as ``\\u003c``, ``\\u003e`` and
    ``\\u0026``, so no string in it can end the element or open a comment."""
    text = json.dumps(data, sort_keys=True, default=str, separators=(",", ":"))
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def render(page: dict[str, Any], title: str = "grail-bench leaderboard", domain: str | None = None) -> str:
    """The index's HTML, or with ``domain`` that domain's page."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.PackageLoader("grail_bench.report", "templates"),
                             autoescape=jinja2.select_autoescape(["html"]), undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True)
    env.filters["f2"] = lambda v: "–" if v is None or v != v else f"{v:.2f}"
    context = {**page, "title": title, "version": version("grail-bench")}
    if domain is None:
        html = env.get_template("index.html").render(**context)
    else:
        here = next(p for p in page["pages"] if p.domain == domain)
        html = env.get_template("domain.html").render(**context, here=here,
                                                      records_json=json_for_script(here.details),
                                                      fits_json=json_for_script(here.fits))
    return re.sub(r"\n[ \t]+", "\n", html)  # the templates' indentation: a tenth of a page, shown nowhere


def json_lines(items: Sequence[Any]) -> str:
    """A JSON array with one compact item per line: a third smaller than indented JSON, and still a line per record
    in a diff."""
    lines = (json.dumps(item, sort_keys=True, default=str, separators=(",", ":")) for item in items)
    return "[\n" + ",\n".join(lines) + "\n]\n"


def write_site(board: Leaderboard, out: str | Path, title: str = "grail-bench leaderboard",
               summaries: Sequence[DomainSummary] | None = None, claims: Sequence[Any] | None = None,
               note: str | None = None) -> list[Path]:
    """Render the site into ``out``: ``index.html``, a page per domain, ``records.json``, ``fits.json`` and the
    figures (``figures/*.svg``); the pages and figures an earlier rendering wrote are removed (any other file in
    ``out`` is left alone). Returns the files written, the index first (``summaries`` and ``claims``: see
    :func:`build_page`; ``note``: a line under the index's heading, what the rows shown leave out)."""
    out = Path(out)
    page = build_page(board, summaries=summaries, claims=claims) | {"note": note}
    files = {"index.html": render(page, title)}
    files |= {p.file: render(page, title, p.domain) for p in page["pages"]}
    files |= {"records.json": json_lines(page["records"]),
              "fits.json": json.dumps(page["fits"], sort_keys=True, default=str) + "\n"}
    files |= dict(page["figures"])
    # Every file rendered first, then all written as one (a failed write leaves the earlier site whole); only
    # then the pages and figures of an earlier rendering that this one no longer has are removed.
    stale = [*(out / FIGURES).glob("*.svg"),
             *(p for p in out.glob("*.html") if GENERATOR in p.read_text(encoding="utf-8", errors="replace")[:2000])]
    written = write_files({out / name: text for name, text in files.items()})
    for old in stale:
        if old not in written:
            old.unlink()
    return written
