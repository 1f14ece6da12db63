"""Sweeps: many (task, recognizer, seed) units, run by an executor, stored by the driver.

A :class:`Unit` is one recognizer fitted on one seed of one task and scored at
every level: the finest piece of work that shares a fit, so long GAIL fits
balance across workers. Units are planned in this process (names, scorers,
hyperparameter types, configuration hashes and output paths are checked
before anything runs), shipped to the executor, and their rows come back here,
where the driver alone writes them to the store as each unit finishes. A unit
whose rows are all stored is not run again (unless the sweep reruns: its new
rows then replace the stored ones), so an interrupted sweep resumes where it
stopped; rows are keyed, so nothing is stored twice. A plugin recognizer's
identity (:mod:`grail_bench.recognizers.identity`) is part of its
configuration's hash: a changed plugin gets new units, and the sweep says so.

A request's mode (:data:`grail_bench.harness.modes.MODES`) says what a unit
measures and which rows it stores.
"""

from __future__ import annotations

import contextlib

import json
import sys
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from itertools import groupby, zip_longest
from typing import Any, Callable, Sequence

from grail_bench.core.progress import progress as show_progress
from grail_bench.core.provenance import package_versions, stamp
from grail_bench.core.trajectory import Demos
from grail_bench.harness import diagnostics
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.executors import Executor, SerialExecutor
from grail_bench.harness.modes import SeedRun, get_mode
from grail_bench.harness.modes.base import Outputs
from grail_bench.harness.outputs import ROW_TYPES as OUTPUT_ROWS
from grail_bench.harness.outputs import output_row
from grail_bench.harness.planning import Planned, RecognizerSpec, check_channel, plan, without_identity
from grail_bench.harness.store import ResultsStore
from grail_bench.task import GRTask, make_task
from grail_bench.task.observation import DATASET, ObservationSpec
from grail_bench.task.overrides import TaskOverrides
from grail_bench.task.versions import fingerprint


@dataclass(frozen=True)
class Request:
    """One task's share of a sweep: recognizers x seeds under one observation spec and mode.

    Attributes:
        task_id: A ``GRAIL/`` ID.
        specs: The recognizers (with configs and scorers).
        seeds: Seeds to run.
        observation: Protocol, rounding and levels (online: no levels), resolved.
        overrides: Task parameters set over the card (a mapping is taken as :class:`TaskOverrides`).
        mode: ``offline``, ``online``, ``open-set`` or ``zero-shot``.
        task: The task with its overrides, built once here (given by a caller that has it already).

    Raises:
        grail_bench.core.errors.UserError: For an unknown task or an override it cannot apply.
    """

    task_id: str
    specs: tuple[RecognizerSpec, ...]
    seeds: tuple[int, ...]
    observation: ObservationSpec
    overrides: TaskOverrides = TaskOverrides()
    mode: str = "offline"
    task: GRTask | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "overrides", TaskOverrides.of(self.overrides))
        if self.task is None:
            object.__setattr__(self, "task", make_task(self.task_id, **self.overrides.as_dict()))

    def owns(self, row: Any, planned: Sequence[Planned]) -> bool:
        """Whether a stored row is one of this request's (its task, protocol, mode, recognizer and config)."""
        return (row.task == self.task_id and row.protocol == self.label and type(row) is get_mode(self.mode).row
                and any(row.recognizer == p.name and row.config_hash == p.config_hash for p in planned))

    @property
    def label(self) -> str:
        """The protocol as stored (e.g. ``prefix+floor``)."""
        return self.observation.label


@dataclass(frozen=True)
class Unit:
    """One recognizer, fitted on one seed of one task and scored at every level.

    It carries the task and the planned recognizer as the driver built them, so a worker builds neither again.
    """

    task: GRTask
    planned: Planned
    seed: int
    observation: ObservationSpec
    goals: int  # goal models the unit fits
    mode: str = "offline"

    def describe(self) -> str:
        return f"{self.task.id.removeprefix('GRAIL/')} {self.planned.name} seed {self.seed}"


