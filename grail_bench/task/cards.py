"""Task cards: the declarative TOML files that define every task, the shipped ``GRAIL/`` ones and a user's own.

A card file describes one domain and lists its tasks::

    domain = "minigrid"

    [defaults]              # optional, applied to every task below
    n_demos = 10

    [[task]]
    id = "GRAIL/MiniGrid-Biased-v0"
    regime = "biased"
    goals = [[7, 1], [7, 7]]
    params = { routes = ["NE", "ES"] }

A task's fields: ``id``, ``regime``, ``goals`` (required); ``params`` (regime
parameters), ``env`` (env parameters), ``n_demos``, ``n_train``,
``observability``, ``protocol``, ``rounding``, ``description``, and ``demos``:
a Minari dataset to take the demonstrations from instead of the generator (a
folder, relative to the card's folder, or a dataset ID; read when the task is
made, see :mod:`grail_bench.task.demos`), and ``test``: test parameters, which
change the test demonstrations only (``test = { test_slip = 0.1 }``, see
:meth:`~grail_bench.task.model.GRTask.test_task`). An env parameter that names a file (a symbolic ``problem``)
is read from beside the card too, when the file is there.

``goal_sets`` names smaller goal sets of the same task: a table ``{ name = [goal, ...], ... }``, each set
drawn from the block's ``goals`` in any order, that adds one task per entry, equal to the block's but for its
goals and its ID, which is the block's with ``-name`` inserted before the version (``GRAIL/X-Optimal-v0``
with ``goal_sets = { L1 = [...] }`` gives ``GRAIL/X-Optimal-L1-v0`` as well). A regime parameter with one
entry per goal (a list whose default is a list, such as ``routes``) follows its goals into each set. The
block's own ``goals`` keep the unsuffixed ID; the sets' tasks come after it, in the table's order. Like any
field but ``id``, ``goal_sets`` may sit in ``[defaults]``::

    [[task]]
    id = "GRAIL/MiniGrid-Biased-v0"
    regime = "biased"
    goals = [[7, 1], [7, 7], [7, 3]]         # GRAIL/MiniGrid-Biased-v0
    params = { routes = ["NE", "ES", "NE"] }
    [task.goal_sets]
    L1 = [[7, 7], [7, 1]]                    # GRAIL/MiniGrid-Biased-L1-v0, routes ["ES", "NE"]

Parsing builds :class:`~grail_bench.task.model.GRTask` objects, which validate every
field (regime parameters included, through the domain); errors read
``file: task[i].field: why``. A task ID defined twice, in one card or two, is
an error naming the file(s).

A broken card in the card folder (invalid TOML, a wrong field, a file that is not UTF-8, an ID another card
defines) never breaks ``import grail_bench`` or the other tasks: it is skipped with one warning line (the logger
``grail_bench.task.cards``) naming the file and why, and ``grail-bench tasks`` lists it
(:func:`skipped_cards`).
"""

from __future__ import annotations

import logging
import re
import tomllib
from functools import lru_cache
from importlib.resources import files
from pathlib import Path
from typing import Any, Iterable

from grail_bench.core.errors import UserError
from grail_bench.task.domain import available_domains, get_domain
from grail_bench.task.model import GRTask, TaskFieldError

logger = logging.getLogger(__name__)

#: A task ID: a namespace (``GRAIL`` for the shipped cards, any other for a user's), a name and a version.
ID_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9_.\-]*/[A-Za-z0-9][A-Za-z0-9.\-]*-v\d+$")
FILE_KEYS = {"domain", "description", "defaults", "task"}
TASK_KEYS = {
    "id", "regime", "goals", "params", "env", "n_demos", "n_train",
    "observability", "protocol", "rounding", "description", "demos", "goal_sets", "test",
}
#: A ``goal_sets`` name: what it adds to the ID (``L1`` in ``GRAIL/X-L1-v0``).
GOAL_SET_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9.]*$")
#: A Minari dataset ID (``namespace/name-v0``): a card's ``demos`` that is no folder beside the card is one.
DATASET_ID = re.compile(r"^([\w.-]+/)?[\w.-]+-v\d+$")
#: The one TOML file beside the shipped cards that is no card: what each task ID's version means
#: (:mod:`grail_bench.task.versions`).
VERSIONS_FILE = "versions.toml"
DEFAULT_FIELDS = {"n_demos": 10, "n_train": 7, "observability": [0.1, 0.2, 0.3], "protocol": "subset",
                  "rounding": "ceil"}


class CardError(UserError):
    """A task card is malformed; the message names the file and the field."""


def _fail(source: str, where: str, why: str) -> CardError:
    return CardError(f"{source}: {where}: {why}")


def _demos_source(value: Any, folder: Path | None) -> Any:
    """A card's ``demos``: a relative folder resolved against the card's folder (a dataset ID kept as it is)."""
    if not isinstance(value, str) or not value or folder is None:
        return value
    path = Path(value).expanduser()
    if path.is_absolute():
        return str(path)
    beside = folder / path
    if beside.exists() or not DATASET_ID.match(value):
        return str(beside.absolute())
    return value


