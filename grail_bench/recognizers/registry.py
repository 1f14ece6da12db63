"""Lazy registry of recognizers, fed by the ``grail_bench.recognizers`` entry points.

Built-in methods are registered through the same entry-point group as third
party ones (see ``pyproject.toml``), so a plugin package adds a recognizer by
declaring::

    [project.entry-points."grail_bench.recognizers"]
    mine = "my_package.module:MyRecognizer"

Nothing is imported until a recognizer is made.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Any, Callable

from grail_bench.core.errors import UserError
from grail_bench.core.params import check_kwargs
from grail_bench.core.plugins import load_target
from grail_bench.recognizers.contract import Capabilities, Info, capabilities, info

GROUP = "grail_bench.recognizers"

_LOCAL: dict[str, str | Callable[..., Any]] = {}


class UnknownRecognizerError(UserError):
    """No recognizer is registered under the requested name."""


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


def make_recognizer(name: str, **config: Any) -> Any:
    """Return a fresh recognizer, its hyperparameters checked against the types its constructor declares.

    Args:
        name: A registered recognizer name.
        **config: Hyperparameters passed to its constructor (a value of the
            wrong type is converted where it can be, e.g. ``1e3`` to an integer).

    Raises:
        UnknownRecognizerError: For unregistered names.
        UserError: For an unknown hyperparameter or a value of the wrong type, or an object without
            ``fit`` and ``score``.
    """
    return build(name, config).recognizer


def build(name: str, config: dict[str, Any] | None = None) -> Capabilities:
    """A fresh recognizer as the harness uses it: built from checked hyperparameters, its capabilities read.

    Raises:
        The errors of :func:`make_recognizer`.
    """
    factory, _ = _factory(name)
    kwargs = check_kwargs(factory, dict(config or {}), f"recognizer {name!r}")
    return capabilities(factory(**kwargs), name, kwargs)


def _factory(name: str) -> tuple[Callable[..., Any], str]:
    targets = {**_entry_point_targets(), **_LOCAL}
    if name not in targets:
        raise UnknownRecognizerError(
            f"unknown recognizer {name!r}; available: {', '.join(sorted(targets)) or 'none'}"
        )
    target = targets[name]
    return (load_target(target), target) if isinstance(target, str) else (target, repr(target))


def recognizer_info(name: str) -> Info:
    """The registered recognizer's name, published name and default scorer (imports its module, builds nothing).

    Raises:
        UnknownRecognizerError: For unregistered names.
    """
    factory, _ = _factory(name)
    return info(factory, name)