@dataclass(frozen=True)
class UnitResult:
    """What a worker sends back: the unit's rows and how its models were obtained."""

    rows: list[Any]  # Row, FitRow and output rows (grail_bench.harness.outputs)
    trained: int  # models trained by this unit
    reused: int  # models loaded from the cache


@dataclass
class SweepSummary:
    """Counts of a sweep (models: one per goal, recognizer and seed), and what it planned.

    Attributes:
        planned: Per request, its recognizers as planning checked and hashed them (what identifies the
            request's stored rows: :func:`grail_bench.harness.api.collect` reads them, it does not plan again).
        units: Units in the sweep.
        skipped: Units already in the store.
        done: Units run and stored by this sweep.
        rows: Result rows stored by this sweep.
        fits: Fit diagnostics stored by this sweep (one per unit whose recognizer offers them).
        trained: Models trained.
        reused: Models loaded from the model cache.
        naive: Models a sweep without the cache would train for the units run.
        seconds: Wall-clock time.
        changed: The plugin recognizers whose version or source changed since their stored rows
            (:func:`changed`).
    """

    units: int = 0
    skipped: int = 0
    done: int = 0
    rows: int = 0
    fits: int = 0
    trained: int = 0
    reused: int = 0
    naive: int = 0
    seconds: float = 0.0
    planned: list[tuple[Request, list[Planned]]] = field(default_factory=list)
    changed: list[str] = field(default_factory=list)


class Interrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C; the units that finished are stored.

    Attributes:
        summary: The sweep's counts when it stopped (``summary.done`` units kept).
    """

    def __init__(self, summary: SweepSummary) -> None:
        super().__init__(f"interrupted; {summary.done} unit(s) of this run were kept in the store")
        self.summary = summary


@lru_cache(maxsize=4)
def _demos(task: GRTask, seed: int) -> Demos:
    """A seed's demonstrations, generated once per process for every recognizer run on them."""
    return task.generate_demos(seed)


@lru_cache(maxsize=1)
def _versions() -> str:
    return package_versions()


def run_unit(unit: Unit) -> UnitResult:
    """Run one unit (in a worker or in this process); deterministic given the unit."""
    from grail_bench.core.torchutil import single_thread  # here: planning and storing need no torch

    kept: list[Outputs] = []
    own = unit.observation.protocol == DATASET  # the task's own observations: no demonstration is generated
    job = SeedRun(task=unit.task, planned=unit.planned, seed=unit.seed, observation=unit.observation,
                  versions=_versions(), demos={} if own else _demos(unit.task, unit.seed), outputs=kept)
    with single_thread():  # as every worker does: the same arithmetic wherever a unit runs
        rows, fitted = get_mode(unit.mode).run(job)
    fp = fingerprint(unit.task)  # the task as run: its card's, or a variant's with its parameters
    rows = [replace(r, task_fingerprint=fp) if hasattr(r, "task_fingerprint") else r for r in rows]
    rows = [*rows, *(output_row(o) for o in kept)]
    if fitted is not None and fitted.diagnostics is not None:
        rows = [*rows, FitRow(unit.task.id, unit.planned.name, unit.planned.config_hash, unit.seed, unit.mode,
                              diagnostics.to_json(fitted.diagnostics))]
    report = fitted.report if fitted is not None else None
    if report is None:  # a recognizer that reports nothing trained every goal
        return UnitResult(rows, trained=unit.goals, reused=0)
    return UnitResult(rows, trained=report.trained, reused=report.reused)


