"""The paper-style table model: offline records grouped into boards, computed once and drawn by every renderer.

One board per domain, regime and observation protocol, like the paper's
Table 2: a row per goal count and observability level (and per reading of the
task's parameters, where runs used other than its defaults), a column per
recognizer (``name/scorer`` when a recognizer was run with several scorers),
each cell an :class:`~grail_bench.harness.modes.offline.OfflineRecord`. Values
a publication reports are attached on the rows of each task's default protocol
only, beside each recognizer's default configuration where it ran in several
(the others are variants, so no cell is counted twice); Bayes ceilings come in already computed
(:func:`grail_bench.harness.ceiling.ceilings_for`), so no renderer computes one.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Iterable, Sequence


from grail_bench.harness.ceiling import Ceiling, Cell
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.recognizers.registry import UnknownRecognizerError, build, recognizer_info
from grail_bench.report.reference import Reported
from grail_bench.task import find_task, variant
from grail_bench.task.overrides import TaskOverrides

Row = tuple[int, str, str, float, str]  # (goals, task, protocol, observability, variant of the task's parameters)
CellKey = tuple[int, str, str, float, str, str]  # a row and a column label


@dataclass
class Board:
    """One table: a domain, regime and protocol; its rows, columns, cells, reported values and ceilings."""

    title: str
    columns: list[str]
    rows: list[Row] = field(default_factory=list)
    cells: dict[CellKey, OfflineRecord] = field(default_factory=dict)
    reported: dict[CellKey, Reported] = field(default_factory=dict)
    ceilings: dict[Row, Ceiling] = field(default_factory=dict)
    pairs_only: dict[Row, Ceiling] = field(default_factory=dict)

    def best(self, row: Row) -> float | None:
        """The best mean F1 of a row."""
        means = [self.cells[(*row, c)].f1_mean for c in self.columns if (*row, c) in self.cells]
        return max(means) if means else None

    def has_reported(self, column: str) -> bool:
        return any(key[-1] == column for key in self.reported)


@lru_cache(maxsize=None)
def paper_method(recognizer: str) -> tuple[str, str | None]:
    """``(published name, published scorer)`` from the recognizer's metadata (its own name and no scorer if
    it is not registered here)."""
    try:
        info = recognizer_info(recognizer)
    except UnknownRecognizerError:
        return recognizer, None
    return info.paper_name, info.default_scorer


@lru_cache(maxsize=None)
def default_config(recognizer: str) -> str | None:
    """The recognizer's default configuration as canonical JSON (None when it is not registered here or does
    not build without arguments)."""
    try:
        return _canonical(build(recognizer).config)
    except Exception:  # noqa: BLE001 - a plugin that cannot build on its own has no default to prefer
        return None


def _canonical(config: dict[str, Any]) -> str:
    return json.dumps(config, sort_keys=True, default=str)


def _is_default(record: OfflineRecord) -> bool:
    return _canonical(record.recognizer_config) == default_config(record.recognizer)


def own_scorer_records(records: Sequence[OfflineRecord]) -> list[OfflineRecord]:
    """Each recognizer's records under its own (the paper's) scorer (a plugin no longer installed: all of them)."""
    own = {name: paper_method(name)[1] for name in {r.recognizer for r in records}}
    return [r for r in records if own[r.recognizer] in (None, r.scorer)]


def row_name(row: Row) -> str:
    """A board row's task as tables show it: the short name, and the reading of its parameters if any."""
    return short_name(row[1]) + (f" ({row[4]})" if row[4] else "")


def short_name(task_id: str) -> str:
    """``GRAIL/MiniGrid-Optimal-4Goals-v0`` -> ``MiniGrid-Optimal-4Goals``."""
    name = task_id.removeprefix("GRAIL/")
    return name.rsplit("-v", 1)[0] if "-v" in name else name


def domain_of(task_id: str) -> str:
    """``GRAIL/PandaReach-Gaussian-0.1-v0`` -> ``PandaReach``."""
    return task_id.removeprefix("GRAIL/").split("-", 1)[0]


def column_label(record: Any, variants: dict[tuple[str, str], list[str] | None]) -> str:
    """``recognizer/scorer`` (just the recognizer for plugins with their own scoring).

    A recognizer run with several configurations gets one column per
    configuration, named by the settings that tell them apart (``sac_steps=60000``)
    or, when only the task's parameters differ, by the configuration hash.
    """
    label = record.recognizer
    if record.scorer != "default":
        label += f"/{record.scorer}"
    key = (record.recognizer, record.scorer)
    if key in variants:
        keys = variants[key]
        if keys:
            label += " " + " ".join(f"{k}={json.dumps(record.recognizer_config.get(k))}" for k in keys)
        else:
            label += f" [{record.config_hash[:6]}]"
    return label


