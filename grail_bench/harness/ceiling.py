"""The Bayes ceiling: the best accuracy any recognizer can reach on a task.

A recognizer that knew the demonstrator exactly would answer, for each
observation ``o``, the goal with the largest posterior ``P(g | o)`` (goals are
equally likely in every task). Its expected accuracy, ``E_o[max_g P(g | o)]``,
bounds every recognizer's accuracy under that protocol and level.

* ``exact``: every demonstration and every observation of it is enumerated
  (optimal and biased demonstrators, path-span protocols and prefixes).
* ``monte-carlo``: observations are drawn as the harness draws them, and the
  posterior of each is computed exactly; the estimate comes with its
  standard error.

The *pairs-only* ceiling asks less of a recognizer's knowledge and more of its
form: each goal is scored from the observed pairs through that goal's policy
alone (GRAIL, GRAQL and DRACO all score so), with every policy the
demonstrator's own (``P(action | state)`` over the states it visits, zero
elsewhere) and the observed actions' log-probability summed; ties are broken
at random. It leaves out what the pairs say beyond their actions: how many
there are (a longer path yields more) and how likely the demonstrator is to
visit their states. Where a demonstrator is deterministic (one route per goal)
two goals whose demonstrators act alike on every observed state score alike
under any per-pair score, so no such recognizer does better.

Only regimes whose demonstrator has a known likelihood have a ceiling: a
domain lists them in ``ceiling_regimes`` and builds the per-goal model
(:class:`~grail_bench.domains.base.GoalModel`) in ``demonstrator`` (MiniGrid:
every regime; PointMaze: the noise-free ones; PandaReach: none).

Reports never compute a ceiling themselves: :func:`ceilings_for` gives every
ceiling a set of records needs, once (each level is cached on disk), and
:func:`online_ceilings` the curves of online records.
"""

from __future__ import annotations

import json
import math
import os
from collections import defaultdict
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, Hashable, Iterable, NamedTuple, Sequence

import numpy as np

from grail_bench.core.cache import key_digest
from grail_bench.core.errors import UserError
from grail_bench.core.paths import cache_dir
from grail_bench.domains.base import GoalModel
from grail_bench.harness.executors import Executor, SerialExecutor
from grail_bench.task import GRTask, find_task
from grail_bench.task.overrides import TaskOverrides
from grail_bench.task.observation import (
    BUILTIN,
    PREFIX_OF,
    ObservationProtocol,
    Selection,
    get_protocol,
    n_observed,
    parse_label,
    protocol_label,
)

METHODS = ("auto", "exact", "monte-carlo")
EXACT_LIMIT = 2_000_000  # observations enumerated at most before "auto" samples instead
CACHED_SEED = 0  # the Monte Carlo seed of every cached ceiling: its cache key records it


@dataclass(frozen=True)
class Ceiling:
    """The Bayes ceiling of a task under one protocol and level.

    Attributes:
        task: The task ID.
        protocol: The protocol as stored (``"subset"``, ``"prefix+floor"``, ...).
        observability: The level.
        accuracy: Best achievable expected accuracy.
        stderr: Standard error of a Monte Carlo estimate (0 when exact).
        chance: Accuracy of guessing, ``1 / n_goals``.
        method: ``"exact"`` or ``"monte-carlo"``.
        samples: Observations drawn (0 when exact).
        pairs_only: Whether this is the pairs-only ceiling (see the module docstring).
    """

    task: str
    protocol: str
    observability: float
    accuracy: float
    stderr: float
    chance: float
    method: str
    samples: int
    pairs_only: bool = False

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def normalised(score: float, ceiling: float, chance: float) -> float | None:
    """``(score - chance) / (ceiling - chance)``: 0 at chance, 1 at the ceiling (None if the ceiling is chance)."""
    if ceiling - chance <= 1e-12:
        return None
    return (score - chance) / (ceiling - chance)


def has_ceiling(task: GRTask) -> bool:
    """Whether the task's demonstrator has a known likelihood."""
    return task.regime in task.spec.ceiling_regimes


def _selection(protocol: str, level: float, rounding: str) -> Selection:
    chosen = get_protocol(protocol)
    if not isinstance(chosen, ObservationProtocol):
        raise UserError(f"the Bayes ceiling knows only the built-in protocols, not {chosen.name!r}")
    return Selection(horizon=chosen.span == "horizon", random_subset=chosen.random_subset, level=level,
                     rounding=rounding)


