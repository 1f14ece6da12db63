"""What every mode is made of: a stored row type, a per-seed run, an aggregation into records, and columns.

A mode (:class:`Mode`) says what one unit of a sweep measures. The sweep runs
its :attr:`Mode.run` per (task, recognizer, seed); the store keeps its rows in
a table of its own; its :attr:`Mode.aggregate` turns rows into across-seed
records; reports show those records with its :attr:`Mode.columns`. A new mode
is one module defining these and one line in :data:`grail_bench.harness.modes.MODES`.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Demos
from grail_bench.harness.planning import Fitted, Planned, dataset, recognizer_config, stored_identity, task_params
from grail_bench.stats import metrics
from grail_bench.task import GRTask
from grail_bench.task.observation import DATASET, ObservationSpec


@dataclass(frozen=True)
class Run:
    """What every stored row is about: one recognizer (its scorer and configuration) on one task and seed."""

    task: str
    recognizer: str
    scorer: str
    config_hash: str
    seed: int


@dataclass(frozen=True, kw_only=True)
class Record:
    """What every across-seed record shares: the run it aggregates and how many seeds.

    Attributes:
        task, recognizer, scorer, protocol, config_hash: What was run.
        n_seeds: Seeds aggregated; ``seeds`` lists them.
        fit_seconds_per_goal: Mean training seconds per goal.
        task_params: The regime and env parameters the runs used.
        recognizer_config: The recognizer's configuration.
        source: The submission the rows came from (``lab``, ``recognizer``, ``version``, ``url``; see
            :mod:`grail_bench.harness.submissions`); None for rows run here.
        dataset: The dataset the demonstrations came from (``run --demos``): ``demos``, its content's digest,
            and ``dataset``, its name (:func:`grail_bench.harness.planning.dataset`); empty for the generator's.
        identity: A plugin recognizer's identity as the runs recorded it (distribution, version, source hash;
            :mod:`grail_bench.recognizers.identity`); empty for grail-bench's own.
    """

    task: str
    recognizer: str
    scorer: str
    protocol: str
    config_hash: str
    n_seeds: int
    seeds: list[int]
    fit_seconds_per_goal: float
    task_params: dict[str, Any] = field(default_factory=dict)
    recognizer_config: dict[str, Any] = field(default_factory=dict)
    source: dict[str, Any] | None = None
    dataset: dict[str, str] = field(default_factory=dict)
    identity: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The record as JSON-able plain data (the ``--json`` format).

        Flat: each :class:`~grail_bench.stats.metrics.Summary` field is written in its place as fields of its
        own (:meth:`~grail_bench.stats.metrics.Summary.flat`): ``f1`` as ``f1_mean``, ``f1_std``, ``f1_ci95_low``,
        ``f1_ci95_high``, ``f1_iqm`` and ``f1_values``. ``dataset`` and ``identity`` are written only where not
        empty (runs on a dataset, a plugin's runs).
        """
        plain = asdict(self)
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("dataset", "identity") and not value:
                continue
            out |= value.flat(f.name) if isinstance(value, metrics.Summary) else {f.name: plain[f.name]}
        return out


def cells(rows: Iterable[Any], by_level: bool = True) -> list[list[Any]]:
    """Rows grouped per cell: (task, recognizer, scorer, configuration, protocol[, observability]), sorted.

    Each group is in seed order; groups are sorted by their key.
    """
    groups: dict[tuple, list[Any]] = {}
    for r in rows:
        key = (r.task, r.recognizer, r.scorer, r.config_hash, r.protocol) + ((r.observability,) if by_level else ())
        groups.setdefault(key, []).append(r)
    return [sorted(group, key=lambda r: r.seed) for _, group in sorted(groups.items())]


