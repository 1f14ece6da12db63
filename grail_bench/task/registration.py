"""The one place that registers tasks with gymnasium, and looks them up by ID: the shipped ``GRAIL/`` cards and
a user's own.

Registration runs on ``import grail_bench``, which is what each of
gymnasium 1.x's ways to reach a third-party env does:
``gym.make("grail_bench:GRAIL/...")`` imports the package first,
``gym.register_envs(grail_bench)`` names it, and an ``import grail_bench``
anywhere before ``gym.make("GRAIL/...")`` does the same. Gymnasium 1.x loads
no plugins on ``import gymnasium``, so a bare ``gym.make("GRAIL/...")`` with no
import of ``grail_bench`` finds no ``GRAIL`` namespace. Registration is
idempotent and imports nothing heavier than the task cards.

Cards from outside the package register the same way, under namespaces of their own
(:mod:`grail_bench.task.external`): those ``GRAIL_BENCH_CARDS`` lists and installed packages ship on ``import
grail_bench``, those given to :func:`~grail_bench.task.external.load_cards` (``--cards``) when it is called.
"""

from __future__ import annotations

import difflib
import functools
import json
from typing import TYPE_CHECKING, Any

from grail_bench.core.errors import UserError
from grail_bench.task import cards, external
from grail_bench.task.cards import skipped_cards
from grail_bench.task.domain import stored_params
from grail_bench.task.external import ENTRY_POINT, RESERVED, add_tasks, given_paths, load_cards
from grail_bench.task.model import ENV_ONLY, GRTask

if TYPE_CHECKING:
    import gymnasium as gym

__all__ = ["ENTRY_POINT", "add_tasks", "find_task", "given_paths", "known_tasks", "load_cards", "make_registered_env",
           "make_task", "register_envs", "shipped_tasks", "task_ids", "variant"]


def shipped_tasks() -> dict[str, GRTask]:
    """Every task of the shipped cards, by ID (parsed once per process)."""
    return {task.id: task for task in cards.load_cards()}


def known_tasks() -> dict[str, GRTask]:
    """Every registered task, by ID: the shipped ones, then those of cards from outside the package."""
    return {**shipped_tasks(), **external.registered()}


#: Tasks built in this process outside the cards (a symbolic problem set's), by ID: see :func:`remember`.
_remembered: dict[str, GRTask] = {}


def remember(task: GRTask) -> None:
    """Make a task built outside the cards (a problem set's, ``symbolic:<name>``) known by its ID in this process,
    to :func:`make_task` and :func:`find_task` (so the boards of the run that built it name its configurations).
    A card's ID is never taken over: the card's task stays what the ID means.
    """
    if task.id not in known_tasks():
        _remembered[task.id] = task
        _found.cache_clear()


def register_envs() -> list[GRTask]:
    """Register every task card's ID with gymnasium (skipping existing ones): the shipped cards, then those
    ``GRAIL_BENCH_CARDS`` lists and installed packages ship.

    Returns:
        The tasks, registered or already present.
    """
    # Imported here: `import grail_bench` imports gymnasium through this function only.
    from gymnasium.envs.registration import register, registry

    for task in cards.load_cards():
        if task.id not in registry:
            register(id=task.id, entry_point=ENTRY_POINT, kwargs={"task_id": task.id})
    external.load_ambient()
    return list(known_tasks().values())


def task_ids() -> list[str]:
    """IDs of all registered tasks (the shipped ones and those of cards found so far), sorted."""
    register_envs()
    return sorted(known_tasks())


def make_registered_env(task_id: str, **kwargs: Any) -> gym.Env:
    """Gymnasium entry point of every task ID.

    ``render_mode`` and ``goal`` shape the env; every other keyword overrides a task parameter.
    """
    env_only = {k: kwargs.pop(k) for k in ENV_ONLY if k in kwargs}
    task = known_tasks()[task_id].with_overrides(**kwargs)
    return task.make_env(env_only.pop("goal", None), **env_only)


def make_task(task_id: str, **overrides: Any) -> GRTask:
    """Return the :class:`GRTask` of a registered ID without building an env.

    A card's ``demos`` dataset is read here (its counts set ``n_train`` and ``n_demos``) unless ``demos`` is
    overridden.

    Args:
        task_id: A registered task ID (``GRAIL/...`` or a card's own).
        **overrides: Regime or env parameters, ``n_demos``, ``n_train`` or ``demos``.

    Raises:
        UserError: For an ID that is no registered task (close IDs suggested), or an override it cannot apply.
    """
    tasks = {**_remembered, **known_tasks()}
    card = tasks.get(task_id) if isinstance(task_id, str) else None
    if card is None:
        raise UserError(_unknown(task_id, list(tasks)))
    if card.demos and "demos" not in overrides:
        overrides = {"demos": card.demos, **overrides}
    return card.with_overrides(**overrides)


def _unknown(task_id: Any, known: list[str]) -> str:
    """One line saying ``task_id`` is no registered task, with the closest IDs when there are some."""
    from gymnasium.envs.registration import registry

    if not isinstance(task_id, str):
        return f"a task ID is a string like 'GRAIL/MiniGrid-Biased-v0', got {task_id!r}"
    if task_id in registry:
        return f"{task_id} is a gymnasium env but not a grail-bench task"
    close = difflib.get_close_matches(task_id, known, n=3, cutoff=0.6)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    skipped = skipped_cards()
    broken = f"; the broken task card(s) {', '.join(skipped)} were skipped" if skipped else ""
    own = ("; a task of your own is found through its card: --cards PATH, GRAIL_BENCH_CARDS or "
           "grail_bench.load_cards(PATH)") if not close and not task_id.startswith(RESERVED) else ""
    return f"unknown task {task_id!r}{hint} (`grail-bench tasks` lists them){broken}{own}"


def find_task(task_id: str, params: dict[str, Any] | None = None) -> GRTask | None:
    """The registered task with the parameters a stored run used (parameters added since the run filled in as
    its domain declares, see :func:`~grail_bench.task.domain.stored_params`), or None when its card is gone (or
    no longer accepts those parameters): reports of old stores show such rows without the task's details.

    Built once per process for each ID and parameters (reports ask for the same few thousands of times)."""
    try:
        key = json.dumps(params, sort_keys=True, default=str) if params is not None else None
    except (TypeError, ValueError):
        return _find_task(task_id, params)
    return _found(task_id, key, external.generation())


@functools.lru_cache(maxsize=4096)
def _found(task_id: str, params_json: str | None, generation: int) -> GRTask | None:
    """The task, cached until the tasks of cards from outside the package change (``generation``)."""
    return _find_task(task_id, json.loads(params_json) if params_json is not None else None)


def _find_task(task_id: str, params: dict[str, Any] | None) -> GRTask | None:
    try:
        task = make_task(task_id)
        if params is None:
            return task
        settable = set(task.settings()) - {"demos"}
        return task.with_overrides(**{k: v for k, v in stored_params(task.spec, params).items() if k in settable})
    except UserError:
        return None


def variant(task: GRTask, params: dict[str, Any]) -> str:
    """How a stored run's parameters differ from the task's defaults, e.g. ``route_choice="uniform"`` (empty when
    they do not)."""
    run = find_task(task.id, params)
    return run.overrides_against(task).label() if run is not None else ""
