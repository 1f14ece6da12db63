"""The leaderboard as one model, computed once from stored rows and drawn by every renderer.

:func:`build` aggregates the rows of each mode, computes the Bayes ceilings
the tables and the online figure need (once; each level cached on disk) and
attaches the reported values; the terminal tables, Markdown, the figures and
the web page all read the resulting :class:`Leaderboard`.
"""

from __future__ import annotations

from collections import defaultdict
from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Any, Sequence

from grail_bench.harness.ceiling import Ceiling, ceiling_curve, ceilings_for
from grail_bench.harness.diagnostics import FitRow, FitSummary, summarize
from grail_bench.harness.executors import Executor
from grail_bench.harness.modes import MODES, Mode, ResultRow
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.boards import Board, build_boards, ceiling_cells
from grail_bench.report.reference import Reported
from grail_bench.task import find_task


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
        boards: The paper-style tables, with reported values and ceilings attached.
        ceilings: The Bayes ceilings by ``(task, task parameters as JSON, protocol, level)``.
        reference: The reported values, if any.
        studies: Per mode beyond the offline one that has rows, its :class:`Study`.
        fits: The offline fits' diagnostics by ``(task, recognizer, config hash)``, where stored.
    """

    rows: list[ResultRow]
    records: list[OfflineRecord]
    boards: list[Board]
    ceilings: dict[tuple[str, str, str, float], Ceiling]
    reference: dict[tuple[str, str, float], Reported] | None = None
    studies: dict[str, Study] = field(default_factory=dict)
    fits: dict[tuple[str, str, str], FitSummary] = field(default_factory=dict)


def _progress(enabled: bool, total: int) -> tuple[Any, Any]:
    """A progress bar over the ceiling levels (a Monte Carlo one takes seconds) and the callback advancing it."""
    if not enabled or not total:
        return nullcontext(), None
    from rich.progress import Progress

    bar = Progress(transient=True)
    job = bar.add_task("Bayes and pairs-only ceilings (computed once, then cached)", total=total)
    return bar, lambda: bar.advance(job)


def build(rows: Sequence[ResultRow], reference: dict[tuple[str, str, float], Reported] | None = None,
          ceiling_samples: int | None = 2000, studies: dict[str, Sequence[Any]] | None = None,
          records: Sequence[OfflineRecord] | None = None, progress: bool = False,
          fits: Sequence[FitRow] = (), executor: Executor | None = None) -> Leaderboard:
    """The leaderboard of stored rows.

    Args:
        rows: Offline rows (every seed).
        reference: Reported values to show beside ours.
        ceiling_samples: Monte Carlo samples of the Bayes and pairs-only ceilings; None computes and shows none.
        studies: Rows of the other modes by mode name (``online``, ``open-set``).
        records: The offline records when already aggregated (else aggregated here).
        progress: Show a progress bar while ceilings are computed.
        fits: Stored fit diagnostics (:class:`~grail_bench.harness.diagnostics.FitRow`).
        executor: Where ceilings missing from the cache are computed (default: in this process).
    """
    rows = list(rows)
    records = list(records) if records is not None else MODES["offline"].aggregate(rows)
    studies_out = {}
    for name, mode_rows in (studies or {}).items():
        mode_rows = list(mode_rows)
        if mode_rows:
            studies_out[name] = Study(MODES[name], mode_rows, MODES[name].aggregate(mode_rows))
    cells = ceiling_cells(records) if ceiling_samples is not None else []
    online = studies_out.get("online")
    panels = _online_panels(online.records) if online is not None and ceiling_samples is not None else {}
    bar, tick = _progress(progress, 2 * len(cells) + sum(len(f) for _, f in panels.values()))
    with bar:
        ceilings = ceilings_for(cells, ceiling_samples, tick, executor=executor) if cells else {}
        pairs_only = ceilings_for(cells, ceiling_samples, tick, pairs_only=True, executor=executor) if cells else {}
        if online is not None:
            online.curves = {key: ceiling_curve(task, key[1], fractions, ceiling_samples, tick)
                             for key, (task, fractions) in panels.items() if task is not None}
    return Leaderboard(rows, records, build_boards(records, reference, ceilings, pairs_only), ceilings, reference,
                       studies_out, summarize(fits))


def _online_panels(records: Sequence[Any]) -> dict[tuple[str, str], tuple[Any, list[float]]]:
    """Per (task, protocol) of online records, the task with its run's parameters and the curve's fractions."""
    params: dict[tuple[str, str], list[Any]] = defaultdict(list)
    for r in records:
        params[(r.task, r.protocol)].append(r)
    return {key: (find_task(key[0], rs[0].task_params), list(rs[0].fractions)) for key, rs in sorted(params.items())}