def record_fields(group: Sequence[Any], intervals: Sequence[str] = (), means: Sequence[str] = ()) -> dict[str, Any]:
    """The :class:`Record` fields of one cell's rows, plus ``{key}_mean`` and 95 % intervals of row metrics.

    Args:
        group: One cell's rows (see :func:`cells`).
        intervals: Row metrics summarised as mean and 95 % interval across seeds (the seeded percentile bootstrap
            of the mean, :func:`grail_bench.stats.metrics.summarize`: within the metric's bounds).
        means: Row metrics summarised as their mean only.
    """
    first = group[0]
    fields: dict[str, Any] = dict(
        task=first.task, recognizer=first.recognizer, scorer=first.scorer, protocol=first.protocol,
        config_hash=first.config_hash, n_seeds=len(group), seeds=[r.seed for r in group],
        fit_seconds_per_goal=float(np.mean([r.fit_seconds_per_goal for r in group])),
        task_params=task_params(first.config), recognizer_config=recognizer_config(first.config),
        source=json.loads(first.source) if getattr(first, "source", None) else None,
        dataset=dataset(first.config), identity=stored_identity(first.config),
    )
    if hasattr(first, "observability"):
        fields["observability"] = first.observability
    for key in intervals:
        fields |= metrics.summary_fields(key, [getattr(r, key) for r in group])
    for key in means:
        fields[f"{key}_mean"] = float(np.mean([getattr(r, key) for r in group]))
    return fields


@dataclass(frozen=True)
class Column:
    """One column of a mode's table: its header, a cell's text and the value it sorts by."""

    header: str
    text: Callable[[Any], str]
    value: Callable[[Any], Any]


def label(r: Record) -> str:
    """``recognizer/scorer``."""
    return f"{r.recognizer}/{r.scorer}"


#: What the bracketed interval of a mode's column is (its tables' intros and legends).
INTERVAL_NOTE = ("[low, high]: 95 % interval of the mean over seeds, a seeded percentile bootstrap "
                 f"({metrics.BOOTSTRAP_REPS} resamples of the seeds, seed {metrics.BOOTSTRAP_SEED}); it stays within "
                 "the seeds' values, so within the metric's bounds, and is the value itself with one seed.")


def interval(key: str, percent: bool = False) -> Callable[[Any], str]:
    """A column text: ``mean [low, high]`` of a record's metric and its 95 % interval (see :data:`INTERVAL_NOTE`)."""
    fmt = "{:.0%}" if percent else "{:.2f}"

    def text(record: Any) -> str:
        mean, low, high = (getattr(record, f"{key}_{part}") for part in ("mean", "ci95_low", "ci95_high"))
        return f"{fmt.format(mean)} [{fmt.format(low)}, {fmt.format(high)}]"

    return text


LEAD = (Column("task", lambda r: r.task.removeprefix("GRAIL/"), lambda r: r.task),
        Column("protocol", lambda r: r.protocol, lambda r: r.protocol))
WHO = (Column("recognizer/scorer", label, label), Column("seeds", lambda r: str(r.n_seeds), lambda r: r.n_seeds))


@dataclass(frozen=True)
class Outputs:
    """What one row's metrics were computed from: the per-instance arrays its mode keeps, named as the mode's
    output kind names them (:data:`grail_bench.harness.outputs.KINDS`), in the order the run computed them.

    Attributes:
        row: The row.
        arrays: Array name -> values (offline: ``y_true``, ``lengths``, ``scores``; online: ``y_true``,
            ``lengths``, ``scores`` of every prefix; open set: ``y_true``, ``scores``, ``calibration``; zero shot:
            ``y_true``, ``scores``, ``held_out``).
        posterior: Whether the scores are log-likelihoods of a posterior (offline).
    """

    row: Any
    arrays: dict[str, Any]
    posterior: bool = False


