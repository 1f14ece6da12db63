"""The paper-style table model: offline records grouped into boards, computed once and drawn by every renderer.

Every record's configuration is named first (:mod:`grail_bench.report.configs`): canonical, a named variant or
archived. **Main boards** (one per domain, regime and observation protocol, like the paper's Tables 3 and 4) show the
canonical configurations: a row per goal count and observability level (and per reading of the task's
parameters, where runs used other than its defaults), a column per method named as the paper names it, each
cell an :class:`~grail_bench.harness.modes.offline.OfflineRecord`. References (the demonstrator) sit after the
methods and never count as a row's best. **Variant boards** (one per domain and method) show every named
variant, a column per label. **Archived** configurations are listed (:func:`archive`), in no board.

Values a publication reports are attached beside canonical columns, on the rows of each task's default
protocol and parameters only; Bayes ceilings come in already computed
(:func:`grail_bench.harness.ceiling.ceilings_for`), so no renderer computes one.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Iterable, Literal, Sequence

from grail_bench.harness.ceiling import Ceiling, Cell
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.configs import ConfigKey, Configuration, config_key, configurations, method_of
from grail_bench.report.reference import Reported
from grail_bench.task import find_task, variant
from grail_bench.task.overrides import TaskOverrides

BoardKind = Literal["canonical", "variant"]


@dataclass(frozen=True, order=True)
class BoardRow:
    """One row of a board (rows sort by goal count, task, protocol, level, then reading).

    Attributes:
        goals: The task's goal count (0 for a task not registered here).
        task: The task id.
        protocol: The observation protocol as stored (``subset``, ``prefix+floor``).
        observability: The observed fraction (or count) of the level.
        reading: How the runs' task parameters differ from the task's defaults (empty: the defaults).
    """

    goals: int
    task: str
    protocol: str
    observability: float
    reading: str = ""

    @property
    def name(self) -> str:
        """The task as tables show it: the short name, and the reading of its parameters if any."""
        return short_name(self.task) + (f" ({self.reading})" if self.reading else "")

    @property
    def stratum(self) -> tuple[str, str, float]:
        """``(task as shown, protocol, level)``: what summaries compare methods over."""
        return self.name, self.protocol, self.observability


CellKey = tuple[BoardRow, str]  # a row and a column label


@dataclass
class Board:
    """One table: its rows, columns (labels), cells, reported values and ceilings.

    Attributes:
        title: ``minigrid / optimal (subset)`` (main) or ``minigrid: BC-GRAIL variants``.
        columns: Column labels, methods first (sorted), references after them.
        kind: ``canonical`` (a main board) or ``variant``.
        domain: The domain of its tasks.
        regime: The regime of a main board's tasks (empty on variant boards).
        configs: Each column's configuration.
    """

    title: str
    columns: list[str]
    kind: BoardKind = "canonical"
    domain: str = ""
    regime: str = ""
    rows: list[BoardRow] = field(default_factory=list)
    cells: dict[CellKey, OfflineRecord] = field(default_factory=dict)
    reported: dict[CellKey, Reported] = field(default_factory=dict)
    ceilings: dict[BoardRow, Ceiling] = field(default_factory=dict)
    pairs_only: dict[BoardRow, Ceiling] = field(default_factory=dict)
    configs: dict[str, Configuration] = field(default_factory=dict)

    def cell(self, row: BoardRow, column: str) -> OfflineRecord | None:
        return self.cells.get((row, column))

    def is_reference(self, column: str) -> bool:
        config = self.configs.get(column)
        return config is not None and config.reference

    @property
    def methods(self) -> list[str]:
        """The columns that are methods (ranked and summarised), not references."""
        return [c for c in self.columns if not self.is_reference(c)]

    @property
    def protocols(self) -> list[str]:
        return sorted({row.protocol for row in self.rows})

    def best(self, row: BoardRow) -> float | None:
        """The best mean F1 of a row among the methods (references excluded)."""
        means = [self.cells[(row, c)].f1.mean for c in self.methods if (row, c) in self.cells]
        return max(means) if means else None

    def has_reported(self, column: str) -> bool:
        return any(key[1] == column for key in self.reported)

    def recognizer(self, column: str) -> str:
        config = self.configs.get(column)
        return config.recognizer if config else column


@dataclass(frozen=True)
class ArchiveEntry:
    """An archived configuration: what it was, where it ran, and its records.

    Attributes:
        config: Its :class:`~grail_bench.report.configs.Configuration` (``kind == "archived"``).
        tasks: The tasks it ran.
        seeds: The seeds of its runs.
        rows: How many stored rows (one per seed, level and protocol) it has.
        records: Its records (one per task, protocol and level).
    """

    config: Configuration
    tasks: tuple[str, ...]
    seeds: tuple[int, ...]
    rows: int
    records: tuple[OfflineRecord, ...]


def own_scorer_records(records: Sequence[OfflineRecord]) -> list[OfflineRecord]:
    """Each recognizer's records under its own (the paper's) scorer (a plugin no longer installed: all of them)."""
    own = {name: method_of(name)[1] for name in {r.recognizer for r in records}}
    return [r for r in records if own[r.recognizer] in (None, r.scorer)]


def short_name(task_id: str) -> str:
    """``GRAIL/MiniGrid-Optimal-4Goals-v0`` -> ``MiniGrid-Optimal-4Goals``."""
    name = task_id.removeprefix("GRAIL/")
    return name.rsplit("-v", 1)[0] if "-v" in name else name


def domain_of(task_id: str) -> str:
    """``GRAIL/PandaReach-Gaussian-0.1-v0`` -> ``PandaReach`` (any namespace: ``MyLab/Grid-v0`` -> ``Grid``; a
    problem set's ``symbolic:my-set`` -> ``symbolic``, its domain)."""
    kind, colon, _ = task_id.partition(":")
    if colon and "/" not in kind:
        return kind
    return task_id.split("/", 1)[-1].split("-", 1)[0]


def cell_of_record(r: OfflineRecord) -> Cell:
    """The ceiling cell a record shows: its task, the parameters its runs used, its protocol and level."""
    return Cell(r.task, TaskOverrides.of(r.task_params), r.protocol, float(r.observability))


def ceiling_cells(records: Iterable[OfflineRecord]) -> list[Cell]:
    """The cells whose Bayes ceiling a set of records shows, sorted."""
    return sorted({cell_of_record(r) for r in records}, key=lambda c: (c.task, c.params.to_json(), c.protocol,
                                                                       c.level))


class _Rows:
    """Board rows of records: the task's goal count and the reading of the runs' parameters, computed once."""

    def __init__(self, records: Iterable[OfflineRecord]) -> None:
        self.tasks = {t: find_task(t) for t in {r.task for r in records}}
        self.readings: dict[tuple[str, TaskOverrides], str] = {}

    def reading(self, r: OfflineRecord) -> str:
        """How the run's task parameters differ from the task's defaults (rows stored before a parameter
        existed read as its implicit value, so they share the row of the runs that state it)."""
        task = self.tasks[r.task]
        if task is None:
            return ""
        key = (r.task, TaskOverrides.of(r.task_params))
        if key not in self.readings:
            self.readings[key] = variant(task, r.task_params)
        return self.readings[key]

    def row(self, r: OfflineRecord) -> BoardRow:
        task = self.tasks[r.task]
        return BoardRow(len(task.goals) if task else 0, r.task, r.protocol, r.observability, self.reading(r))

    def domain(self, task_id: str) -> str:
        task = self.tasks[task_id]
        return task.domain if task else domain_of(task_id)


class _Boards:
    """Boards filled record by record: columns as configurations appear, rows with their ceilings."""

    def __init__(self, ceilings: dict[Cell, Ceiling] | None, pairs_only: dict[Cell, Ceiling] | None) -> None:
        self.boards: dict[str, Board] = {}
        self.seen: dict[str, set[BoardRow]] = defaultdict(set)
        self.ceilings, self.pairs_only = ceilings or {}, pairs_only or {}

    def add(self, title: str, kind: BoardKind, domain: str, regime: str, r: OfflineRecord, row: BoardRow,
            config: Configuration) -> Board:
        board = self.boards.get(title)
        if board is None:
            board = self.boards[title] = Board(title=title, columns=[], kind=kind, domain=domain, regime=regime)
        if config.label not in board.configs:
            board.columns.append(config.label)
            board.configs[config.label] = config
        if row not in self.seen[title]:
            self.seen[title].add(row)
            board.rows.append(row)
            key = cell_of_record(r)
            if key in self.ceilings:
                board.ceilings[row] = self.ceilings[key]
            if key in self.pairs_only:
                board.pairs_only[row] = self.pairs_only[key]
        board.cells[(row, config.label)] = r
        return board

    def done(self) -> list[Board]:
        """The boards by title, rows sorted, methods by label and references after them."""
        for board in self.boards.values():
            board.rows.sort()
            board.columns.sort(key=lambda c: (board.is_reference(c), c))
        return [self.boards[k] for k in sorted(self.boards)]


def build_boards(records: Iterable[OfflineRecord], reference: dict[tuple[str, str, float], Reported] | None = None,
                 ceilings: dict[Cell, Ceiling] | None = None, pairs_only: dict[Cell, Ceiling] | None = None,
                 configs: dict[ConfigKey, Configuration] | None = None) -> list[Board]:
    """The main boards: canonical configurations only (see the module docstring).

    Args:
        records: Offline records (:func:`grail_bench.harness.modes.offline.aggregate`).
        reference: Reported values to show beside canonical columns (on rows of the task's default protocol and
            parameters only).
        ceilings: Bayes ceilings by cell (:func:`cell_of_record`), computed beforehand.
        pairs_only: Pairs-only ceilings, keyed alike.
        configs: The records' configurations when already named (:func:`~grail_bench.report.configs.configurations`).
    """
    records = list(records)
    configs = configs if configs is not None else configurations(records)
    rows, boards = _Rows(records), _Boards(ceilings, pairs_only)
    for r in records:
        config = configs[config_key(r)]
        if not config.canonical:
            continue
        task, row = rows.tasks[r.task], rows.row(r)
        title = (f"{task.domain} / {task.regime}" if task else r.task) + f" ({r.protocol})"
        board = boards.add(title, "canonical", rows.domain(r.task), task.regime if task else "", r, row, config)
        paper_protocol = task is not None and r.protocol == task.protocol_label and not row.reading
        if reference and paper_protocol and not config.reference:
            reported = reference.get((r.task, r.recognizer, round(r.observability, 6)))
            if reported:
                board.reported[(row, config.label)] = reported
    return boards.done()


def variant_boards(records: Iterable[OfflineRecord], ceilings: dict[Cell, Ceiling] | None = None,
                   pairs_only: dict[Cell, Ceiling] | None = None,
                   configs: dict[ConfigKey, Configuration] | None = None) -> list[Board]:
    """One board per domain and method of its named variants, a column per label (no reported values beside
    them): a method's variants share their rows, so the boards stay dense."""
    records = list(records)
    configs = configs if configs is not None else configurations(records)
    rows, boards = _Rows(records), _Boards(ceilings, pairs_only)
    for r in records:
        config = configs[config_key(r)]
        if config.kind == "variant":
            domain = rows.domain(r.task)
            boards.add(f"{domain}: {config.method} variants", "variant", domain, "", r, rows.row(r), config)
    return boards.done()


def archive(records: Iterable[OfflineRecord],
            configs: dict[ConfigKey, Configuration] | None = None) -> list[ArchiveEntry]:
    """The archived configurations (one entry per stored configuration hash and scorer), by method and label."""
    records = list(records)
    configs = configs if configs is not None else configurations(records)
    groups: dict[tuple[str, str], list[OfflineRecord]] = defaultdict(list)
    for r in records:
        config = configs[config_key(r)]
        if config.kind == "archived":
            groups[(config.label, r.config_hash)].append(r)
    out = []
    for group in groups.values():
        config = configs[config_key(group[0])]
        out.append(ArchiveEntry(config, tuple(sorted({r.task for r in group})),
                                tuple(sorted({int(s) for r in group for s in r.seeds})),
                                sum(r.n_seeds for r in group), tuple(group)))
    return sorted(out, key=lambda e: (e.config.method, e.config.changes_text, e.config.label))


def placement_counts(boards: Iterable[Board]) -> dict[str, int]:
    """How many of our cells fall inside, above and below the reported 95 % intervals."""
    counts = {"inside": 0, "above": 0, "below": 0}
    for board in boards:
        for key, reported in board.reported.items():
            place = reported.place(board.cells[key].f1.mean)
            if place:
                counts[place] += 1
    return counts


def verdict_counts(boards: Iterable[Board]) -> dict[str, int]:
    """How many of our cells a two-sided Welch test finds consistent with, higher or lower than the reported."""
    counts = {"consistent": 0, "higher": 0, "lower": 0}
    for board in boards:
        for key, reported in board.reported.items():
            verdict = reported.verdict(list(board.cells[key].f1.values))
            if verdict is not None:
                counts[verdict.verdict] += 1
    return counts
