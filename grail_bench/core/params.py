"""Keyword arguments checked against the types a callable declares, before anything is built.

A value typed on the command line (``--set bc.n_epochs=abc``) reaches a
constructor as whatever JSON made of it; :func:`check_kwargs` converts it to
the parameter's declared type (``int``, ``float``, ``bool``, ``str``, a
sequence of those, or ``X | None``) or says, in one line, which parameter
expects what. A ``float`` setting is a finite number: NaN and infinities,
which JSON lets through as ``NaN`` and ``Infinity``, are refused for every
setting alike. A parameter whose hint carries a :class:`~grail_bench.core.bounds.Range`
(``Annotated[int, Range(1, 100_000)]``) is refused outside it, naming the value
and the range. Parameters without an annotation it understands pass unchanged.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import types
import typing
from collections.abc import Sequence as AbcSequence
from typing import Any, Callable, Mapping

from grail_bench.core.bounds import ranges
from grail_bench.core.errors import UserError

_NAMES = {int: "an integer", float: "a finite number", bool: "true or false", str: "a string"}


class _Mismatch(Exception):
    """A value does not fit an annotation."""


def _convert(value: Any, annotation: Any) -> Any:
    """``value`` as ``annotation`` declares it, or :class:`_Mismatch`."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        return _convert(value, args[0])
    if origin in (typing.Union, types.UnionType):
        for option in args:
            try:
                return _convert(value, option)
            except _Mismatch:
                continue
        raise _Mismatch
    if origin is typing.Literal:
        if isinstance(value, bool) or value not in args:
            raise _Mismatch
        return value
    if annotation is type(None):
        if value is None:
            return None
        raise _Mismatch
    if annotation is bool:
        if isinstance(value, bool):
            return value
        raise _Mismatch
    if annotation is int:
        if isinstance(value, bool):
            raise _Mismatch
        if isinstance(value, int):
            return value
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            return int(value)  # 1e5 on a command line is JSON's 100000.0
        raise _Mismatch
    if annotation is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            try:
                converted = float(value)
            except OverflowError:  # an integer beyond any float
                raise _Mismatch from None
            if math.isfinite(converted):
                return converted
        raise _Mismatch
    if annotation is str:
        if isinstance(value, str):
            return value
        raise _Mismatch
    if origin in (list, tuple, AbcSequence) and args:
        if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
            raise _Mismatch
        converted = [_convert(v, args[0]) for v in value]
        return tuple(converted) if origin is tuple else converted
    return value  # an annotation this check does not read: the callable checks it itself


def _describe(annotation: Any) -> str:
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        return _describe(args[0])
    if origin in (typing.Union, types.UnionType):
        return " or ".join("null" if a is type(None) else _describe(a) for a in args)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (list, tuple, AbcSequence) and args:
        return f"a list of {_describe(args[0]).removeprefix('an ').removeprefix('a ')}s"
    return _NAMES.get(annotation, getattr(annotation, "__name__", str(annotation)))


def _declared(factory: Callable[..., Any]) -> tuple[dict[str, inspect.Parameter], dict[str, Any], bool]:
    """The keyword parameters a callable declares, their type hints, and whether it takes any keyword at all.

    A class whose ``__init__`` passes ``**kwargs`` on to its base is read through the base classes too,
    so their parameters count as declared. A class with a settings dataclass ``Config`` (the recognizers'
    convention) declares that dataclass's fields and the keyword parameters its own ``__init__`` names.
    """
    settings = getattr(factory, "Config", None) if inspect.isclass(factory) else None
    if dataclasses.is_dataclass(settings) and inspect.isclass(settings):
        params, hints, _ = _declared(settings)
        own = typing.get_type_hints(factory.__init__, include_extras=True)
        for name, param in inspect.signature(factory.__init__).parameters.items():
            if param.kind in (param.POSITIONAL_OR_KEYWORD, param.KEYWORD_ONLY) and name not in params | {"self": 0}:
                params[name] = param
                hints[name] = own.get(name, inspect.Parameter.empty)
        return params, hints, False
    targets = [c.__init__ for c in inspect.getmro(factory) if "__init__" in vars(c)] if inspect.isclass(factory) \
        else [factory]
    params: dict[str, inspect.Parameter] = {}
    hints: dict[str, Any] = {}
    for target in targets:
        try:
            signature = inspect.signature(target)
        except (TypeError, ValueError):  # no signature to read (a builtin or C callable)
            return params, hints, True
        try:
            own_hints = typing.get_type_hints(target, include_extras=True)
        except Exception:  # noqa: BLE001 - annotations that do not evaluate: leave the values to the callable
            own_hints = {}
        for name, param in signature.parameters.items():
            if param.kind in (param.POSITIONAL_OR_KEYWORD, param.KEYWORD_ONLY) and name not in params:
                params[name] = param
                hints.setdefault(name, own_hints.get(name, inspect.Parameter.empty))
        if not any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values()):
            return params, hints, False
    return params, hints, True


def check_kwargs(factory: Callable[..., Any], kwargs: Mapping[str, Any], owner: str) -> dict[str, Any]:
    """``kwargs`` checked against the parameters ``factory`` declares and converted to their declared types.

    Args:
        factory: A class or function taking the keyword arguments.
        kwargs: The values given (e.g. parsed from the command line).
        owner: Names the callable in messages (e.g. ``"recognizer 'bc'"``).

    Returns:
        The converted keyword arguments.

    Raises:
        UserError: For an unknown parameter or a value of the wrong type, naming both.
    """
    params, hints, open_ended = _declared(factory)
    unknown = [name for name in kwargs if name not in params or params[name].name == "self"]
    if unknown and not open_ended:
        known = ", ".join(n for n in params if n != "self") or "none"
        raise UserError(f"{owner}: got an unexpected keyword argument {unknown[0]!r} (known: {known})")
    out = {}
    for name, value in kwargs.items():
        annotation = hints.get(name, inspect.Parameter.empty)
        if annotation is inspect.Parameter.empty or annotation is Any:
            out[name] = value
            continue
        try:
            out[name] = _convert(value, annotation)
        except _Mismatch:
            raise UserError(f"{owner}: {name} expects {_describe(annotation)}, got {value!r}") from None
        for bound in ranges(annotation):
            bound.check(name, out[name], owner)
    return out
