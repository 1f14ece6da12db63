"""Lazy registry of recognizers, fed by the ``grail_bench.recognizers`` entry points.

Built-in methods are registered through the same entry-point group as third
party ones (see ``pyproject.toml``), so a plugin package adds a recognizer by
declaring::

    [project.entry-points."grail_bench.recognizers"]
    mine = "my_package.module:MyRecognizer"

Nothing is imported until a recognizer is made.
"""

from __future__ import annotations

from typing import Any, Callable

from grail_bench.core.errors import UserError
from grail_bench.core.params import check_kwargs
from grail_bench.core.registry import Registry
from grail_bench.recognizers.contract import Capabilities, Info, capabilities, info

GROUP = "grail_bench.recognizers"


class UnknownRecognizerError(UserError):
    """No recognizer is registered under the requested name."""


#: Every recognizer: the built-in ones come through the same entry-point group as third-party ones.
RECOGNIZERS: Registry[Callable[..., Any]] = Registry("recognizer", GROUP, unknown=UnknownRecognizerError)


def available_recognizers() -> dict[str, str]:
    """Registered recognizer names and what they point to (nothing is imported)."""
    return RECOGNIZERS.targets()


def register_recognizer(name: str, factory: str | Callable[..., Any]) -> None:
    """Register a recognizer in this process (entry points are the durable way).

    Args:
        name: The name users pass to ``--recognizer``.
        factory: A callable returning a recognizer, or ``"module:attribute"``.

    Raises:
        UserError: If the name is taken.
    """
    RECOGNIZERS.register(name, factory)


def unregister_recognizer(name: str) -> None:
    """Remove a recognizer registered with :func:`register_recognizer`."""
    RECOGNIZERS.unregister(name)


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
    factory = RECOGNIZERS.get(name)
    kwargs = check_kwargs(factory, dict(config or {}), f"recognizer {name!r}")
    return capabilities(factory(**kwargs), name, kwargs)


def recognizer_info(name: str) -> Info:
    """The registered recognizer's name, published name and default scorer (imports its module, builds nothing).

    Raises:
        UnknownRecognizerError: For unregistered names.
    """
    factory = RECOGNIZERS.get(name)
    return info(factory, name)