def plan_request(request: Request, store: ResultsStore, rerun: bool = False,
                 add_outputs: bool = False) -> tuple[list[Planned], list[Unit], int]:
    """Check a request and list its units not yet in ``store`` (every unit with ``rerun``; with ``add_outputs``,
    also the units stored without their per-instance outputs).

    Returns:
        ``(planned recognizers, units to run, units already stored)``.

    Raises:
        grail_bench.core.errors.UserError: For unknown names, bad parameters or scorers, or a task or
            observation the mode cannot run.
    """
    task = request.task
    check_channel(request.specs, request.observation.channel)
    mode = get_mode(request.mode)
    mode.check(task, request.observation)
    action_space = task.action_space()
    planned = [plan(task, spec, action_space) for spec in request.specs]
    for p in planned:
        mode.check_recognizer(p)
    levels = request.observation.levels or (None,)  # an online row has no level
    units, skipped = [], 0
    for p in planned:
        done = [store.completed(task.id, p.name, label, p.config_hash, request.label, mode) for label in p.labels]
        if add_outputs:
            done = [d & store.with_outputs(task.id, p.name, label, p.config_hash, request.label, mode)
                    for d, label in zip(done, p.labels)]
        for seed in request.seeds:
            if not rerun and all((seed, lv) in d for lv in levels for d in done):
                skipped += 1
                continue
            units.append(Unit(task, p, seed, request.observation, mode.goals_fitted(task), mode.name))
    return planned, units, skipped


def changed(request: Request, planned: Sequence[Planned], store: ResultsStore) -> list[str]:
    """The plugin recognizers of a request whose identity (version or source) differs from that of the stored
    rows of the same configuration otherwise, and that has no rows yet: those rows stay, archived, and the units
    run again under the new one."""
    mode = get_mode(request.mode)
    out = []
    for p in planned:
        if "identity" not in json.loads(p.config):
            continue  # grail-bench's own: identified by grail-bench's version, as before
        rest = without_identity(p.config)
        stored = {(r.config_hash, r.config) for r in store.select(mode, task=request.task_id, recognizer=p.name,
                                                                   protocol=request.label)}
        if p.config_hash in {h for h, _ in stored}:
            continue  # this identity has rows already: said when they were first run
        if any(without_identity(c) == rest for _, c in stored):
            out.append(p.name)
    return out


def order_units(units: Sequence[Unit], workers: int = 1) -> list[Unit]:
    """Seed by seed, each task's recognizers together (a worker reuses the demonstrations it generated), but
    within a seed first one unit of each group that may share models: the same recognizer configuration,
    env and goals (e.g. DRACO or GRAQL on every regime of a goal set). Workers then start by training different
    models instead of waiting for each other's, and the rest of each group reuses them.

    With several workers, consecutive units also take turns among ``workers`` sets of demonstrations at a time
    (one unit of each, then the next of each), so workers that start together generate different ones: where a
    domain caches its demonstrations, a second worker asking for the same ones waits for the first.
    """
    ordered = sorted(units, key=lambda u: (u.seed, u.task.id, u.planned.name, u.mode))
    seen: set[tuple] = set()
    later = []
    for u in ordered:
        group = (u.seed, u.planned.name, json.dumps(u.planned.spec.config, sort_keys=True, default=str),
                 u.task.env_key, tuple(sorted(u.task.goals)))
        later.append(group in seen)
        seen.add(group)
    def block(pair: tuple[bool, Unit]) -> tuple[int, bool]:
        return pair[1].seed, pair[0]

    blocks = groupby(sorted(zip(later, ordered), key=block), key=block)  # a stable sort
    return [u for _, pairs in blocks for u in _take_turns([u for _, u in pairs], workers)]


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def _demos_group(task: GRTask) -> tuple:
    """What a task's demonstrations depend on besides the seed and goals: tasks alike in it (a regime's goal
    sets) share their common goals' demonstrations."""
    return (task.domain, task.regime, json.dumps(dict(task.params), sort_keys=True, default=str), task.env_key,
            task.n_demos, task.demos)


def _take_turns(units: Sequence[Unit], workers: int) -> list[Unit]:
    """``units`` grouped by demonstrations, ``workers`` groups at a time in turn (order within a group kept)."""
    groups: dict[tuple, list[Unit]] = {}
    for u in units:
        groups.setdefault(_demos_group(u.task), []).append(u)
    lists, step = list(groups.values()), max(1, workers)
    return [u for i in range(0, len(lists), step) for turn in zip_longest(*lists[i:i + step]) for u in turn
            if u is not None]