def _demonstrators(task: GRTask) -> list[GoalModel]:
    if not has_ceiling(task):
        known = ", ".join(task.spec.ceiling_regimes) or "none"
        raise UserError(f"{task.id}: the Bayes ceiling needs a demonstrator with a known likelihood; "
                        f"{task.domain} has one for these regimes: {known}")
    return [task.spec.demonstrator(task, goal) for goal in task.goals]


def _exact_size(demonstrators: list, selection) -> int | None:
    """Observations an exact enumeration visits, or None if it cannot enumerate."""
    if not all(d.enumerable for d in demonstrators):
        return None
    size = 0
    for d in demonstrators:
        for actions, _ in d.support():
            n = len(d.span(actions, selection))
            size += math.comb(n, n_observed(selection.level, n, selection.rounding)) if selection.random_subset else 1
    return size


def _exact(demonstrators: list, selection) -> float:
    joint: dict[tuple, np.ndarray] = defaultdict(lambda: np.zeros(len(demonstrators)))
    for g, d in enumerate(demonstrators):
        for actions, p_demo in d.support():
            for obs, p_obs in d.observations(actions, selection):
                joint[obs][g] += p_demo * p_obs
    total = math.fsum(float(v.max()) for v in joint.values()) / len(demonstrators)
    return min(1.0, total)  # rounding in the many small terms can push a certain answer past 1


def _monte_carlo(demonstrators: list, selection, samples: int, rng: np.random.Generator,
                 hit: Callable[[tuple, int], float]) -> tuple[float, float, int]:
    """Mean of ``hit(observation, goal index)`` over observations drawn from each goal alike, its standard
    error and the number drawn."""
    per_goal = max(1, math.ceil(samples / len(demonstrators)))  # stratified: equal draws per goal
    values = np.array([hit(d.sample_observation(rng, selection), g)
                       for g, d in enumerate(demonstrators) for _ in range(per_goal)])
    stderr = float(values.std(ddof=1) / math.sqrt(len(values))) if len(values) > 1 else float("nan")
    return float(values.mean()), stderr, len(values)


def _bayes_hit(demonstrators: list, selection) -> Callable[[tuple, int], float]:
    """The Bayes recognizer's expected accuracy on one observation: its largest posterior."""
    def hit(observation: tuple, goal: int) -> float:
        like = np.array([d.likelihood(observation, selection) for d in demonstrators])
        return float(like.max() / like.sum())
    return hit


def _policies(demonstrators: list[GoalModel], selection: Selection, samples: int,
              rng: np.random.Generator) -> list[dict[Hashable, float]]:
    """Each demonstrator as a policy over the pairs the protocol samples from: ``{pair: P(action | state)}``,
    states weighted by how often it visits them (over its support, else over ``samples`` demonstrations)."""
    whole = replace(selection, random_subset=False, level=1.0)  # a demonstration's every pair
    policies = []
    for d in demonstrators:
        visits: dict[Hashable, float] = defaultdict(float)
        if d.enumerable:
            for demonstration, p in d.support():
                for pair in d.span(demonstration, selection):
                    visits[pair] += p
        else:
            for _ in range(samples):
                for pair in d.sample_observation(rng, whole):
                    visits[pair] += 1.0
        per_state: dict[Hashable, float] = defaultdict(float)
        for pair, w in visits.items():
            per_state[pair[:-d.action_size]] += w
        policies.append({pair: w / per_state[pair[:-d.action_size]] for pair, w in visits.items()})
    return policies


def _pairs_only_hit(policies: list[dict[Hashable, float]], observation: tuple, goal: int) -> float:
    """Expected accuracy of the summed log-probability under each policy on one observation, ties at random."""
    scores = np.array([math.fsum(math.log(pi[pair]) if pair in pi else -math.inf for pair in observation)
                       for pi in policies])
    best = np.flatnonzero(scores >= scores.max() - 1e-9)  # equal policies can differ in the last bits
    return float(goal in best) / len(best)


def _pairs_only(demonstrators: list[GoalModel], selection: Selection, exact: bool, samples: int,
                seed: int) -> tuple[float, float, int]:
    rng = np.random.default_rng(seed)
    policies = _policies(demonstrators, selection, samples, rng)
    if exact:
        total = math.fsum(p_demo * p_obs * _pairs_only_hit(policies, obs, g)
                          for g, d in enumerate(demonstrators) for demonstration, p_demo in d.support()
                          for obs, p_obs in d.observations(demonstration, selection))
        return total / len(demonstrators), 0.0, 0
    return _monte_carlo(demonstrators, selection, samples, rng, partial(_pairs_only_hit, policies))


