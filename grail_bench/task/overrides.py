"""Task overrides: the one shape in which "this task, with these parameters changed" travels.

A :class:`TaskOverrides` is what a user sets over a card (``gym.make(id, turn_prob=0.5)``,
``--param turn_prob=0.5``, ``task_params={...}``) and what a stored run differs from its card by
(:meth:`grail_bench.task.model.GRTask.overrides_against`). It is frozen and hashable, so units, cache keys
and report cells use it as it is; JSON appears only where it crosses a process or the store
(:meth:`TaskOverrides.to_json`, :meth:`TaskOverrides.from_json`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Iterator, Mapping

from grail_bench.core.errors import UserError


class _Table(tuple):
    """A frozen mapping: its sorted ``(key, value)`` pairs, which :func:`thaw` makes a table again."""

    __slots__ = ()


def freeze(value: Any) -> Any:
    """``value`` with every list made a tuple and every mapping a sorted tuple of pairs (hashable, comparable)."""
    if isinstance(value, Mapping):
        return _Table(sorted((str(k), freeze(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(freeze(v) for v in value)
    return value


def thaw(value: Any) -> Any:
    """The inverse of :func:`freeze`: tuples back to lists and frozen mappings back to tables (what JSON and the
    cards give)."""
    if isinstance(value, _Table):
        return {k: thaw(v) for k, v in value}
    if isinstance(value, tuple):
        return [thaw(v) for v in value]
    return value


@dataclass(frozen=True)
class TaskOverrides:
    """Task parameters set over a card: regime and env parameters, ``n_demos``, ``n_train``, ``demos``.

    Attributes:
        items: ``(name, value)`` pairs sorted by name, values frozen (:func:`freeze`).
    """

    items: tuple[tuple[str, Any], ...] = ()

    @classmethod
    def of(cls, source: TaskOverrides | Mapping[str, Any] | None = None) -> TaskOverrides:
        """Overrides from a mapping (``None``: none), or ``source`` itself.

        Raises:
            UserError: For a source that is neither, or a name that is not a string.
        """
        if isinstance(source, TaskOverrides):
            return source
        if source is None:
            return cls()
        if not isinstance(source, Mapping):
            raise UserError(f"task parameters must be a mapping of names to values, got {type(source).__name__}")
        bad = [k for k in source if not isinstance(k, str) or not k]
        if bad:
            raise UserError(f"task parameter names must be non-empty strings, got {bad[0]!r}")
        return cls(tuple(sorted((k, freeze(v)) for k, v in source.items())))

    @classmethod
    def from_json(cls, text: str) -> TaskOverrides:
        """The overrides :meth:`to_json` wrote.

        Raises:
            UserError: For text that is not a JSON object.
        """
        try:
            data = json.loads(text)
        except ValueError:
            raise UserError(f"task parameters are not JSON: {text[:80]!r}") from None
        return cls.of(data)

    def as_dict(self) -> dict[str, Any]:
        """The overrides as keyword arguments (``make_task(id, **o.as_dict())``), lists as lists."""
        return {k: thaw(v) for k, v in self.items}

    def to_json(self) -> str:
        """JSON with sorted keys: the store's and the process boundary's form."""
        return json.dumps(self.as_dict(), sort_keys=True)

    def label(self) -> str:
        """``route_choice="fixed" turn_prob=0.5``: how the overrides read on a board (empty for none)."""
        return " ".join(f"{k}={json.dumps(v)}" for k, v in self.as_dict().items())

    def __bool__(self) -> bool:
        return bool(self.items)

    def __iter__(self) -> Iterator[str]:
        return (k for k, _ in self.items)

    def __contains__(self, name: object) -> bool:
        return any(k == name for k, _ in self.items)

    def get(self, name: str, default: Any = None) -> Any:
        """The value of ``name`` (thawed), or ``default``."""
        return next((thaw(v) for k, v in self.items if k == name), default)
