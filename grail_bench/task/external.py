"""The tasks of cards from outside the package (or built by code): registered with gymnasium under their own IDs.

Cards are found by :mod:`grail_bench.task.sources`: those ``GRAIL_BENCH_CARDS`` lists and installed packages
ship (entry-point group ``grail_bench.cards``) by :func:`load_ambient`, which ``import grail_bench`` runs, and
those given to :func:`load_cards` (``--cards``). Their tasks take any namespace but ``GRAIL/`` (the shipped
tasks'). A broken card is skipped with one warning line naming the file and the field
(:func:`~grail_bench.task.cards.skipped_cards`); the other tasks register. An ID that is a shipped task's,
another card's or another gymnasium env's is refused in the same way: nothing is shadowed.

Code that builds tasks itself (from a dataset of problems, say) registers a card table it built with
:func:`register_card`, or tasks it built with :func:`add_tasks`.
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path
from typing import Any, Iterable

from grail_bench.core.errors import UserError
from grail_bench.task import cards
from grail_bench.task.cards import CardError
from grail_bench.task.model import GRTask
from grail_bench.task.sources import ENV_VAR, Card, entry_point_cards, env_paths, path_cards

#: The gymnasium entry point of every task ID (in :mod:`grail_bench.task.registration`).
ENTRY_POINT = "grail_bench.task.registration:make_registered_env"
#: The namespace of the shipped tasks; a card from outside the package uses its own.
RESERVED = "GRAIL/"

_external: dict[str, GRTask] = {}  # the tasks, by ID
_owner: dict[str, str] = {}  # their source, by ID
_given: dict[str, None] = {}  # the paths given to load_cards in this process (absolute), in order
_generation = 0  # changes whenever a task is added, replaced or dropped (lookups cached by it see it)


def registered() -> dict[str, GRTask]:
    """The tasks registered from outside the package, by ID."""
    return dict(_external)


def generation() -> int:
    """A number that changes whenever :func:`registered` does."""
    return _generation


def load_ambient() -> None:
    """Load the cards ``GRAIL_BENCH_CARDS`` lists and those installed packages ship (once per value of the
    variable and ``sys.path``)."""
    _ambient(os.environ.get(ENV_VAR, ""), tuple(sys.path))


def _shipped_ids() -> set[str]:
    return {task.id for task in cards.load_cards()}


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
        if task.id.startswith(RESERVED) or task.id in _shipped_ids():
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
    global _generation
    _generation += 1
    return tasks


def register_card(card: dict[str, Any], source: str, folder: Path | None = None) -> list[GRTask]:
    """Check a parsed card (a TOML file's table, or one built by code) and register its tasks.

    Args:
        card: ``domain``, optional ``description`` and ``defaults``, and ``task``, a list of task tables
            (:mod:`grail_bench.task.cards`).
        source: What defines it (a file or folder): messages name it, and it owns the IDs.
        folder: What relative ``demos`` folders are resolved against (None: the working directory).

    Raises:
        CardError: ``source: field: why``, for a wrong field or an ID :func:`add_tasks` refuses.
    """
    return add_tasks(cards.card_tasks(card, source, folder), source)


def _drop(task_id: str) -> None:
    from gymnasium.envs.registration import registry

    global _generation
    _generation += 1
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