@dataclass(frozen=True)
class SeedRun:
    """Everything one unit's run needs.

    Attributes:
        task: The task (with the run's parameters).
        planned: The recognizer, as planning checked it.
        seed: The seed.
        observation: How test demonstrations are observed (protocol, rounding, levels).
        versions: JSON of the package versions, stored with each row.
        demos: The seed's demonstrations.
        outputs: Where the mode appends each row's per-instance :class:`Outputs` (None: keep none).
    """

    task: GRTask
    planned: Planned
    seed: int
    observation: ObservationSpec
    versions: str
    demos: Demos
    outputs: list[Outputs] | None = None


def check_dataset(mode: str, task: GRTask, observation: ObservationSpec) -> None:
    """Refuse, in one line, a run of the ``dataset`` protocol its task or mode cannot serve: it needs a task with
    observations of its own (its domain's ``check_dataset``: a symbolic problem set), offline, at level 1.

    Raises:
        UserError: Saying why.
    """
    check = getattr(task.spec, "check_dataset", None)
    if check is None:
        raise UserError(f"the {DATASET} protocol scores a task's own observations; {task.id} has none (a symbolic "
                        "problem set has: grail-bench run --task PATH)")
    check(task)
    if mode != "offline":
        raise UserError(f"the {DATASET} protocol scores each observation once, offline; drop --mode {mode}")
    if tuple(observation.levels) != (1.0,):
        raise UserError(f"the {DATASET} protocol observes each observation whole, at level 1; drop --observability")


@dataclass(frozen=True)
class Mode:
    """One kind of run (see the module docstring).

    Attributes:
        name: As the CLI and profiles name it (``offline``, ``online``, ``open-set``).
        row: The stored row type (a :class:`Run` subclass).
        table: The store's table of these rows.
        key: The row fields that identify a row (the table's primary key).
        run: ``run(SeedRun) -> (rows, the fitted recognizer)`` (None for a mode that fits nothing).
        aggregate: ``aggregate(rows) -> records`` across seeds.
        columns: How a table of its records is shown.
        title: A table's title.
        intro: One paragraph saying what the table shows.
        takes_levels: Whether units are scored at observability levels (online: every prefix instead).
        min_goals: Fewest candidate goals a task needs.
        held_out: Goals a unit leaves out of the fit, given the task's number of goals (open set: one).
        scores_unfitted: Whether the recognizer must score goals it was not fitted on (``set_goals``).
    """

    name: str
    row: type
    table: str
    key: tuple[str, ...]
    run: Callable[[SeedRun], tuple[list[Any], Fitted | None]]
    aggregate: Callable[[Iterable[Any]], list[Any]]
    columns: Sequence[Column]
    title: str
    intro: str
    takes_levels: bool = True
    min_goals: int = 2
    held_out: Callable[[int], int] = lambda n_goals: 0
    scores_unfitted: bool = False

    def check(self, task: GRTask, observation: ObservationSpec) -> None:
        """Refuse a task or observation this mode cannot run.

        Raises:
            UserError: In one line, saying why.
        """
        if observation.protocol == DATASET:
            check_dataset(self.name, task, observation)
        if self.takes_levels and not observation.levels:
            raise UserError(f"{self.name} runs score at observability levels; give at least one")
        if not self.takes_levels and observation.levels:
            raise UserError(f"{self.name} mode scores every prefix; it takes no observability levels")
        if len(task.goals) < self.min_goals:
            raise UserError(f"{self.name} mode holds goals out of the fit and needs at least {self.min_goals} "
                            f"candidate goals; {task.id} has {len(task.goals)}")

    def check_recognizer(self, planned: Planned) -> None:
        """Refuse a recognizer this mode cannot run.

        Raises:
            UserError: In one line, saying why.
        """
        if self.scores_unfitted and not planned.scores_unfitted:
            raise UserError(f"{self.name} mode scores goals without demonstrations; recognizer {planned.name!r} "
                            "scores only the goals it was fitted on (it has no set_goals, e.g. use gc-bc)")

    def goals_fitted(self, task: GRTask) -> int:
        """Goals one unit of this mode fits on ``task``."""
        return len(task.goals) - self.held_out(len(task.goals))
