"""The leaderboard as one model, computed once from stored rows and drawn by every renderer.

:func:`build` aggregates the rows of each mode, names every configuration
(canonical, named variant or archived), computes the Bayes ceilings the
boards and the online figure need (once; each level cached on disk) and
attaches the reported values; the terminal tables, Markdown, the figures and
the web page all read the resulting :class:`Leaderboard`.
"""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Any, Sequence

from grail_bench.core.progress import progress
from grail_bench.harness.ceiling import Ceiling, Cell, ceilings_for, curve_cells, curve_of, distinct_cells
from grail_bench.harness.diagnostics import FitRow, FitSummary, summarize
from grail_bench.harness.executors import Executor
from grail_bench.harness.modes import MODES, Mode, ResultRow
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.boards import ArchiveEntry, Board, archive, build_boards, ceiling_cells, variant_boards
from grail_bench.report.configs import ConfigKey, Configuration, config_key, configurations
from grail_bench.report.reference import Reported


@dataclass
class Study:
    """The runs of one mode beyond the paper's protocol: rows, records and (online) the ceiling curves."""

    mode: Mode
    rows: list[Any]
    records: list[Any]
    curves: dict[tuple[str, str], list[float] | None] = field(default_factory=dict)


@dataclass
class Leaderboard:
    """Everything the renderers show (see the module docstring).

    Attributes:
        rows: The offline rows (each carries its run's provenance).
        records: Their across-seed records.
        boards: The main boards (canonical configurations), with reported values and ceilings attached.
        ceilings: The Bayes ceilings by cell (:class:`~grail_bench.harness.ceiling.Cell`).
        reference: The reported values, if any.
        studies: Per mode beyond the offline one that has rows, its :class:`Study`.
        fits: The offline fits' diagnostics by ``(task, recognizer, config hash)``, where stored.
        configs: Every record's configuration by :func:`~grail_bench.report.configs.config_key`.
        variants: One board per domain and method of the named variants.
        archive: The archived configurations.
    """

    rows: list[ResultRow]
    records: list[OfflineRecord]
    boards: list[Board]
    ceilings: dict[Cell, Ceiling]
    reference: dict[tuple[str, str, float], Reported] | None = None
    studies: dict[str, Study] = field(default_factory=dict)
    fits: dict[tuple[str, str, str], FitSummary] = field(default_factory=dict)
    configs: dict[ConfigKey, Configuration] = field(default_factory=dict)
    variants: list[Board] = field(default_factory=list)
    archive: list[ArchiveEntry] = field(default_factory=list)

    def config(self, record: Any) -> Configuration:
        """The configuration of one of the records."""
        return self.configs[config_key(record)]


def _progress(enabled: bool, total: int) -> tuple[Any, Any]:
    """A progress bar over the ceiling levels (a Monte Carlo one takes seconds) and the callback advancing it."""
    if not enabled or not total:
        return nullcontext(), None
    # On stderr (stdout holds the boards alone): a bar on a terminal, plain lines in a log.
    bar = progress("Bayes and pairs-only ceilings (computed once, then cached)", total, transient=True)
    return bar, bar.advance


def build(rows: Sequence[ResultRow], reference: dict[tuple[str, str, float], Reported] | None = None,
          ceiling_samples: int | None = 2000, studies: dict[str, Sequence[Any]] | None = None,
          records: Sequence[OfflineRecord] | None = None, progress: bool = False,
          fits: Sequence[FitRow] = (), executor: Executor | None = None, cache: Any | None = None) -> Leaderboard:
    """The leaderboard of stored rows.

    Args:
        rows: Offline rows (every seed).
        reference: Reported values to show beside ours.
        ceiling_samples: Monte Carlo samples of the Bayes and pairs-only ceilings; None computes and shows none
            (:func:`add_ceilings` adds them later).
        studies: Rows of the other modes by mode name (``online``, ``open-set``).
        records: The offline records when already aggregated (else aggregated here).
        progress: Show a progress bar while ceilings are computed.
        fits: Stored fit diagnostics (:class:`~grail_bench.harness.diagnostics.FitRow`).
        executor: Where ceilings missing from the cache are computed (default: in this process).
        cache: The store's ceiling cache (:class:`~grail_bench.harness.ceiling_cache.CeilingCache`), read and written
            beside the user's cache folder.
    """
    rows = list(rows)
    records = list(records) if records is not None else MODES["offline"].aggregate(rows)
    studies_out = {}
    for name, mode_rows in (studies or {}).items():
        mode_rows = list(mode_rows)
        if mode_rows:
            studies_out[name] = Study(MODES[name], mode_rows, MODES[name].aggregate(mode_rows))
    configs = configurations(records)
    board = Leaderboard(rows, records, [], {}, reference, studies_out, summarize(fits), configs, [],
                        archive(records, configs))
    if ceiling_samples is None:
        board.boards = build_boards(records, reference, {}, {}, configs)
        board.variants = variant_boards(records, {}, {}, configs)
    else:
        add_ceilings(board, ceiling_samples, progress, executor, cache)
    return board


def add_ceilings(board: Leaderboard, samples: int = 2000, progress: bool = False, executor: Executor | None = None,
                 cache: Any | None = None) -> None:
    """Compute the Bayes and pairs-only ceilings ``board`` shows (those cached are read) and attach them to its
    boards and its online curves (see :func:`build` for the arguments)."""
    records, configs = board.records, board.configs
    # Archived runs show no ceiling, nor do runs on a dataset's demonstrations (the task's ceiling assumes its own)
    shown = [r for r in records if (c := configs[config_key(r)]).kind != "archived" and c.dataset is None]
    cells = ceiling_cells(shown)
    online = board.studies.get("online")
    curves = _online_curve_cells(online.records) if online is not None else {}
    # The offline levels and the online fractions in one pass, so every worker helps with both.
    bayes_cells = distinct_cells([*cells, *(cell for curve in curves.values() for cell in curve)])
    bar, tick = _progress(progress, len(bayes_cells) + len(cells))
    with bar:
        ceilings = (ceilings_for(bayes_cells, samples, tick, executor=executor, store=cache)
                    if bayes_cells else {})
        pairs_only = (ceilings_for(cells, samples, tick, pairs_only=True, executor=executor, store=cache)
                      if cells else {})
    if online is not None:
        online.curves = {key: curve_of(curve, ceilings) for key, curve in curves.items()}
    board.ceilings = ceilings
    board.boards = build_boards(records, board.reference, ceilings, pairs_only, configs)
    board.variants = variant_boards(records, ceilings, pairs_only, configs)


def _online_curve_cells(records: Sequence[Any]) -> dict[tuple[str, str], list[Cell]]:
    """Per (task, protocol) of online records, the cells of its ceiling curve (its run's parameters and
    fractions)."""
    first: dict[tuple[str, str], Any] = {}
    for r in records:
        first.setdefault((r.task, r.protocol), r)
    return {key: curve_cells(key[0], r.task_params, key[1], list(r.fractions)) for key, r in sorted(first.items())}
