"""One registry for every pluggable kind: recognizers, scorers, observation protocols, domains and modes.

A :class:`Registry` holds built-in entries (objects, or ``"module:attribute"`` targets imported on first
use), entries registered in this process, aliases, and an entry-point group through which installed packages
add their own. Listing names imports nothing; getting one imports it once and checks it. Entry points are
scanned once per ``sys.path`` (a scan reads every installed distribution's metadata, tens of milliseconds), so
a package whose folder is put on the path while a process runs is found.

A plugin never breaks what it does not provide: one that reuses the name of a built-in entry or of one of
grail-bench's own entry points is ignored with one warning line (the built-in is kept); a name two plugins
register is withheld, with one warning line, and asking for it is an error naming both; a plugin whose module
raises on import, or whose entry point names nothing, is one :class:`UserError` naming it when it is asked for,
and the other entries work.
"""

from __future__ import annotations

import importlib
import logging
import sys
from functools import lru_cache
from importlib.metadata import entry_points
from typing import Any, Callable, Generic, Iterator, TypeVar

from grail_bench.core.errors import UserError

T = TypeVar("T")

BUILT_IN = "built-in"
#: The prefix of grail-bench's own entry points' targets (the built-in recognizers and domains are declared as
#: entry points): a third-party entry point under the same name never replaces one of these.
OWN = "grail_bench."

logger = logging.getLogger(__name__)
_warned: set[str] = set()


def _warn_once(message: str) -> None:
    """One warning line per message and process (plugins are rescanned, their problems said once)."""
    if message not in _warned:
        _warned.add(message)
        logger.warning("grail-bench: %s", message)


@lru_cache(maxsize=64)
def _entry_points(group: str, path: tuple[str, ...]) -> tuple[Any, ...]:
    """The installed entry points of ``group``, scanned once per ``sys.path`` (a scan reads every installed
    distribution's metadata; a plugin put on the path is seen at the next lookup)."""
    return tuple(entry_points(group=group))


def installed_entry_points(group: str) -> tuple[Any, ...]:
    """The installed entry points of ``group`` (scanned once per ``sys.path``)."""
    return _entry_points(group, tuple(sys.path))


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

    def local_names(self) -> list[str]:
        """The names registered in this process with :meth:`register`."""
        return list(self._local)

    def _plugins(self) -> dict[str, str]:
        return dict(self._scan()[0])

    def _scan(self) -> tuple[dict[str, str], dict[str, str]]:
        """The entry points by name, and the names two third-party entry points claim (name -> message).

        An entry point reusing a built-in's name (or one of grail-bench's own entry points') is left out with one
        warning line; a name two third-party entry points claim is left out of both, with one warning line.
        """
        found: dict[str, str] = {}
        clashes: dict[str, str] = {}
        if self.group is None:
            return found, clashes
        points = _entry_points(self.group, tuple(sys.path))
        own = {ep.name: ep.value for ep in points if ep.value.startswith(OWN)}
        for ep in points:
            kept = BUILT_IN if ep.name in self._builtin else own.get(ep.name)
            if kept is not None and kept != ep.value:
                _warn_once(f"ignored the {self.kind} plugin {ep.name} = {ep.value}: {ep.name!r} is grail-bench's own "
                           f"{self.kind} ({kept}), which is kept")
                continue
            earlier = found.get(ep.name)
            if ep.name in clashes or (earlier is not None and earlier != ep.value):
                clashes[ep.name] = clashes.get(ep.name) or (f"{self.kind} name {ep.name!r} is registered twice: "
                                                            f"{earlier} and {ep.value}")
                _warn_once(f"{clashes[ep.name]}; neither is used")
                continue
            found[ep.name] = ep.value
        for name in clashes:
            found.pop(name, None)
        return found, clashes

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
        clash = self._scan()[1].get(canonical)
        if clash is not None and canonical not in entries:
            raise UserError(clash)
        if canonical not in entries:
            raise self._unknown(f"unknown {self.kind} {name!r}; available: {', '.join(self.names()) or 'none'}")
        return canonical, entries[canonical]

    def distribution(self, name: str) -> Any | None:
        """The installed distribution whose entry point provides ``name``
        (:class:`importlib.metadata.Distribution`), or None: a built-in entry, one registered in this process, or
        an entry point whose distribution is not known.

        Raises:
            UserError: As :meth:`target` does.
        """
        canonical, target = self.target(name)
        if canonical in self._local or canonical in self._builtin or not isinstance(target, str):
            return None
        for ep in _entry_points(self.group, tuple(sys.path)) if self.group else ():
            if ep.name == canonical and ep.value == target:
                return getattr(ep, "dist", None)
        return None

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
            entry = self._checked(self._load(canonical, target), target) if named \
                else self._checked(target, _describe(target))
            found = self._loaded[key] = (target, entry)
        return found[1]

    def _load(self, name: str, target: str) -> Any:
        """Import a ``"module:attribute"`` target; a plugin that fails to is one line naming it.

        Raises:
            UserError: For a module that raises on import or an attribute it lacks.
        """
        try:
            return load_target(target)
        except Exception as exc:  # noqa: BLE001 - a plugin's import may raise anything; say which and why
            why = str(exc).splitlines()[0] if str(exc) else ""
            raise UserError(f"the {self.kind} {name!r} ({target}) cannot be loaded: {type(exc).__name__}"
                            f"{': ' + why if why else ''}") from None

    def _checked(self, obj: Any, target: str) -> T:
        return self._check(obj, target) if self._check is not None else obj
