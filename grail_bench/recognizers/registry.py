"""Lazy registry of recognizers, fed by the ``grail_bench.recognizers`` entry points.

Built-in methods are registered through the same entry-point group as third
party ones (see ``pyproject.toml``), so a plugin package adds a recognizer by
declaring::

    [project.entry-points."grail_bench.recognizers"]
    mine = "my_package.module:MyRecognizer"

Nothing is imported until a recognizer is made.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, Callable

from grail_bench.errors import UserError
from grail_bench.plugins import load_target
from grail_bench.recognizers.base import Recognizer

GROUP = "grail_bench.recognizers"

_LOCAL: dict[str, str | Callable[..., Any]] = {}


class UnknownRecognizerError(UserError):
    """No recognizer is registered under the requested name."""


@dataclass(frozen=True)
class RecognizerInfo:
    """What a registered recognizer says of itself, read from its class without building one.

    Attributes:
        name: The registered name.
        paper_name: The method's published name (the class's ``paper_name``, else ``name``).
        default_scorer: The scorer it uses unless told otherwise (its published one).
    """

    name: str
    paper_name: str
    default_scorer: str


def _entry_point_targets() -> dict[str, str]:
    targets: dict[str, str] = {}
    for ep in entry_points(group=GROUP):
        if ep.name in targets and targets[ep.name] != ep.value:
            raise UserError(
                f"recognizer name {ep.name!r} is registered twice: {targets[ep.name]} and {ep.value}"
            )
        targets[ep.name] = ep.value
    return targets


def available_recognizers() -> dict[str, str]:
    """Registered recognizer names and what they point to (nothing is imported)."""
    targets = _entry_point_targets()
    for name, target in _LOCAL.items():
        targets[name] = target if isinstance(target, str) else f"{target.__module__}:{target.__qualname__}"
    return dict(sorted(targets.items()))


def register_recognizer(name: str, factory: str | Callable[..., Any]) -> None:
    """Register a recognizer in this process (entry points are the durable way).

    Args:
        name: The name users pass to ``--recognizer``.
        factory: A callable returning a recognizer, or ``"module:attribute"``.

    Raises:
        UserError: If the name is taken.
    """
    if name in _LOCAL or name in _entry_point_targets():
        raise UserError(f"recognizer name {name!r} is already registered")
    _LOCAL[name] = factory


def unregister_recognizer(name: str) -> None:
    """Remove a recognizer registered with :func:`register_recognizer`."""
    _LOCAL.pop(name, None)


def make_recognizer(name: str, **config: Any) -> Recognizer:
    """Return a fresh recognizer.

    Args:
        name: A registered recognizer name.
        **config: Hyperparameters passed to its constructor.

    Raises:
        UnknownRecognizerError: For unregistered names.
        UserError: If the object made does not satisfy :class:`Recognizer`.
    """
    factory, target = _factory(name)
    try:
        inspect.signature(factory).bind(**config)
    except TypeError as exc:
        raise UserError(f"recognizer {name!r}: {exc}") from None
    except ValueError:  # no signature to check (a builtin or C callable)
        pass
    recognizer = factory(**config)
    if not isinstance(recognizer, Recognizer):
        missing = [m for m in ("name", "config", "default_scorer", "exposes", "fit", "score")
                   if not hasattr(recognizer, m)]
        raise UserError(f"recognizer {name!r} ({target}) does not satisfy the Recognizer protocol: it lacks "
                        f"{', '.join(missing)}")
    return recognizer


def _factory(name: str) -> tuple[Callable[..., Any], str]:
    targets = {**_entry_point_targets(), **_LOCAL}
    if name not in targets:
        raise UnknownRecognizerError(
            f"unknown recognizer {name!r}; available: {', '.join(sorted(targets)) or 'none'}"
        )
    target = targets[name]
    return (load_target(target), target) if isinstance(target, str) else (target, repr(target))


def recognizer_info(name: str) -> RecognizerInfo:
    """The registered recognizer's metadata (imports its module, builds nothing).

    Raises:
        UnknownRecognizerError: For unregistered names.
    """
    factory, _ = _factory(name)
    return RecognizerInfo(name=name, paper_name=getattr(factory, "paper_name", "") or name,
                          default_scorer=getattr(factory, "default_scorer", "default"))