def _applies(task: GRTask | None, label: str) -> bool:
    """Whether a stored protocol label on ``task`` has a ceiling (known demonstrator, built-in protocol)."""
    return task is not None and has_ceiling(task) and parse_label(label)[0] in BUILTIN


def _cache_path(task: GRTask, label: str, level: float, samples: int,
                pairs_only: bool) -> tuple[dict[str, Any], Path]:
    """The cache key of one ceiling (computed at :data:`CACHED_SEED`) and the file it is stored in."""
    key = {"task": task.id, "regime": task.regime, "goals": [list(g) for g in task.goals],
           "params": dict(task.params), "env": dict(task.env_params), "protocol": label, "level": level,
           "samples": samples, "seed": CACHED_SEED, "schema": 1,
           "domain": task.domain} | ({"pairs_only": True} if pairs_only else {})
    return key, cache_dir() / "ceilings" / f"{key_digest(key)}.json"


def _read(key: dict[str, Any], path: Path) -> Ceiling | None:
    """The stored ceiling, or None when it is missing or unreadable (compute it again)."""
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
        if stored.get("key") == json.loads(json.dumps(key)):
            return Ceiling(**stored["ceiling"])
    except (OSError, ValueError, TypeError):
        pass
    return None


def _write(key: dict[str, Any], path: Path, ceiling: Ceiling) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(json.dumps({"key": key, "ceiling": ceiling.as_dict()}), encoding="utf-8")
    tmp.replace(path)


def bayes_ceiling(task: GRTask, protocol: str, level: float, *, rounding: str | None = None, method: str = "auto",
                  samples: int = 2000, seed: int = 0, pairs_only: bool = False) -> Ceiling:
    """Bayes-optimal expected accuracy of ``task`` under a protocol at one observability level.

    Args:
        task: A task whose regime has a known likelihood (see :func:`has_ceiling`).
        protocol: A built-in protocol name.
        level: Observability fraction in (0, 1].
        rounding: ``"ceil"`` or ``"floor"`` for the number of observed pairs; defaults to the task's.
        method: ``"exact"``, ``"monte-carlo"`` or ``"auto"`` (exact when it can enumerate).
        samples: Monte Carlo observations (split equally across goals); for the pairs-only ceiling of a
            demonstrator that cannot be enumerated, also the demonstrations its policy is estimated from.
        seed: Monte Carlo seed.
        pairs_only: The pairs-only ceiling instead (see the module docstring).

    Raises:
        UserError: For regimes without a known likelihood, plugin protocols, or ``exact`` where it
            cannot enumerate.
    """
    if method not in METHODS:
        raise UserError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if samples < 2:
        raise UserError(f"need at least 2 Monte Carlo samples, got {samples}")
    rounding = rounding or task.rounding
    selection = _selection(protocol, level, rounding)
    demonstrators = _demonstrators(task)
    size = _exact_size(demonstrators, selection) if method != "monte-carlo" else None
    if method == "exact" and (size is None or size > EXACT_LIMIT):
        raise UserError(f"{task.id}: cannot enumerate {protocol} at {level:g} exactly "
                         f"({'the demonstrator is random' if size is None else f'{size} observations'}); "
                         f"use the Monte Carlo estimate")
    common = dict(task=task.id, protocol=protocol_label(protocol, rounding), observability=level,
                  chance=1.0 / len(task.goals))
    if pairs_only:
        exact = size is not None and size <= EXACT_LIMIT
        accuracy, stderr, n = _pairs_only(demonstrators, selection, exact, samples, seed)
        return Ceiling(accuracy=accuracy, stderr=stderr, method="exact" if exact else "monte-carlo", samples=n,
                       pairs_only=True, **common)
    if size is not None and size <= EXACT_LIMIT:
        return Ceiling(accuracy=_exact(demonstrators, selection), stderr=0.0, method="exact", samples=0, **common)
    accuracy, stderr, n = _monte_carlo(demonstrators, selection, samples, np.random.default_rng(seed),
                                       _bayes_hit(demonstrators, selection))
    return Ceiling(accuracy=accuracy, stderr=stderr, method="monte-carlo", samples=n, **common)


