"""``evaluate``: benchmark recognizers on one task from Python (what ``grail-bench run`` calls); ``inspect_fit``."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.seeding import seed_list
from grail_bench.harness.executors import Executor
from grail_bench.harness.modes import Record, ResultRow, SeedRun, get_mode
from grail_bench.harness.planning import Planned, RecognizerSpec, check_channel
from grail_bench.harness.store import ResultsStore
from grail_bench.harness.sweep import Request, plan_request, run_sweep
from grail_bench.recognizers.contract import FitDiagnostics
from grail_bench.stats import metrics
from grail_bench.task import GRTask, make_task
from grail_bench.task.registration import remember
from grail_bench.task.datasets import check_seeds
from grail_bench.task.observation import ObservationSpec
from grail_bench.task.overrides import TaskOverrides


RecognizerLike = str | RecognizerSpec | tuple[str, Mapping[str, Any]]


def _is_recognizer(item: Any) -> bool:
    """Whether ``item`` names one recognizer: a name, a spec or a ``(name, config)`` pair."""
    pair = isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str) and isinstance(item[1], Mapping)
    return isinstance(item, (str, RecognizerSpec)) or pair


def _specs(recognizers: RecognizerLike | Sequence[RecognizerLike]) -> tuple[RecognizerSpec, ...]:
    """The recognizers asked for, as specs: one name, spec or ``(name, config)`` pair, or a sequence of them.

    Raises:
        UserError: For none, or an item that is none of those.
    """
    items = [recognizers] if _is_recognizer(recognizers) else recognizers
    if not isinstance(items, Sequence) or not items:
        raise UserError("name at least one recognizer (a name, a (name, config) pair or a RecognizerSpec)")
    bad = [item for item in items if not _is_recognizer(item)]
    if bad:
        raise UserError(f"a recognizer is a name, a (name, config) pair or a RecognizerSpec, got {bad[0]!r}")
    return tuple(RecognizerSpec.of(item) for item in items)


def request(task_id: str | GRTask, recognizers: RecognizerLike | Sequence[RecognizerLike], *,
            seeds: int | Sequence[int] = 3, observability: Iterable[float] | str | None = None,
            protocol: str | None = None, rounding: str | None = None, task_params: Mapping[str, Any] | None = None,
            mode: str = "offline", noise: float = 0.0, channel: str = "pairs") -> Request:
    """A checked :class:`~grail_bench.harness.sweep.Request` (see :func:`evaluate` for the arguments; the task is
    an ID or a :class:`~grail_bench.task.GRTask`, e.g. a problem set's).

    Raises:
        UserError: For anything :func:`evaluate` would refuse, before any work.
    """
    chosen = get_mode(mode)
    if not isinstance(task_id, (str, GRTask)):
        raise UserError(f"a task is named by its GRAIL/ ID, got {task_id!r} (or is a GRTask, e.g. a problem set's)")
    if observability is not None and not isinstance(observability, (str, Iterable)):
        raise UserError(f"observability is a list of fractions (e.g. [0.3]) or a comma-separated string, got "
                        f"{observability!r}")
    overrides = TaskOverrides.of(task_params)
    if isinstance(task_id, GRTask):
        remember(task_id)  # its ID names it in this process (its run's boards read it back)
        task = task_id.with_overrides(**overrides.as_dict()) if overrides.as_dict() else task_id
    else:
        task = make_task(task_id, **overrides.as_dict())
    if observability is not None:
        levels = observability
    else:
        levels = task.observability if chosen.takes_levels else ()
    specs = _specs(recognizers)
    observation = ObservationSpec.resolve(protocol or task.protocol, rounding or task.rounding, levels, noise=noise,
                                          channel=channel, action_space=task.action_space() if noise else None)
    check_channel(specs, observation.channel)
    seeds = tuple(seed_list(seeds))
    if task.demos:
        check_seeds(task.demos, seeds)
    return Request(task.id, specs, seeds, observation, overrides, chosen.name, task=task)


def evaluate(
    task_id: str | GRTask,
    recognizers: RecognizerLike | Sequence[RecognizerLike],
    *,
    seeds: int | Sequence[int] = 3,
    observability: Iterable[float] | str | None = None,
    protocol: str | None = None,
    rounding: str | None = None,
    store: ResultsStore | None = None,
    progress: bool = False,
    task_params: Mapping[str, Any] | None = None,
    executor: Executor | None = None,
    mode: str = "offline",
    noise: float = 0.0,
    channel: str = "pairs",
    rerun: bool = False,
) -> list[Record]:
    """Benchmark recognizers on one task.

    Seeds whose rows are already in ``store`` are skipped, so an interrupted
    run resumes where it stopped.

    Args:
        task_id: A ``GRAIL/`` ID, or a task (e.g. a problem set's:
            :func:`grail_bench.domains.symbolic.problem_set.problem_set_tasks`).
        recognizers: A name, a ``(name, config)`` pair or a :class:`RecognizerSpec` (which also selects
            scorers), or a sequence of them.
        seeds: ``n`` for seeds ``0..n-1``, or explicit seeds.
        observability: Fractions observed; defaults to the task's.
        protocol: Observation protocol; defaults to the task's (``subset`` for
            the paper's optimal and suboptimal MiniGrid tasks).
        rounding: ``"ceil"`` or ``"floor"`` (gr_libs' ``int(p * T)``) for the
            number of observed pairs; defaults to the task's (``ceil`` on every card).
        store: Where rows go; an in-memory store if ``None``.
        progress: Show a progress bar.
        task_params: Task overrides, as ``gym.make`` accepts them (e.g.
            ``{"turn_prob": 0.5}`` or ``{"n_demos": 20, "n_train": 14}``).
        executor: Where the (recognizer, seed) units run
            (:mod:`grail_bench.harness.executors`); in this process if ``None``.
        mode: ``offline`` (the protocol at each level), ``online`` (every
            prefix; no ``observability``) or ``open-set`` (one goal held out
            per seed; at least 3 goals).
        noise: Share of the observed steps made spurious, each keeping its state and showing another action
            (:mod:`grail_bench.task.observation`); it keys the rows (``subset+noise0.2``).
        channel: What a recognizer observes: ``pairs``, ``states`` or ``actions`` (``subset+states``); a
            recognizer that does not declare the channel is refused before any training.
        rerun: Run every seed even where ``store`` has its rows, replacing them (each unit's in one transaction).

    Returns:
        The across-seed records of the mode (``record.to_dict()`` is the
        ``--json`` format): offline and open set one per recognizer, scorer
        and level; online one per recognizer and scorer.

    Raises:
        UserError: For an unknown or malformed task, recognizer, setting, seed, level, protocol, noise, channel,
            mode, store or executor, before any training.
    """
    req = request(task_id, recognizers, seeds=seeds, observability=observability, protocol=protocol,
                  rounding=rounding, task_params=task_params, mode=mode, noise=noise, channel=channel)
    if store is not None and not isinstance(store, ResultsStore):
        raise UserError(f"store is a ResultsStore (e.g. ResultsStore('results.sqlite')), got {store!r}")
    if executor is not None and not callable(getattr(executor, "map_unordered", None)):
        raise UserError(f"executor is an Executor (grail_bench.harness.executors.make_executor), got {executor!r}")
    store = store if store is not None else ResultsStore(":memory:")
    summary = run_sweep([req], store, executor, progress=progress, description=f"{req.task_id} ({mode})",
                        rerun=rerun)
    return collect(req, store, summary.planned[0][1])


def collect(req: Request, store: ResultsStore, planned: Sequence[Planned]) -> list[Record]:
    """The records of a request's rows in ``store`` (and no other rows).

    Args:
        planned: The request's recognizers as its sweep planned them (``run_sweep(...).planned``).
    """
    mode = get_mode(req.mode)
    levels = req.observation.levels or (None,)
    rows = []
    for p in planned:
        rows += [r for r in store.select(mode, task=req.task_id, recognizer=p.name, scorer=list(p.labels),
                                         config_hash=p.config_hash, protocol=req.label, seed=list(req.seeds))
                 if getattr(r, "observability", None) in levels]
    return mode.aggregate(rows)


@dataclass(frozen=True)
class Inspection:
    """One fit looked at closely (``grail-bench inspect``).

    Attributes:
        task: The task (with the parameters used).
        recognizer: Its registered name.
        seed: The seed.
        diagnostics: The fit's diagnostics (None when the recognizer offers none).
        rows: The offline rows of the same fit, one per level (their ``confusion`` summed is the fit's).
    """

    task: GRTask
    recognizer: str
    seed: int
    diagnostics: FitDiagnostics | None
    rows: list[ResultRow]

    @property
    def confusion(self) -> list[list[float]]:
        """Test observations of each true goal (rows) and the goal predicted (columns), over every level."""
        return metrics.plain_matrix(np.sum([json.loads(r.confusion) for r in self.rows], axis=0))


def inspect_fit(task_id: str | GRTask, recognizer: str, seed: int = 0, config: Mapping[str, Any] | None = None,
                task_params: Mapping[str, Any] | None = None, protocol: str | None = None) -> Inspection:
    """Fit (or reload from the model cache) one recognizer on one seed of a task (an ID or a
    :class:`~grail_bench.task.GRTask`, e.g. a problem set's), score it offline at the task's
    levels, and return its diagnostics and rows; nothing is stored.

    Raises:
        UserError: For an unknown task, recognizer, hyperparameter or protocol, before any training.
    """
    if config is not None and not isinstance(config, Mapping):
        raise UserError(f"a recognizer's config is a mapping of setting names to values, got {config!r}")
    req = request(task_id, [RecognizerSpec(recognizer, dict(config or {}))], seeds=[seed], protocol=protocol,
                  task_params=task_params)
    (planned,), _, _ = plan_request(req, ResultsStore(":memory:"))
    task = req.task
    job = SeedRun(task=task, planned=planned, seed=seed, observation=req.observation, versions="{}",
                  demos=task.generate_demos(seed))
    rows, fitted = get_mode("offline").run(job)
    return Inspection(task, recognizer, seed, fitted.diagnostics, rows)
