"""Sweeps: many (task, recognizer, seed) units, run by an executor, stored by the driver.

A :class:`Unit` is one recognizer fitted on one seed of one task and scored at
every level: the finest piece of work that shares a fit, so long GAIL fits
balance across workers. Units are planned in this process (names, scorers and
configuration hashes are checked before anything runs), shipped to the
executor, and their rows come back here, where the driver alone writes them to
the store as each unit finishes. A unit whose rows are all stored is not run
again, so an interrupted sweep resumes where it stopped; rows are keyed, so
nothing is stored twice.

A request's ``mode`` says what a unit measures: ``offline`` (the paper's
protocol, :func:`~grail_bench.evaluation.runner.run_seed`), ``online`` (every
prefix, :mod:`grail_bench.evaluation.online`) or ``open-set`` (a goal held
out, :mod:`grail_bench.evaluation.open_set`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any, Mapping, Sequence

from grail_bench.errors import UserError
from grail_bench.evaluation.online import run_online_seed
from grail_bench.evaluation.open_set import held_out_goal, run_open_set_seed
from grail_bench.evaluation.protocol import get_protocol, protocol_label
from grail_bench.evaluation.runner import Planned, RecognizerSpec, plan, run_seed
from grail_bench.executors import Executor, SerialExecutor
from grail_bench.provenance import stamp
from grail_bench.store import OnlineRow, OpenSetRow, ResultRow, ResultsStore, Row, package_versions
from grail_bench.task import GRTask, make_task

#: What a unit measures -> the kind of row it stores.
MODES: dict[str, type] = {"offline": ResultRow, "online": OnlineRow, "open-set": OpenSetRow}


@dataclass(frozen=True)
class Request:
    """One task's share of a sweep: recognizers x seeds at some levels under one protocol.

    Attributes:
        task_id: A ``GRAIL/`` ID.
        specs: The recognizers (with configs and scorers).
        seeds: Seeds to run.
        levels: Observability levels.
        protocol: Observation protocol name.
        rounding: ``"ceil"`` or ``"floor"``.
        task_params: Task overrides, as ``gym.make`` takes them.
        mode: ``offline``, ``online`` (no levels: every prefix) or ``open-set``.
    """

    task_id: str
    specs: tuple[RecognizerSpec, ...]
    seeds: tuple[int, ...]
    levels: tuple[float, ...]
    protocol: str
    rounding: str = "ceil"
    task_params: Mapping[str, Any] = field(default_factory=dict)
    mode: str = "offline"

    @property
    def label(self) -> str:
        """The protocol as stored (e.g. ``prefix+floor``)."""
        return protocol_label(self.protocol, self.rounding)


@dataclass(frozen=True)
class Unit:
    """One recognizer, fitted on one seed of one task and scored at every level."""

    task_id: str
    task_params: str  # JSON, so units hash and pickle plainly
    planned: Planned
    seed: int
    levels: tuple[float, ...]
    protocol: str
    rounding: str
    goals: int
    mode: str = "offline"

    def describe(self) -> str:
        return f"{self.task_id.removeprefix('GRAIL/')} {self.planned.spec.name} seed {self.seed}"


@dataclass(frozen=True)
class UnitResult:
    """What a worker sends back: the unit's rows and how its models were obtained."""

    rows: list[Row]
    trained: int  # models trained by this unit
    reused: int  # models loaded from the cache


@dataclass
class SweepSummary:
    """Counts of a finished sweep (models: one per goal, recognizer and seed).

    Attributes:
        units: Units in the sweep.
        skipped: Units already in the store.
        rows: Rows stored by this sweep.
        trained: Models trained.
        reused: Models loaded from the model cache.
        naive: Models a sweep without the cache would train for the units run.
        seconds: Wall-clock time.
    """

    units: int = 0
    skipped: int = 0
    rows: int = 0
    trained: int = 0
    reused: int = 0
    naive: int = 0
    seconds: float = 0.0


@lru_cache(maxsize=4)
def _task(task_id: str, task_params: str) -> GRTask:
    return make_task(task_id, **json.loads(task_params))


@lru_cache(maxsize=4)
def _demos(task_id: str, task_params: str, seed: int):
    """A seed's demonstrations, generated once per process for every recognizer run on them."""
    return _task(task_id, task_params).generate_demos(seed)


