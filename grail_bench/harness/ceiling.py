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
from dataclasses import asdict, dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from grail_bench.core.cache import key_digest
from grail_bench.core.errors import UserError
from grail_bench.core.paths import cache_dir
from grail_bench.domains.base import GoalModel
from grail_bench.task import GRTask, find_task
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
    """

    task: str
    protocol: str
    observability: float
    accuracy: float
    stderr: float
    chance: float
    method: str
    samples: int

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


def _monte_carlo(demonstrators: list, selection, samples: int, seed: int) -> tuple[float, float, int]:
    rng = np.random.default_rng(seed)
    per_goal = max(1, math.ceil(samples / len(demonstrators)))  # stratified: equal draws per goal
    best = []
    for d in demonstrators:
        for _ in range(per_goal):
            obs = d.sample_observation(rng, selection)
            like = np.array([other.likelihood(obs, selection) for other in demonstrators])
            best.append(like.max() / like.sum())
    values = np.asarray(best)
    stderr = float(values.std(ddof=1) / math.sqrt(len(values))) if len(values) > 1 else float("nan")
    return float(values.mean()), stderr, len(values)


def cached_ceiling(task: GRTask, label: str, level: float, *, samples: int = 2000, seed: int = 0) -> Ceiling | None:
    """:func:`bayes_ceiling` for a stored protocol label, read from or written to the on-disk cache.

    Returns:
        None where the task or protocol has no ceiling (other domains, plugin or legacy protocols).
    """
    name, rounding = parse_label(label)
    if not has_ceiling(task) or name not in BUILTIN:
        return None
    key = {"task": task.id, "regime": task.regime, "goals": [list(g) for g in task.goals],
           "params": dict(task.params), "env": dict(task.env_params), "protocol": label, "level": level,
           "samples": samples, "seed": seed, "schema": 1,
           "domain": task.domain}
    path = cache_dir() / "ceilings" / f"{key_digest(key)}.json"
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
        if stored.get("key") == json.loads(json.dumps(key)):
            return Ceiling(**stored["ceiling"])
    except (OSError, ValueError, TypeError):
        pass  # missing or unreadable: compute it again
    ceiling = bayes_ceiling(task, name, level, rounding=rounding, samples=samples, seed=seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(json.dumps({"key": key, "ceiling": ceiling.as_dict()}), encoding="utf-8")
    tmp.replace(path)
    return ceiling


def bayes_ceiling(task: GRTask, protocol: str, level: float, *, rounding: str | None = None, method: str = "auto",
                  samples: int = 2000, seed: int = 0) -> Ceiling:
    """Bayes-optimal expected accuracy of ``task`` under a protocol at one observability level.

    Args:
        task: A task whose regime has a known likelihood (see :func:`has_ceiling`).
        protocol: A built-in protocol name.
        level: Observability fraction in (0, 1].
        rounding: ``"ceil"`` or ``"floor"`` for the number of observed pairs; defaults to the task's.
        method: ``"exact"``, ``"monte-carlo"`` or ``"auto"`` (exact when it can enumerate).
        samples: Monte Carlo observations (split equally across goals).
        seed: Monte Carlo seed.

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
    if size is not None and size <= EXACT_LIMIT:
        return Ceiling(accuracy=_exact(demonstrators, selection), stderr=0.0, method="exact", samples=0, **common)
    accuracy, stderr, n = _monte_carlo(demonstrators, selection, samples, seed)
    return Ceiling(accuracy=accuracy, stderr=stderr, method="monte-carlo", samples=n, **common)


def ceilings_for(cells: Iterable[tuple[str, dict[str, Any], str, float]], samples: int = 2000,
                 on_cell: Callable[[], None] | None = None) -> dict[tuple[str, str, str, float], Ceiling]:
    """The Bayes ceiling of each ``(task, task parameters, protocol label, level)`` cell that has one.

    Returns:
        ``{(task, task parameters as sorted JSON, protocol label, level): Ceiling}``, without the cells that
        have none.
    """
    out = {}
    for task_id, params, label, level in cells:
        task = find_task(task_id, params)
        ceiling = cached_ceiling(task, label, level, samples=samples) if task is not None else None
        if ceiling is not None:
            out[(task_id, json.dumps(params, sort_keys=True), label, level)] = ceiling
        if on_cell is not None:
            on_cell()
    return out


def ceiling_curve(task: GRTask, label: str, fractions: Sequence[float], samples: int = 2000,
                  on_level: Callable[[], None] | None = None) -> list[float] | None:
    """The Bayes ceiling of an online run at each observed fraction (cached on disk).

    Online, the first ``n_observed(p, T)`` steps are what the offline prefix
    protocol of the same span observes at level ``p``, so the ceiling is that
    protocol's. ``None`` where there is none (other domains, plugin protocols).
    ``on_level`` is called after each fraction (for a progress bar).
    """
    name, rounding = parse_label(label)
    if name not in PREFIX_OF:
        return None
    curve = []
    for fraction in fractions:
        ceiling = cached_ceiling(task, protocol_label(PREFIX_OF[name], rounding), fraction, samples=samples)
        if ceiling is None:
            return None
        curve.append(ceiling.accuracy)
        if on_level is not None:
            on_level()
    return curve