class Cell(NamedTuple):
    """A board cell whose ceiling is asked for: a task with the parameters its runs used, a protocol and a level.

    A plain ``(task, parameters mapping, protocol label, level)`` tuple is taken too (:meth:`of`).
    """

    task: str
    params: TaskOverrides
    protocol: str
    level: float

    @classmethod
    def of(cls, cell: Sequence[Any]) -> Cell:
        """A cell from a cell or a ``(task, parameters, protocol label, level)`` tuple."""
        task, params, protocol, level = cell
        return cls(task, TaskOverrides.of(params), protocol, float(level))


def distinct_cells(cells: Iterable[Sequence[Any]]) -> list[Cell]:
    """``cells`` without repeats, in order (an offline level may also be an online fraction)."""
    return list(dict.fromkeys(Cell.of(cell) for cell in cells))


def _cell_ceiling(cell: Cell, samples: int, pairs_only: bool) -> Ceiling:
    """One cell's ceiling, computed (an executor's work item: no cache access, so any worker can run it)."""
    name, rounding = parse_label(cell.protocol)
    return bayes_ceiling(find_task(cell.task, cell.params.as_dict()), name, cell.level, rounding=rounding, samples=samples,
                         seed=CACHED_SEED, pairs_only=pairs_only)


def ceilings_for(cells: Iterable[Sequence[Any]], samples: int = 2000, on_cell: Callable[[], None] | None = None,
                 pairs_only: bool = False, executor: Executor | None = None) -> dict[Cell, Ceiling]:
    """The Bayes ceiling (or the pairs-only one) of each ``(task, task parameters, protocol label, level)`` cell
    that has one.

    Cached cells are read here; the others are computed on ``executor`` (default: in this process, in order)
    and cached by this process. ``on_cell`` is called once per distinct cell (for a progress bar).

    Returns:
        ``{Cell: Ceiling}``, without the cells that have none.
    """
    out, missing = {}, {}

    def tick() -> None:
        if on_cell is not None:
            on_cell()

    for cell in distinct_cells(cells):
        task = find_task(cell.task, cell.params.as_dict())
        if _applies(task, cell.protocol):
            key, path = _cache_path(task, cell.protocol, cell.level, samples, pairs_only)
            ceiling = _read(key, path)
            if ceiling is None:
                missing[cell] = (key, path)
                continue
            out[cell] = ceiling
        tick()
    compute = partial(_cell_ceiling, samples=samples, pairs_only=pairs_only)
    for cell, ceiling in (executor or SerialExecutor()).map_unordered(compute, list(missing)):
        key, path = missing[cell]
        _write(key, path, ceiling)
        out[cell] = ceiling
        tick()
    return out


def curve_cells(task_id: str, params: TaskOverrides | dict[str, Any], label: str,
                fractions: Sequence[float]) -> list[Cell]:
    """The cells whose Bayes ceilings make the ceiling curve of an online run (empty for plugin protocols).

    Online, the first ``n_observed(p, T)`` steps are what the offline prefix
    protocol of the same span observes at level ``p``, so the ceiling at each
    fraction is that protocol's.
    """
    name, rounding = parse_label(label)
    if name not in PREFIX_OF:
        return []
    prefix = protocol_label(PREFIX_OF[name], rounding)
    return [Cell(task_id, TaskOverrides.of(params), prefix, float(fraction)) for fraction in fractions]


def curve_of(cells: Sequence[Cell], ceilings: dict[Cell, Ceiling]) -> list[float] | None:
    """The accuracies of :func:`curve_cells`' cells in ``ceilings`` (from :func:`ceilings_for`), or None
    where any has no ceiling."""
    found = [ceilings.get(cell) for cell in cells]
    if not found or None in found:
        return None
    return [ceiling.accuracy for ceiling in found]


def ceiling_curve(task_id: str, params: dict[str, Any], label: str, fractions: Sequence[float],
                  samples: int = 2000, executor: Executor | None = None) -> list[float] | None:
    """The Bayes ceiling of an online run at each observed fraction (cached on disk; see :func:`curve_cells`).

    Returns:
        None where there is none (other domains, plugin protocols).
    """
    cells = curve_cells(task_id, params, label, fractions)
    return curve_of(cells, ceilings_for(cells, samples, executor=executor))
