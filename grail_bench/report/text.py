"""Terminal (rich) and Markdown renderings of the boards (the paper-style F1 tables) and the leaderboard document.

Every table is built once as a header and rows of text (a *grid*), then drawn
by rich or written as Markdown; nothing here computes a statistic or a ceiling.
Names in Markdown are escaped by :func:`grail_bench.report.escape.md`, so no
configuration's name becomes markup.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

from rich.text import Text

from grail_bench.harness.ceiling import Ceiling, normalised
from grail_bench.report.claims import ClaimResult
from grail_bench.report.configs import SEPARATOR
from grail_bench.report.boards import (
    ArchiveEntry,
    Board,
    BoardRow,
    placement_counts,
    verdict_counts,
)
from grail_bench.report.layout import Fitted, grid_table, stacked
from grail_bench.report.reference import MARKS
from grail_bench.report.summary import DomainSummary
from grail_bench.report.escape import md
from grail_bench.report.tables import runs_markdown
from grail_bench.task.observation import level_text

Grid = tuple[list[str], list[list[tuple[str, bool]]]]  # header; per row, (text, bold) cells

VERDICT_MARKS = {"consistent": "", "higher": "↑", "lower": "↓"}

#: What a board's bracketed values and marks mean (terminal captions and the Markdown intro).
LEGEND = ("[0.83] = normalised F1, (F1 - chance) / (ceiling - chance); the ceiling bounds expected accuracy, not "
          "F1, so above 1 (e.g. [1.06]) is F1 above the accuracy ceiling, not a method beating it; = ▲ ▼: inside, above, below the "
          "paper's 95 % interval; ↑ ↓: a Welch test finds ours higher, lower; bold: best of its row (methods "
          "only); (reference): shown for comparison, never ranked")


def _cell(board: Board, row: BoardRow, column: str, ci: bool = False) -> tuple[str, bool]:
    record = board.cell(row, column)
    if record is None:
        return "–", False
    text = f"{record.f1.mean:.2f} ± {record.f1.std:.2f}"
    if ci:
        text += f" ({record.f1.ci95[0]:.2f}–{record.f1.ci95[1]:.2f})"
    reported = board.reported.get((row, column))
    if reported is not None:
        place = reported.place(record.f1.mean)
        verdict = reported.verdict(list(record.f1.values))
        text += f" {MARKS[place]}" if place else ""
        text += VERDICT_MARKS[verdict.verdict] if verdict else ""
    ceiling = board.ceilings.get(row)
    if ceiling is not None:
        norm = normalised(record.f1.mean, ceiling.accuracy, ceiling.chance)
        text += f" [{norm:.2f}]" if norm is not None else ""
    return text, not board.is_reference(column) and record.f1.mean == board.best(row)


def _ceiling_text(ceiling: Ceiling | None) -> str:
    if ceiling is None:
        return "–"
    return f"{ceiling.accuracy:.2f}" + (f" ± {ceiling.stderr:.2f}" if ceiling.method == "monte-carlo" else "")


def column_header(board: Board, column: str, name: Callable[[str], str] = str) -> str:
    """A column's header: its label, and ``(reference)`` after a reference's."""
    return name(column) + (" (reference)" if board.is_reference(column) else "")


def board_grid(board: Board, paper_label: Callable[[str], str] = str, ci: bool = False,
               name: Callable[[str], str] = str) -> Grid:
    """The table model both renderers draw: a header and, per row, ``(text, best)`` cells.

    Args:
        paper_label: The header of the reported values beside a column, from the column's label.
        ci: Also show each cell's 95 % Student-t interval over seeds.
        name: How names (labels, tasks) are written (:func:`md` for Markdown).
    """
    protocols = len(board.protocols) > 1
    header = ["task", *(["protocol"] if protocols else []), "goals", "obs", "ceiling"]
    header += ["pairs-only"] if board.pairs_only else []
    for c in board.columns:
        header.append(column_header(board, c, name))
        if board.has_reported(c):
            header.append(paper_label(c))
    rows = []
    for row in board.rows:
        cells = [(name(row.name), False), *([(name(row.protocol), False)] if protocols else []),
                 (str(row.goals), False), (level_text(row.observability), False),
                 (_ceiling_text(board.ceilings.get(row)), False)]
        if board.pairs_only:
            cells.append((_ceiling_text(board.pairs_only.get(row)), False))
        for c in board.columns:
            cells.append(_cell(board, row, c, ci))
            if board.has_reported(c):
                cells.append((str(board.reported.get((row, c), "–")), False))
        rows.append(cells)
    return header, rows


def rich_tables(boards: Sequence[Board]) -> list[Fitted]:
    """Terminal tables (best mean per row in bold, references dim): a column per configuration where the
    console is wide enough, else each row's values stacked under its task; names are never cut."""
    tables = []
    for board in boards:
        header, rows = board_grid(board, lambda c: f"{c} (paper)")
        dim = {i for i, h in enumerate(header) if h.endswith(("(paper)", "(reference)"))}
        cells = [[Text(text, style="bold" if best else "dim" if i in dim else "") for i, (text, best) in
                  enumerate(row)] for row in rows]
        title = f"F1 (mean ± std over seeds): {board.title}"
        keys = 1 + (len(board.protocols) > 1)
        tables.append(Fitted(grid_table(title, header, cells, LEGEND, first_style=None),
                             stacked(title, header, cells, keys=keys, caption=LEGEND)))
    return tables