def _files_beside(env: Any, domain: str, folder: Path | None) -> Any:
    """A card's env parameters, those naming a file (the domain's ``path_params``) read from beside the card
    when the file is there (an absolute path then; other values as they are)."""
    if folder is None or not isinstance(env, dict):
        return env
    try:
        names = set(getattr(get_domain(domain), "path_params", ()))
    except UserError:
        return env  # the task's own check names the domain
    return {k: str((folder / v).absolute()) if k in names and isinstance(v, str) and v and
            not Path(v).expanduser().is_absolute() and (folder / v).exists() else v for k, v in env.items()}


def goal_set_id(task_id: str, name: str) -> str:
    """The ID of goal set ``name`` of the task ``task_id`` (a valid ID): ``-name`` inserted before its version."""
    head, version = task_id.rsplit("-", 1)
    return f"{head}-{name}-{version}"


def _tasks(raw: dict[str, Any], domain: str, defaults: dict[str, Any], source: str, where: str,
           folder: Path | None) -> list[GRTask]:
    """The block's task, then one per entry of its ``goal_sets`` (see the module docstring)."""
    if not isinstance(raw, dict):
        raise _fail(source, where, f"expected a [[task]] table, got {raw!r}")
    unknown = set(raw) - TASK_KEYS
    if unknown:
        raise _fail(source, f"{where}.{sorted(unknown)[0]}", f"unknown field (known: {', '.join(sorted(TASK_KEYS))})")
    merged = {**DEFAULT_FIELDS, **defaults, **raw}
    task_id = merged.get("id")
    if not isinstance(task_id, str) or not ID_PATTERN.match(task_id):
        raise _fail(source, f"{where}.id", f"expected an ID like 'MyLab/Name-v0' (a namespace, a name, a "
                                             f"version), got {task_id!r}")
    goal_sets = merged.pop("goal_sets", None)
    base = _task(merged, domain, source, where, folder)
    if goal_sets is None:
        return [base]
    if not isinstance(goal_sets, dict) or not goal_sets:
        raise _fail(source, f"{where}.goal_sets", "expected a table of named goal lists, e.g. "
                                                  "{ L1 = [[7, 1], [7, 7]] }")
    tasks = [base]
    for name, goals in goal_sets.items():
        at = f"{where}.goal_sets.{name}"
        if not GOAL_SET_NAME.match(name):
            raise _fail(source, at, "a name is letters, digits and dots, e.g. L1")
        if not isinstance(goals, list) or not all(isinstance(g, list) and tuple(g) in base.goals for g in goals):
            raise _fail(source, at, f"expected a list among the task's goals {[list(g) for g in base.goals]}, "
                                    f"got {goals!r}")
        params = _goal_set_params(base, merged.get("params", {}), [base.goal_index(g) for g in goals])
        tasks.append(_task({**merged, "id": goal_set_id(task_id, name), "goals": goals, "params": params}, domain,
                           source, at, folder))
    return tasks


def _goal_set_params(base: GRTask, params: Any, picked: list[int]) -> Any:
    """A goal set's regime parameters: those with one entry per goal of the block (a list whose default is a
    list, such as ``routes``) cut to the set's goals, in its order; the others as they are."""
    if not isinstance(params, dict):
        return params
    defaults = base.spec.regimes[base.regime]
    return {name: [value[i] for i in picked]
            if isinstance(value, list) and isinstance(defaults.get(name), list) and len(value) == len(base.goals)
            else value for name, value in params.items()}


def _task(merged: dict[str, Any], domain: str, source: str, where: str, folder: Path | None) -> GRTask:
    task_id = merged["id"]
    try:
        return GRTask(
            id=task_id, domain=domain, regime=merged.get("regime"), goals=merged.get("goals"),
            params=merged.get("params", {}), env_params=_files_beside(merged.get("env", {}), domain, folder),
            n_demos=merged["n_demos"],
            n_train=merged["n_train"], observability=merged["observability"], protocol=merged["protocol"],
            rounding=merged["rounding"], description=merged.get("description", ""), source=source,
            demos=_demos_source(merged.get("demos", ""), folder), test_params=merged.get("test", {}),
        )
    except TaskFieldError as exc:
        raise _fail(source, f"{where}.{exc.field}", exc.why) from None


