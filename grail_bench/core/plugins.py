"""Entry-point plugin lookups shared by the scorer and observation-protocol registries.

Both keep their built-ins in a dict and find plugins in an entry-point group;
plugins are imported only when asked for by name.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Any, Iterable

from grail_bench.core.errors import UserError


def available(group: str, builtin: Iterable[str], kind: str) -> dict[str, str]:
    """Names and what provides them (``"built-in"`` or the entry point's target), without importing plugins.

    Raises:
        UserError: If a name is registered twice.
    """
    out = {name: "built-in" for name in builtin}
    for ep in entry_points(group=group):
        if ep.name in out:
            raise UserError(f"{kind} name {ep.name!r} is registered twice: {out[ep.name]} and {ep.value}")
        out[ep.name] = ep.value
    return out


def load(group: str, name: str) -> tuple[Any, str] | None:
    """The object a plugin registers under ``name`` and its target, or None if none does."""
    for ep in entry_points(group=group):
        if ep.name == name:
            return ep.load(), ep.value
    return None


def load_target(target: str) -> Any:
    """Import ``"package.module:attribute"`` and return the attribute."""
    module_name, _, attr = target.partition(":")
    return getattr(importlib.import_module(module_name), attr)