def comparison_lines(boards: Sequence[Board]) -> list[str]:
    """The counts of our cells against the reported values: placement and Welch verdicts (empty without any)."""
    places, verdicts = placement_counts(boards), verdict_counts(boards)
    lines = []
    if any(places.values()):
        lines.append(f"Against the paper's 95 % intervals (appendix tables): our mean is inside (=) in "
                     f"{places['inside']} cells, above (▲) in {places['above']}, below (▼) in {places['below']}.")
    if any(verdicts.values()):
        lines.append(f"Two-sided Welch test of our seeds against the paper's mean and std over its 10 seeds "
                     f"(alpha 0.05): consistent in {verdicts['consistent']} cells, significantly higher (↑) in "
                     f"{verdicts['higher']}, lower (↓) in {verdicts['lower']}.")
    return lines


def _board_markdown(board: Board, ci: bool, level: str = "##") -> list[str]:
    header, rows = board_grid(board, lambda c: f"{md(c)} *(paper)*", ci, name=md)
    lines = [f"{level} {md(board.title)}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(f"**{text}**" if best else text for text, best in cells) + " |" for cells in rows]
    return lines + [""]


def summaries_markdown(summaries: Sequence[DomainSummary]) -> list[str]:
    """The domain summaries: per domain the strata compared, each method's IQM with its interval and mean, and
    the strata any method lacks."""
    lines = ["## Summary per domain", "",
             "Per domain, every method in its canonical configuration (references such as the demonstrator apart)",
             "over the (task, protocol, level) strata all of them ran: interquartile mean (IQM) of F1 over every",
             "seed with a 95 % bootstrap interval stratified by stratum, and the plain mean. Bold: every method",
             "whose interval overlaps the best one's. A domain whose methods do not all share a stratum gets one",
             "summary per group that does, numbered, so that every method is ranked in one.", ""]
    for s in summaries:
        lines += [f"### {md(s.title)}", "",
                  f"Over the {s.strata} strata all {len(s.names)} methods ran: "
                  + "; ".join(md(t) for t in s.strata_text) + ".", "",
                  "| method | IQM | 95 % interval | mean | strata run |", "|---|---|---|---|---|"]
        for n in s.names:
            iqm = f"{s.iqm[n].point:.2f}"
            lines.append(f"| {md(n)} | {f'**{iqm}**' if n in s.best else iqm} | [{s.iqm[n].low:.2f}, "
                         f"{s.iqm[n].high:.2f}] | {s.mean[n]:.2f} | {s.all_strata[n]} |")
        lines.append("")
        notes = [f"- {md(n)} lacks strata other methods ran (not run for it in these results): {md(text)}."
                 for n, text in s.gaps_text.items()]
        notes += [f"- Ranked in {md(t)} (no stratum shared with all of these): {md(', '.join(names))}."
                  for t, names in s.ranked_elsewhere.items()]
        lines += notes + ([""] if notes else [])
    return lines


def summary_tables(summaries: Sequence[DomainSummary]) -> list[Fitted]:
    """The domain summaries as terminal tables (the rows of :func:`summaries_markdown`): per method the IQM of F1
    with its 95 % interval, the mean and the strata run; bold where the interval overlaps the best one's."""
    header = ["method", "IQM [95 % interval]", "mean", "strata run"]
    tables = []
    for s in summaries:
        rows = [[Text(n, style="bold" if n in s.best else ""),
                 Text(f"{s.iqm[n].point:.2f} [{s.iqm[n].low:.2f}, {s.iqm[n].high:.2f}]",
                      style="bold" if n in s.best else ""), f"{s.mean[n]:.2f}", str(s.all_strata[n])]
                for n in sorted(s.names, key=lambda n: -s.iqm[n].point)]
        strata = s.strata_text
        notes = [f"Over the {s.strata} (task, protocol, level) strata all {len(s.names)} methods ran"
                 + (": " + "; ".join(strata) + "." if len(strata) <= 3 else
                    f", in {len(strata)} tasks and protocols (--markdown lists them).")]
        lacking = [f"{n} ({len(s.missing[n])})" for n in s.names if s.missing.get(n)]
        notes += [f"Strata another method ran and these did not: {', '.join(lacking)}."] if lacking else []
        notes += [f"Ranked in {t}: {', '.join(names)}." for t, names in s.ranked_elsewhere.items()]
        caption = "\n".join(notes)
        title = f"F1 per method, IQM over seeds and strata: {s.title}"
        tables.append(Fitted(grid_table(title, header, rows, caption, first_style=None),
                             stacked(title, header, rows, caption=caption)))
    return tables


def claims_table(results: Sequence[ClaimResult], all_variants: bool = False) -> Fitted:
    """The headline claims: one row per claim and canonical method, its best named variant beside it (the one
    with the highest estimate); ``all_variants`` adds a row per named variant under its method."""
    header = ["claim", "method", "estimate [95 % CI]", "verdict", "best named variant"]
    groups: dict[tuple[str, str], list[ClaimResult]] = {}
    for r in results:
        groups.setdefault((r.claim, r.configuration.split(SEPARATOR)[0]), []).append(r)
    rows, previous = [], None
    measured_claims = {claim for (claim, _), group in groups.items() if any(r.verdict != "not measured" for r in group)}
    for (claim, method), group in groups.items():
        if claim not in measured_claims:  # none of its strata in these runs: counted under the table
            continue
        canonical = next((r for r in group if r.configuration == method), None)
        variants = [r for r in group if r.configuration != method]
        measured = [r for r in variants if not math.isnan(r.estimate)]
        best = max(measured, key=lambda r: r.estimate) if measured else None
        beside = (f"{best.configuration.removeprefix(method + SEPARATOR)}: {_estimate(best)} {best.verdict}"
                  if best else "–")
        shown = canonical or group[0]
        rows.append([claim if claim != previous else "", method, _estimate(shown) if canonical else "–",
                     Text(shown.verdict if canonical else "not run", style="bold" if shown.verdict == "holds" else ""),
                     beside if not all_variants else f"{len(variants)} below" if variants else "–"])
        previous = claim
        if all_variants:
            rows += [["", f"  {r.configuration}", _estimate(r), r.verdict, ""] for r in variants]
    unmeasured = len({claim for claim, _ in groups} - measured_claims)
    caption = ("Verdicts: holds, the 95 % interval lies inside the claimed range; does not hold, wholly outside; "
               "partly, it straddles an end; not measured, a stratum the claim needs was not run. "
               + (f"Not listed: {unmeasured} of the paper's claims, whose strata these runs lack. " if unmeasured else "")
               + ("" if all_variants else "--all-variants lists every named variant."))
    title = "The paper's headline claims, measured on these runs"
    return Fitted(grid_table(title, header, rows, caption, first_style=None), stacked(title, header, rows, keys=2,
                                                                                        caption=caption))


def _estimate(r: ClaimResult) -> str:
    if math.isnan(r.estimate):
        return "–"
    return f"{r.estimate + 0.0:.2f} [{r.low + 0.0:.2f}, {r.high + 0.0:.2f}]"


def archive_markdown(entries: Sequence[ArchiveEntry]) -> list[str]:
    """The archived configurations: method, label, what differs from today's default, tasks, seeds, rows."""
    if not entries:
        return []
    lines = ["## Archive", "",
             "Configurations today's code would store under another hash (a superseded default, or a setting or",
             "task parameter since added, removed or refused): kept for provenance, out of every board and",
             "summary. Changes: the settings that differ from today's default.", "",
             "| method | label | changes | tasks | seeds | rows | config hash |", "|---|---|---|---|---|---|---|"]
    for e in entries:
        tasks = ", ".join(md(t.removeprefix("GRAIL/")) for t in e.tasks)
        seeds = _span(e.seeds)
        lines.append(f"| {md(e.config.method)} | {md(e.config.label)} | {md(e.config.changes_text)} | {tasks} | "
                     f"{seeds} | {e.rows} | `{md(e.config.config_hash)}` |")
    return lines + [""]


def _span(values: Sequence[int]) -> str:
    """``0–9`` for consecutive integers, else ``0, 2, 5``."""
    if values and list(values) == list(range(values[0], values[-1] + 1)) and len(values) > 2:
        return f"{values[0]}–{values[-1]}"
    return ", ".join(map(str, values))


def markdown(boards: Sequence[Board], records: Sequence[Any], ci: bool = False,
             title: str = "grail-bench leaderboard", fits: dict | None = None, *,
             variants: Sequence[Board] = (), archive: Sequence[ArchiveEntry] = (),
             summaries: Sequence[DomainSummary] = (), claims: Sequence[Any] | None = None,
             note: str | None = None) -> str:
    """The leaderboard as Markdown: claims and summaries, the main boards, variants and archive, then seeds,
    timings and ranking metrics.

    Args:
        boards: The main boards (canonical configurations).
        ci: Also show each cell's 95 % Student-t interval over seeds (the paper's appendix format).
        title: The document's heading.
        fits: Fit diagnostics by (task, recognizer, config hash), for the share of fits reaching their goal.
        variants: The variant boards (a "Variants" section).
        archive: The archived configurations (an "Archive" section).
        summaries: The domain summaries (:func:`grail_bench.report.summary.domain_summaries`).
        claims: The headline claims checked (:func:`grail_bench.report.claims.headline_claims`), if any.
        note: A paragraph (Markdown) after the introduction: what the rows shown leave out.
    """
    lines = [f"# {md(title)}", "",
             "F1 of each method in its canonical configuration (today's default, under its own scorer, named",
             "as the paper names it), mean ± std over seeds" + (" (95 % CI over seeds)" if ci else "")
             + " (best of each row in bold). Where the task has a",
             "Bayes ceiling (the best accuracy any recognizer can reach under that protocol and level; ± its",
             "Monte Carlo standard error), the cell adds the normalised F1 in brackets,",
             "(F1 - chance) / (ceiling - chance). The ceiling bounds expected accuracy, not F1: a normalised F1",
             "above 1 (e.g. [1.06]) is F1 above the accuracy ceiling (macro F1 can exceed accuracy, and a few",
             "seeds vary), not a method beating the Bayes-optimal one. The pairs-only ceiling is the accuracy of scoring each goal",
             "from the observed pairs through that goal's own demonstrator (as GRAIL, GRAQL and DRACO score,",
             "with perfect policies): how far a method is from what its form allows. The demonstrator (perfect",
             "imitation) is a reference, shown after the methods and never ranked.",
             "Columns marked *(paper)* are the values the GRAIL paper (AAMAS 2026) reports, transcribed",
             "from its tables and text; they were not produced by grail-bench, and are shown on the rows",
             "of each task's default protocol only. Other configurations are under Variants (named by how they",
             "differ) and, if run by an earlier version, under Archive.", ""]
    if note:  # the caller's Markdown
        lines += [note, ""]
    if claims is not None:
        from grail_bench.report.claims import claims_markdown

        lines += [claims_markdown(claims).rstrip("\n"), ""]
    if summaries:
        lines += summaries_markdown(summaries)
    comparison = comparison_lines(boards)
    if comparison:
        lines += [" ".join(comparison), ""]
    for board in boards:
        lines += _board_markdown(board, ci)
    if variants:
        lines += ["## Variants", "",
                  "Every other configuration today's code runs, per domain, named by how it differs from the",
                  "method's canonical one (a setting and its value, or another scorer).", ""]
        for board in variants:
            lines += _board_markdown(board, ci, "###")
    lines += archive_markdown(archive)
    lines += runs_markdown(records, fits, intervals=ci)
    return "\n".join(lines) + "\n"
