"""One registry for every pluggable kind: recognizers, scorers, observation protocols, domains and modes.

A :class:`Registry` holds built-in entries (objects, or ``"module:attribute"`` targets imported on first
use), entries registered in this process, aliases, and an entry-point group through which installed packages
add their own. Listing names imports nothing; getting one imports it once and checks it. Entry points are
scanned once per ``sys.path`` (a scan reads every installed distribution's metadata, tens of milliseconds), so
a package whose folder is put on the path while a process runs is found; a name registered twice (by two
packages, or by a package and a built-in) is an error naming both.
"""

from __future__ import annotations

import importlib
import sys
from functools import lru_cache
from importlib.metadata import entry_points
from typing import Any, Callable, Generic, Iterator, TypeVar

from grail_bench.core.errors import UserError

T = TypeVar("T")

BUILT_IN = "built-in"


@lru_cache(maxsize=64)
def _entry_points(group: str, path: tuple[str, ...]) -> tuple[Any, ...]:
    """The installed entry points of ``group``, scanned once per ``sys.path`` (a scan reads every installed
    distribution's metadata; a plugin put on the path is seen at the next lookup)."""
    return tuple(entry_points(group=group))


def load_target(target: str) -> Any:
    """Import ``"package.module:attribute"`` and return the attribute."""
    module_name, _, attr = target.partition(":")
    return getattr(importlib.import_module(module_name), attr)


def _describe(target: Any) -> str:
    if isinstance(target, str):
        return target
    module, name = getattr(target, "__module__", None), getattr(target, "__qualname__", None)
    return f"{module}:{name}" if module and name else repr(target)


class Registry(Generic[T]):
    """Named entries of one kind, found by name and loaded lazily.

    Args:
        kind: What an entry is, for messages (``"recognizer"``, ``"scorer"``).
        group: The entry-point group installed packages register in (None: built-ins only).
        check: Called on each loaded entry; returns it (or raises :class:`UserError` naming the target).
        unknown: The exception type for names nothing registers (a :class:`UserError` subclass).
    """

    def __init__(self, kind: str, group: str | None = None, *, check: Callable[[Any, str], T] | None = None,
                 unknown: type[UserError] = UserError) -> None:
        self.kind, self.group = kind, group
        self._check = check
        self._unknown = unknown
        self._builtin: dict[str, Any] = {}
        self._local: dict[str, Any] = {}
        self._aliases: dict[str, str] = {}
        self._loaded: dict[tuple[str, Any], tuple[Any, T]] = {}  # checked entries by (name, target or its id)

    def add(self, name: str, target: T | str, *, aliases: tuple[str, ...] = ()) -> None:
        """Declare a built-in entry (an object, or a ``"module:attribute"`` target) and its aliases."""
        self._builtin[name] = target
        for alias in aliases:
            self._aliases[alias] = name

    def register(self, name: str, target: T | str) -> None:
        """Register an entry in this process (entry points are the durable way).

        Raises:
            UserError: If the name is taken.
        """
        if name in self.targets():
            raise UserError(f"{self.kind} name {name!r} is already registered")
        self._local[name] = target

    def unregister(self, name: str) -> None:
        """Remove an entry registered with :meth:`register` (nothing if there is none)."""
        self._local.pop(name, None)

    def _plugins(self) -> dict[str, str]:
        found: dict[str, str] = {}
        if self.group is None:
            return found
        for ep in _entry_points(self.group, tuple(sys.path)):
            earlier = found.get(ep.name) or (BUILT_IN if ep.name in self._builtin else None)
            if earlier is not None and earlier != ep.value:
                raise UserError(f"{self.kind} name {ep.name!r} is registered twice: {earlier} and {ep.value}")
            found[ep.name] = ep.value
        return found

    def _entries(self) -> dict[str, Any]:
        return {**self._builtin, **self._plugins(), **self._local}

    def targets(self) -> dict[str, str]:
        """Every name and what provides it (``"built-in"`` or ``"module:attribute"``): the built-in ones in the
        order they were added, then the others sorted; imports nothing."""
        others = self._plugins() | {name: _describe(target) for name, target in self._local.items()}
        return {**{name: BUILT_IN for name in self._builtin}, **dict(sorted(others.items()))}

    def names(self) -> list[str]:
        """Every registered name, in the order of :meth:`targets` (aliases left out)."""
        return list(self.targets())

    def canonical(self, name: str) -> str:
        """The name an alias stands for (``name`` itself otherwise)."""
        return self._aliases.get(name, name) if isinstance(name, str) else name

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self.canonical(name) in self._entries()

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self.targets())

    def __getitem__(self, name: str) -> T:
        return self.get(name)

    def items(self) -> list[tuple[str, T]]:
        """Every ``(name, entry)``, each entry imported (for small registries such as the modes)."""
        return [(name, self.get(name)) for name in self.names()]

    def values(self) -> list[T]:
        """Every entry, imported (see :meth:`items`)."""
        return [entry for _, entry in self.items()]

    def target(self, name: str) -> tuple[str, Any]:
        """``(canonical name, target)`` of a registered name, without importing it.

        Raises:
            UserError: (of the registry's ``unknown`` type) for a name nothing registers, listing the known ones.
        """
        if not isinstance(name, str):
            raise self._unknown(f"a {self.kind} is named by a string, got {name!r}")
        canonical = self.canonical(name)
        if canonical in self._builtin and canonical not in self._local:
            return canonical, self._builtin[canonical]  # no entry-point scan: built-ins are looked up per score
        entries = self._entries()
        if canonical not in entries:
            raise self._unknown(f"unknown {self.kind} {name!r}; available: {', '.join(self.names()) or 'none'}")
        return canonical, entries[canonical]

    def get(self, name: str) -> T:
        """The entry registered as ``name`` (or an alias of it), imported and checked on first use.

        Raises:
            UserError: For an unknown name, or an entry its check refuses.
        """
        canonical, target = self.target(name)
        named = isinstance(target, str)
        # an object target is checked once (describing it for messages costs more than a score), keyed by identity
        key = (canonical, target if named else id(target))
        found = self._loaded.get(key)
        if found is None or (not named and found[0] is not target):
            entry = self._checked(load_target(target), target) if named else self._checked(target, _describe(target))
            found = self._loaded[key] = (target, entry)
        return found[1]

    def _checked(self, obj: Any, target: str) -> T:
        return self._check(obj, target) if self._check is not None else obj