def config_variants(records: Iterable[Any]) -> dict[tuple[str, str], list[str] | None]:
    """The recognizer settings that tell apart the configurations of each ``(recognizer, scorer)``.

    Only pairs run with more than one configuration on some task appear; their
    value is the sorted list of differing settings, or None when those settings
    do not separate the runs (they differ in task parameters) and only the hash can.
    """
    groups: dict[tuple[str, str, str], dict[str, dict[str, str]]] = defaultdict(dict)
    for r in records:
        config = {k: json.dumps(v, sort_keys=True) for k, v in r.recognizer_config.items()}
        groups[(r.task, r.recognizer, r.scorer)][r.config_hash] = config
    keys: dict[tuple[str, str], set[str] | None] = {}
    for (_, rec, scorer), by_hash in groups.items():
        if len(by_hash) < 2 or keys.get((rec, scorer), set()) is None:
            continue
        names = {k for c in by_hash.values() for k in c}
        differing = {k for k in names if len({c.get(k) for c in by_hash.values()}) > 1}
        separated = len({tuple(c.get(k) for k in sorted(differing)) for c in by_hash.values()}) == len(by_hash)
        keys[(rec, scorer)] = (keys.get((rec, scorer)) or set()) | differing if separated else None
    return {pair: sorted(k) if k else None for pair, k in keys.items()}


def cell_of_record(r: OfflineRecord) -> Cell:
    """The ceiling cell a record shows: its task, the parameters its runs used, its protocol and level."""
    return Cell(r.task, TaskOverrides.of(r.task_params), r.protocol, float(r.observability))


def ceiling_cells(records: Iterable[OfflineRecord]) -> list[Cell]:
    """The cells whose Bayes ceiling a set of records shows, sorted."""
    return sorted({cell_of_record(r) for r in records}, key=lambda c: (c.task, c.params.to_json(), c.protocol,
                                                                       c.level))


def build_boards(records: Iterable[OfflineRecord], reference: dict[tuple[str, str, float], Reported] | None = None,
                 ceilings: dict[Cell, Ceiling] | None = None,
                 pairs_only: dict[Cell, Ceiling] | None = None) -> list[Board]:
    """Group records into boards (see the module docstring).

    Args:
        records: Offline records (:func:`grail_bench.harness.modes.offline.aggregate`).
        reference: Reported values to show beside ours (on rows of the task's default parameters only, and
            beside the recognizer's default configuration where the row has it).
        ceilings: Bayes ceilings by cell (:func:`cell_of_record`), computed beforehand.
        pairs_only: Pairs-only ceilings, keyed alike.
    """
    records = list(records)
    tasks = {t: find_task(t) for t in {r.task for r in records}}
    readings: dict[tuple[str, TaskOverrides], str] = {}

    def reading_of(r: OfflineRecord) -> str:
        """How the run's task parameters differ from the task's defaults (rows stored before a parameter
        existed read as its implicit value, so they share the row of the runs that state it)."""
        key = (r.task, TaskOverrides.of(r.task_params))
        if key not in readings:
            readings[key] = variant(tasks[r.task], r.task_params) if tasks[r.task] else key[1].label()
        return readings[key]

    def cell_of(r: OfflineRecord) -> tuple[Any, ...]:
        """A record's cell whatever its configuration: task, reading, protocol, level, recognizer, scorer."""
        return r.task, reading_of(r), r.protocol, r.observability, r.recognizer, r.scorer

    variants = config_variants(records)
    # A recognizer run in several configurations on a row: the reported value sits beside its default one only.
    at_default = {cell_of(r) for r in records if _is_default(r)}
    ceilings, pairs_only = ceilings or {}, pairs_only or {}
    boards: dict[str, Board] = {}
    for r in records:
        task = tasks[r.task]
        title = (f"{task.domain} / {task.regime}" if task else r.task) + f" ({r.protocol})"
        board = boards.setdefault(title, Board(title=title, columns=[]))
        label = column_label(r, variants)
        if label not in board.columns:
            board.columns.append(label)
        reading = reading_of(r) if task else ""
        row = (len(task.goals) if task else 0, r.task, r.protocol, r.observability, reading)
        if row not in board.rows:
            board.rows.append(row)
            key = cell_of_record(r)
            if key in ceilings:
                board.ceilings[row] = ceilings[key]
            if key in pairs_only:
                board.pairs_only[row] = pairs_only[key]
        board.cells[(*row, label)] = r
        paper_protocol = task is not None and r.protocol == task.protocol_label and not reading
        beside_default = _is_default(r) or cell_of(r) not in at_default
        if reference and paper_protocol and beside_default and paper_method(r.recognizer)[1] in (r.scorer, None):
            reported = reference.get((r.task, r.recognizer, round(r.observability, 6)))
            if reported:
                board.reported[(*row, label)] = reported
    for board in boards.values():
        board.rows.sort()
        board.columns.sort()
    return [boards[k] for k in sorted(boards)]


def placement_counts(boards: Iterable[Board]) -> dict[str, int]:
    """How many of our cells fall inside, above and below the reported 95 % intervals."""
    counts = {"inside": 0, "above": 0, "below": 0}
    for board in boards:
        for key, reported in board.reported.items():
            place = reported.place(board.cells[key].f1_mean)
            if place:
                counts[place] += 1
    return counts


def verdict_counts(boards: Iterable[Board]) -> dict[str, int]:
    """How many of our cells a two-sided Welch test finds consistent with, higher or lower than the reported."""
    counts = {"consistent": 0, "higher": 0, "lower": 0}
    for board in boards:
        for key, reported in board.reported.items():
            verdict = reported.verdict(list(board.cells[key].f1_values))
            if verdict is not None:
                counts[verdict.verdict] += 1
    return counts