def plan_sweep(requests: Sequence[Request], store: ResultsStore, workers: int = 1,
               rerun: bool = False, add_outputs: bool = False) -> tuple[list[Unit], SweepSummary]:
    """Plan every request (all are checked before any unit runs): the units to run (``rerun``: every unit, even
    one stored; ``add_outputs``: also those stored without per-instance outputs), in order for ``workers``
    (:func:`order_units`), and the counts."""
    summary = SweepSummary()
    units: list[Unit] = []
    for request in requests:
        planned, todo, skipped = plan_request(request, store, rerun, add_outputs)
        summary.planned.append((request, planned))
        summary.changed += [name for name in changed(request, planned, store) if name not in summary.changed]
        units += todo
        summary.skipped += skipped
    summary.units = len(units) + summary.skipped
    summary.naive = sum(u.goals for u in units)
    return order_units(units, workers), summary


def changed_line(name: str) -> str:
    """What a run says, before it starts, of a plugin recognizer that changed since its stored rows."""
    return f"{name} changed since its stored rows: they are kept as archived, these units run again"


def run_sweep(requests: Sequence[Request], store: ResultsStore, executor: Executor | None = None,
              progress: bool = False, description: str = "sweep", rerun: bool = False,
              notice: Callable[[str], None] | None = None, add_outputs: bool = False) -> SweepSummary:
    """Plan every request, run the missing units on ``executor`` and store their rows; returns the counts and
    what was planned.

    Every request is checked before any unit runs. Rows are stored as each
    unit finishes, so a crash, a lost worker or Ctrl-C loses only the units in
    flight; each carries the sweep's provenance (command, commit, machine, date).

    With ``rerun``, every unit runs, stored or not, and its new rows (results,
    fit diagnostics and outputs) replace the stored ones of the same keys in one
    transaction, written only once the unit has finished: an interrupted or
    failed rerun keeps the rows it did not replace. With ``add_outputs``, the
    units stored without per-instance outputs (run before the store kept them)
    run again the same way, and the others are reused: rerun until none is left.

    Args:
        notice: Called, before any unit runs, with one line per plugin recognizer that changed since its stored
            rows (:func:`changed_line`); by default the line goes to stderr.

    Raises:
        grail_bench.core.errors.UserError: For a bad request (nothing runs).
        grail_bench.harness.executors.WorkerLost: When a worker process dies.
        Interrupted: On Ctrl-C, with the count of units kept.
    """
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    executor = executor or SerialExecutor()
    units, summary = plan_sweep(requests, store, executor.workers, rerun, add_outputs)
    replace_rows = rerun or add_outputs
    for name in summary.changed:
        (notice or _stderr)(changed_line(name))
    origin = stamp()
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TextColumn("eta"), TimeRemainingColumn())
    start = time.perf_counter()
    try:
        # On stderr, so stdout holds what a command prints alone (a bar on a terminal, lines in a log); not built
        # at all when hidden (a disabled bar still writes a line break when it stops, on some rich releases).
        bar = (show_progress(f"{description} ({executor.name}, {executor.workers} worker(s))", len(units), columns)
               if progress else None)
        with bar or contextlib.nullcontext():
            for _, result in executor.map_unordered(run_unit, units):
                stored = [r if isinstance(r, OUTPUT_ROWS) else replace(r, provenance=origin) for r in result.rows]
                if replace_rows:  # the unit's rows replace the stored ones at once
                    store.add(stored, replace=True)
                    summary.rows += sum(not isinstance(r, (FitRow, *OUTPUT_ROWS)) for r in stored)
                    summary.fits += sum(isinstance(r, FitRow) for r in stored)
                else:
                    summary.rows += store.add(r for r in stored if not isinstance(r, (FitRow, *OUTPUT_ROWS)))
                    summary.fits += store.add(r for r in stored if isinstance(r, FitRow))
                    store.add(r for r in stored if isinstance(r, OUTPUT_ROWS))
                summary.done += 1
                summary.trained += result.trained
                summary.reused += result.reused
                if bar:
                    bar.advance()
    except KeyboardInterrupt:
        summary.seconds = time.perf_counter() - start
        raise Interrupted(summary) from None
    summary.seconds = time.perf_counter() - start
    return summary