def parse_card(text: str, source: str, folder: Path | None = None) -> list[GRTask]:
    """Parse and validate one card file's text.

    Args:
        text: TOML text of the card.
        source: Name used in error messages (usually the file name).
        folder: The card's folder, which relative ``demos`` folders are resolved against (None: the working
            directory's).

    Returns:
        The tasks the card defines.

    Raises:
        CardError: If the TOML is invalid or any field is wrong.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CardError(f"{source}: invalid TOML: {exc}") from None
    return card_tasks(data, source, folder)


def card_tasks(data: dict[str, Any], source: str, folder: Path | None = None) -> list[GRTask]:
    """The validated tasks of one parsed card (a TOML file's table, or the same built by code).

    Args:
        data: The card: ``domain``, optional ``description`` and ``defaults``, and ``task``, a list of tables.
        source: Names the card in error messages and becomes each task's :attr:`~GRTask.source`.
        folder: What relative ``demos`` folders are resolved against (None: the working directory).

    Raises:
        CardError: ``source: field: why`` for the first wrong field, or a task ID defined twice.
    """
    if not isinstance(data, dict):
        raise CardError(f"{source}: expected a card table, got {type(data).__name__}")
    unknown = set(data) - FILE_KEYS
    if unknown:
        raise _fail(source, sorted(unknown)[0], f"unknown field (known: {', '.join(sorted(FILE_KEYS))})")
    domain = data.get("domain")
    if domain not in available_domains():
        raise _fail(source, "domain", f"unknown domain {domain!r} (known: {', '.join(available_domains())})")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict) or set(defaults) - (TASK_KEYS - {"id"}):
        raise _fail(source, "defaults", f"expected a table with fields among {', '.join(sorted(TASK_KEYS - {'id'}))}")
    tasks = data.get("task")
    if not isinstance(tasks, list) or not tasks:
        raise _fail(source, "task", "expected at least one [[task]] table")
    return unique(t for i, raw in enumerate(tasks) for t in _tasks(raw, domain, defaults, source, f"task[{i}]", folder))


def unique(tasks: Iterable[GRTask]) -> list[GRTask]:
    """The tasks, checked to have distinct IDs.

    Raises:
        CardError: Naming the ID and the file(s) that define it twice.
    """
    seen: dict[str, GRTask] = {}
    for task in tasks:
        if task.id in seen:
            first = seen[task.id].source
            where = f"{first}" if first == task.source else f"{first} and {task.source}"
            raise CardError(f"task id {task.id!r} is defined twice, in {where}")
        seen[task.id] = task
    return list(seen.values())


def read_card(path: Any, source: str | None = None) -> str:
    """A card file's text (UTF-8).

    Args:
        path: The file (a :class:`~pathlib.Path` or a package resource).
        source: Names it in messages (default: the path).

    Raises:
        CardError: Naming the file, for one that cannot be read or is not UTF-8 text.
    """
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise CardError(f"{source or path}: not UTF-8 text (byte {exc.start}); save the card as UTF-8") from None
    except OSError as exc:
        raise CardError(f"{source or path}: cannot be read: {exc.strerror or exc}") from None


def load_cards(paths: Iterable[Path] | None = None) -> list[GRTask]:
    """Load every shipped card (parsed once per process), or the given files, in a stable order.

    A broken shipped card is skipped (see :func:`skipped_cards`); a broken given file raises.

    Raises:
        CardError: For a given file that is not a valid card, or task IDs defined twice among them.
    """
    if paths is None:
        return list(_shipped_cards()[0])
    return unique(t for p in map(Path, paths) for t in parse_card(read_card(p), str(p), p.parent))


_skipped_external: dict[str, str] = {}


def skipped_cards() -> dict[str, str]:
    """The cards that were skipped because they are broken: file name (a shipped card) or path -> why (one
    line)."""
    return {**dict(_shipped_cards()[1]), **_skipped_external}


def skip(source: str, why: str) -> None:
    """Record a card from outside the package as skipped, with one warning line (once per source and reason)."""
    why = why.removeprefix(f"{source}: ")
    if _skipped_external.get(source) != why:
        logger.warning("grail-bench: skipped the task card %s: %s", source, why)
    _skipped_external[source] = why


def unskip(source: str) -> None:
    """Forget that ``source`` was skipped (it loaded since)."""
    _skipped_external.pop(source, None)


@lru_cache(maxsize=1)
def _shipped_cards() -> tuple[tuple[GRTask, ...], tuple[tuple[str, str], ...]]:
    """The tasks of every card in the card folder, and the cards skipped.

    One broken card (bad TOML, wrong fields, another encoding, an ID another card defines) must not break
    ``import grail_bench`` or the other tasks: it is skipped with one warning line naming the file and why.
    """
    root = files("grail_bench.tasks")
    entries = sorted((p for p in root.iterdir() if p.name.endswith(".toml") and p.name != VERSIONS_FILE),
                     key=lambda p: p.name)
    folder = root if isinstance(root, Path) else None  # a package read from an archive has no folder
    tasks: dict[str, GRTask] = {}
    skipped: dict[str, str] = {}
    for entry in entries:
        try:
            found = parse_card(read_card(entry, entry.name), entry.name, folder)
            taken = next((t for t in found if t.id in tasks), None)
            if taken is not None:
                raise CardError(f"task id {taken.id!r} is defined twice, in {tasks[taken.id].source} and "
                                f"{entry.name}")
        except Exception as exc:  # noqa: BLE001 - a card is user input: whatever it breaks, skip it and say why
            why = str(exc) if isinstance(exc, UserError) else f"{type(exc).__name__}: {exc}"
            skipped[entry.name] = why.removeprefix(f"{entry.name}: ")
            logger.warning("grail-bench: skipped the task card %s: %s", entry.name, skipped[entry.name])
            continue
        tasks.update((t.id, t) for t in found)
    return tuple(tasks.values()), tuple(skipped.items())
