"""Task cards: the declarative TOML files that define every GRAIL/ task.

A card file describes one domain and lists its tasks::

    domain = "minigrid"

    [defaults]              # optional, applied to every task below
    n_demos = 10

    [[task]]
    id = "GRAIL/MiniGrid-Biased-v0"
    regime = "biased"
    goals = [[7, 1], [7, 7]]
    params = { routes = ["NE", "ES"] }

Parsing validates every field and reports errors as ``file: task[i].field: why``.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from functools import lru_cache
from importlib.resources import files
from pathlib import Path
from typing import Any, Iterable

from grail_bench.domains import DOMAINS

ID_PATTERN = re.compile(r"^GRAIL/[A-Za-z0-9][A-Za-z0-9.\-]*-v\d+$")
FILE_KEYS = {"domain", "description", "defaults", "task"}
TASK_KEYS = {
    "id", "regime", "goals", "params", "env", "n_demos", "n_train",
    "observability", "protocol", "description",
}
DEFAULT_FIELDS = {"n_demos": 10, "n_train": 7, "observability": [0.1, 0.2, 0.3], "protocol": "subset"}


class CardError(ValueError):
    """A task card is malformed; the message names the file and the field."""


@dataclass(frozen=True)
class TaskCard:
    """One validated task definition, JSON-serialisable through :meth:`kwargs`."""

    id: str
    domain: str
    regime: str
    goals: tuple[tuple[float, ...], ...]
    params: dict[str, Any]
    env: dict[str, Any]
    n_demos: int
    n_train: int
    observability: tuple[float, ...]
    protocol: str
    description: str
    source: str

    def kwargs(self) -> dict[str, Any]:
        """The JSON-only keyword arguments registered with gymnasium."""
        return {
            "task_id": self.id,
            "domain": self.domain,
            "regime": self.regime,
            "goals": [list(g) for g in self.goals],
            "params": dict(self.params),
            "env": dict(self.env),
            "n_demos": self.n_demos,
            "n_train": self.n_train,
            "observability": list(self.observability),
            "protocol": self.protocol,
            "description": self.description,
        }


def _fail(source: str, where: str, why: str) -> CardError:
    return CardError(f"{source}: {where}: {why}")


def _known_protocol(name: str) -> bool:
    """Built in, or registered by a plugin (entry points are read only for unknown names)."""
    from grail_bench.evaluation.protocol import BUILTIN, available_protocols

    return name in BUILTIN or name in available_protocols()


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _validate_task(raw: dict[str, Any], domain: str, defaults: dict[str, Any],
                   source: str, where: str) -> TaskCard:
    spec = DOMAINS[domain]
    unknown = set(raw) - TASK_KEYS
    if unknown:
        raise _fail(source, f"{where}.{sorted(unknown)[0]}", f"unknown field (known: {', '.join(sorted(TASK_KEYS))})")
    merged = {**DEFAULT_FIELDS, **defaults, **raw}

    task_id = merged.get("id")
    if not isinstance(task_id, str) or not ID_PATTERN.match(task_id):
        raise _fail(source, f"{where}.id", f"expected an ID like 'GRAIL/Name-v0', got {task_id!r}")
    regime = merged.get("regime")
    if regime not in spec.regimes:
        raise _fail(source, f"{where}.regime", f"unknown regime {regime!r} for domain {domain!r} (known: {', '.join(spec.regimes)})")

    goals = merged.get("goals")
    if not isinstance(goals, list) or len(goals) < 2:
        raise _fail(source, f"{where}.goals", "expected a list of at least two goals")
    for g in goals:
        if not isinstance(g, list) or len(g) != spec.goal_dim or not all(_number(c) for c in g):
            raise _fail(source, f"{where}.goals", f"each goal must be a list of {spec.goal_dim} numbers, got {g!r}")
    goal_tuples = tuple(tuple(g) for g in goals)
    if len(set(goal_tuples)) != len(goal_tuples):
        raise _fail(source, f"{where}.goals", "goals must be distinct")

    params = merged.get("params", {})
    env = merged.get("env", {})
    for name, value, allowed in (("params", params, spec.regimes[regime]), ("env", env, spec.env_defaults)):
        if not isinstance(value, dict):
            raise _fail(source, f"{where}.{name}", "expected a table")
        extra = set(value) - set(allowed)
        if extra:
            raise _fail(source, f"{where}.{name}.{sorted(extra)[0]}", f"unknown parameter (known: {', '.join(allowed) or 'none'})")

    n_demos, n_train = merged["n_demos"], merged["n_train"]
    for name, value in (("n_demos", n_demos), ("n_train", n_train)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise _fail(source, f"{where}.{name}", f"expected a positive integer, got {value!r}")
    if n_train >= n_demos:
        raise _fail(source, f"{where}.n_train", f"must be smaller than n_demos ({n_demos}) to leave test demonstrations")

    obs = merged["observability"]
    if not isinstance(obs, list) or not obs or not all(_number(p) and 0 < p <= 1 for p in obs):
        raise _fail(source, f"{where}.observability", "expected a non-empty list of fractions in (0, 1]")
    protocol = merged["protocol"]
    if not isinstance(protocol, str) or not _known_protocol(protocol):
        raise _fail(source, f"{where}.protocol", f"unknown observation protocol {protocol!r}")
    description = merged.get("description", "")
    if not isinstance(description, str):
        raise _fail(source, f"{where}.description", "expected a string")

    return TaskCard(
        id=task_id, domain=domain, regime=regime, goals=goal_tuples,
        params={**spec.regimes[regime], **params}, env={**spec.env_defaults, **env},
        n_demos=n_demos, n_train=n_train, observability=tuple(float(p) for p in obs),
        protocol=protocol, description=description, source=source,
    )


def parse_card(text: str, source: str) -> list[TaskCard]:
    """Parse and validate one card file's text.

    Args:
        text: TOML text of the card.
        source: Name used in error messages (usually the file name).

    Returns:
        The tasks the card defines.

    Raises:
        CardError: If the TOML is invalid or any field is wrong.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CardError(f"{source}: invalid TOML: {exc}") from None
    unknown = set(data) - FILE_KEYS
    if unknown:
        raise _fail(source, sorted(unknown)[0], f"unknown field (known: {', '.join(sorted(FILE_KEYS))})")
    domain = data.get("domain")
    if domain not in DOMAINS:
        raise _fail(source, "domain", f"unknown domain {domain!r} (known: {', '.join(sorted(DOMAINS))})")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict) or set(defaults) - (TASK_KEYS - {"id"}):
        raise _fail(source, "defaults", f"expected a table with fields among {', '.join(sorted(TASK_KEYS - {'id'}))}")
    tasks = data.get("task")
    if not isinstance(tasks, list) or not tasks:
        raise _fail(source, "task", "expected at least one [[task]] table")
    cards = [_validate_task(raw, domain, defaults, source, f"task[{i}]") for i, raw in enumerate(tasks)]
    ids = [c.id for c in cards]
    dupes = {i for i in ids if ids.count(i) > 1}
    if dupes:
        raise _fail(source, "task", f"duplicate id {sorted(dupes)[0]!r}")
    return cards


def load_cards(paths: Iterable[Path] | None = None) -> list[TaskCard]:
    """Load every shipped card (parsed once per process), or the given files, in a stable order."""
    if paths is None:
        return list(_shipped_cards())
    cards: list[TaskCard] = []
    for p in paths:
        cards.extend(parse_card(Path(p).read_text(encoding="utf-8"), str(p)))
    return cards


@lru_cache(maxsize=1)
def _shipped_cards() -> tuple[TaskCard, ...]:
    root = files("grail_bench.tasks")
    entries = sorted((p for p in root.iterdir() if p.name.endswith(".toml")), key=lambda p: p.name)
    return tuple(card for p in entries for card in parse_card(p.read_text(encoding="utf-8"), p.name))