def run_unit(unit: Unit) -> UnitResult:
    """Run one unit (in a worker or in this process); deterministic given the unit."""
    from grail_bench.recognizers._torch import single_thread

    task = _task(unit.task_id, unit.task_params)
    demos = _demos(unit.task_id, unit.task_params, unit.seed)
    with single_thread():  # as every worker does: the same arithmetic wherever a unit runs
        if unit.mode == "online":
            rows, report = run_online_seed(task, unit.planned, unit.seed, unit.protocol, _versions(), demos,
                                           unit.rounding)
        else:
            run = run_open_set_seed if unit.mode == "open-set" else run_seed
            rows, report = run(task, unit.planned, unit.seed, unit.levels, unit.protocol, _versions(), demos,
                               unit.rounding)
    if report is None:  # a recognizer that reports nothing trained every goal
        return UnitResult(rows, trained=unit.goals, reused=0)
    return UnitResult(rows, trained=report.trained, reused=report.reused)


@lru_cache(maxsize=1)
def _versions() -> str:
    return package_versions()


def plan_request(request: Request, store: ResultsStore) -> tuple[list[Planned], list[Unit], int]:
    """Check a request and list its units not yet in ``store``.

    Returns:
        ``(planned recognizers, units to run, units already stored)``.

    Raises:
        grail_bench.errors.UserError: For unknown names, bad parameters or scorers.
    """
    task = make_task(request.task_id, **dict(request.task_params))
    get_protocol(request.protocol)
    if request.mode not in MODES:
        raise UserError(f"unknown mode {request.mode!r}; choose one of {', '.join(MODES)}")
    if request.mode == "online" and request.levels:
        raise UserError("online mode scores every prefix; it takes no observability levels")
    if request.mode == "open-set":
        held_out_goal(task.goals, 0)  # refuses tasks with fewer than 3 goals
    levels = request.levels or (None,)  # an online row has no level
    env = task.make_env()
    action_space = env.action_space
    env.close()
    planned = [plan(task, spec, action_space) for spec in request.specs]
    params = json.dumps(dict(request.task_params), sort_keys=True)
    units, skipped = [], 0
    for p in planned:
        done = [store.completed(task.id, p.spec.name, scorer, p.config_hash, request.label, MODES[request.mode])
                for scorer in p.scorers]
        for seed in request.seeds:
            if all((seed, lv) in d for lv in levels for d in done):
                skipped += 1
                continue
            units.append(Unit(task.id, params, p, seed, tuple(request.levels), request.protocol, request.rounding,
                              len(task.goals) - (request.mode == "open-set"), request.mode))
    return planned, units, skipped


def order_units(units: Sequence[Unit]) -> list[Unit]:
    """Seed by seed, each task's recognizers together (a worker reuses the demonstrations it generated)."""
    return sorted(units, key=lambda u: (u.seed, u.task_id, u.planned.spec.name, u.mode))


def run_sweep(requests: Sequence[Request], store: ResultsStore, executor: Executor | None = None,
              progress: bool = False, description: str = "sweep") -> SweepSummary:
    """Plan every request, run the missing units on ``executor`` and store their rows.

    Every request is checked before any unit runs. Rows are stored as each
    unit finishes, so a crash, a lost worker or Ctrl-C loses only the units in
    flight; each carries the sweep's provenance (command, commit, machine, date).

    Raises:
        grail_bench.errors.UserError: For a bad request (nothing runs).
        grail_bench.executors.WorkerLost: When a worker process dies.
    """
    from rich.progress import (
        BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn,
    )

    executor = executor or SerialExecutor()
    summary = SweepSummary()
    origin = stamp()
    units: list[Unit] = []
    for request in requests:
        _, todo, skipped = plan_request(request, store)
        units += todo
        summary.skipped += skipped
    units = order_units(units)
    summary.units = len(units) + summary.skipped
    summary.naive = sum(u.goals for u in units)
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TextColumn("eta"), TimeRemainingColumn())
    start = time.perf_counter()
    with Progress(*columns, disable=not progress, transient=False) as bar:
        job = bar.add_task(f"{description} ({executor.name}, {executor.workers} worker(s))", total=len(units))
        for unit, result in executor.map_unordered(run_unit, units):
            summary.rows += store.add(replace(r, provenance=origin) for r in result.rows)
            summary.trained += result.trained
            summary.reused += result.reused
            bar.advance(job)
    summary.seconds = time.perf_counter() - start
    return summary
