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

Cards from outside the package (:mod:`grail_bench.task.sources`) register the same way, under any namespace but
``GRAIL/`` (grail-bench's own): those ``GRAIL_BENCH_CARDS`` lists and those installed packages ship (entry-point
group ``grail_bench.cards``) on ``import grail_bench``, and those given to :func:`load_cards` (``--cards``) when
it is called. A broken one is skipped with one warning line naming the file and the field
(:func:`~grail_bench.task.cards.skipped_cards`); the other tasks register. An ID that is a shipped task's,
another card's or another gymnasium env's is refused in the same way: nothing is shadowed.
"""

from __future__ import annotations

import difflib
import functools
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable

from grail_bench.core.errors import UserError
from grail_bench.task import cards
from grail_bench.task.cards import CardError, skipped_cards
from grail_bench.task.domain import stored_params
from grail_bench.task.model import ENV_ONLY, GRTask
from grail_bench.task.sources import ENV_VAR, Card, entry_point_cards, env_paths, path_cards

if TYPE_CHECKING:
    import gymnasium as gym

ENTRY_POINT = "grail_bench.task.registration:make_registered_env"
#: The namespace of the shipped tasks; a card from outside the package uses its own.
RESERVED = "GRAIL/"

_external: dict[str, GRTask] = {}  # tasks of cards from outside the package (or built by code), by ID
_owner: dict[str, str] = {}  # their source, by ID
_given: dict[str, None] = {}  # the paths given to load_cards in this process (absolute), in order


def shipped_tasks() -> dict[str, GRTask]:
    """Every task of the shipped cards, by ID (parsed once per process)."""
    return {task.id: task for task in cards.load_cards()}


def known_tasks() -> dict[str, GRTask]:
    """Every registered task, by ID: the shipped ones, then those of cards from outside the package."""
    return {**shipped_tasks(), **_external}


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
    _ambient(os.environ.get(ENV_VAR, ""), tuple(sys.path))
    return list(known_tasks().values())


@functools.lru_cache(maxsize=8)
def _ambient(env_value: str, path: tuple[str, ...]) -> None:
    """Load the cards ``GRAIL_BENCH_CARDS`` lists and those installed packages ship (once per value and path)."""
    found: list[Card | CardError] = list(entry_point_cards())
    for given in env_paths({ENV_VAR: env_value}):
        found += _cards_at(given)
    _load(found, strict=False)


def add_tasks(tasks: Iterable[GRTask], source: str) -> list[GRTask]:
    """Register tasks from outside the package's cards (a card's, or built by code) with gymnasium, all or none.

    Loading the same source again replaces its tasks (an edited card); its IDs no longer defined are dropped.

    Args:
        tasks: Validated tasks with distinct IDs, none in the ``GRAIL/`` namespace.
        source: What defines them (a card's path): messages name it, and it owns the IDs.

    Returns:
        The tasks.

    Raises:
        CardError: ``source: ...`` in one line, for an ID defined twice, in the ``GRAIL/`` namespace, defined
            by another source, or another gymnasium env's.
    """
    from gymnasium.envs.registration import register, registry

    tasks = cards.unique(tasks)
    for task in tasks:
        if task.id.startswith(RESERVED) or task.id in shipped_tasks():
            raise CardError(f"{source}: task id {task.id!r}: the {RESERVED} namespace is grail-bench's own tasks'; "
                            f"give yours its own, e.g. 'MyLab/{task.id.split('/', 1)[-1]}'")
        owner = _owner.get(task.id)
        if owner is not None and owner != source:
            raise CardError(f"{source}: task id {task.id!r} is already defined by {owner}")
        spec = registry.get(task.id)
        if owner is None and spec is not None and spec.entry_point != ENTRY_POINT:
            raise CardError(f"{source}: task id {task.id!r} is already a gymnasium env ({spec.entry_point})")
    ids = {t.id for t in tasks}
    for task_id in [i for i, o in _owner.items() if o == source and i not in ids]:
        _drop(task_id)
    for task in tasks:
        _external[task.id], _owner[task.id] = task, source
        if task.id not in registry:
            register(id=task.id, entry_point=ENTRY_POINT, kwargs={"task_id": task.id})
    _found.cache_clear()
    return tasks


def _drop(task_id: str) -> None:
    from gymnasium.envs.registration import registry

    _external.pop(task_id, None)
    _owner.pop(task_id, None)
    registry.pop(task_id, None)


def load_cards(*paths: str | os.PathLike[str], strict: bool = False) -> list[GRTask]:
    """Register the tasks of task cards from anywhere (what ``--cards PATH`` does): after it,
    ``gym.make(ID)``, :func:`make_task` and every command find them.

    Args:
        *paths: Card files (``.toml``) or folders of them (their ``*.toml`` files, in name order).
        strict: Raise for a broken card instead of skipping it.

    Returns:
        The tasks of the cards that loaded, in order.

    Raises:
        CardError: With ``strict``, ``file: field: why`` for the first broken card (otherwise it is skipped
            with one warning line and listed by :func:`~grail_bench.task.cards.skipped_cards`).
    """
    found: list[Card | CardError] = []
    for path in paths:
        found += _cards_at(path)
        _given[str(Path(path).expanduser().absolute())] = None
    return _load(found, strict)


def given_paths() -> list[str]:
    """The card paths given to :func:`load_cards` in this process (so workers it starts load them too)."""
    return list(_given)


def task_ids() -> list[str]:
    """IDs of all registered tasks (the shipped ones and those of cards found so far), sorted."""
    register_envs()
    return sorted(known_tasks())


def _cards_at(path: str | os.PathLike[str]) -> list[Card | CardError]:
    try:
        return list(path_cards(path))
    except CardError as exc:
        return [exc]


def _load(found: Iterable[Card | CardError], strict: bool) -> list[GRTask]:
    """Register each card's tasks; a broken card raises (``strict``) or is skipped with one line."""
    out: list[GRTask] = []
    for card in found:
        source = card.source if isinstance(card, Card) else str(card).split(": ", 1)[0]
        try:
            if isinstance(card, CardError):
                raise card
            out += add_tasks(card.tasks(), source)
        except Exception as exc:  # noqa: BLE001 - a card is user input: whatever it breaks, skip it and say why
            error = exc if isinstance(exc, CardError) else CardError(
                f"{source}: {exc}" if isinstance(exc, UserError) else f"{source}: {type(exc).__name__}: {exc}")
            if strict:
                raise error from None
            cards.skip(source, str(error))
            continue
        cards.unskip(source)
    return out


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
    tasks = known_tasks()
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
    return _found(task_id, key)


@functools.lru_cache(maxsize=4096)
def _found(task_id: str, params_json: str | None) -> GRTask | None:
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
