"""Size bounds on the values a user supplies, declared once beside each parameter and checked where values enter.

A value that sizes work (an epoch count, a grid's side, a number of samples) is bounded by a :class:`Range`
declared next to the parameter itself:

* recognizer settings and other constructor keywords, in the type hint:
  ``n_epochs: Annotated[int, Range(1, 100_000)] = 100`` (read by :func:`grail_bench.core.params.check_kwargs`,
  through which ``--set``, ``make_recognizer`` and every recognizer's constructor pass);
* a domain's regime and env parameters, in its ``bounds`` beside ``regimes`` and ``env_defaults``, and a
  task's own fields beside their defaults (checked when a :class:`~grail_bench.task.model.GRTask` is built: from
  a card, ``--param``, ``make_task(...)`` or ``gym.make(...)``);
* a command's sizes beside the function that takes them (``bayes_ceiling``'s ``samples``).

Every check runs before any work starts and fails with a :class:`~grail_bench.core.errors.UserError` naming the
parameter, the value and the allowed range. Bounds are generous: far above every published configuration, they
only stop a mistyped size from running until it is killed.
"""

from __future__ import annotations

import numbers
import types
import typing
from dataclasses import dataclass
from typing import Any, Mapping

from grail_bench.core.errors import UserError


@dataclass(frozen=True)
class Range:
    """The closed interval a number (or each number of a list) must lie in; ``None`` leaves a side open.

    Attributes:
        low: The smallest value allowed.
        high: The largest value allowed.
    """

    low: float | None = None
    high: float | None = None

    def __str__(self) -> str:
        low = "" if self.low is None else f"{self.low:,}"
        high = "" if self.high is None else f"{self.high:,}"
        return f"{low}..{high}"

    def contains(self, value: Any) -> bool:
        """Whether ``value`` lies inside (anything but a number, or a list of numbers, is left to type checks)."""
        if isinstance(value, (list, tuple)):
            return all(self.contains(v) for v in value)
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return True
        return (self.low is None or value >= self.low) and (self.high is None or value <= self.high)

    def check(self, name: str, value: Any, owner: str = "") -> None:
        """Refuse ``value`` for the parameter ``name`` when it lies outside.

        Raises:
            UserError: ``owner: name=value is out of range (allowed low..high)``.
        """
        if not self.contains(value):
            raise UserError(f"{owner + ': ' if owner else ''}{out_of_range(name, value, self)}")


def out_of_range(name: str, value: Any, bound: Range) -> str:
    """The message of a value outside its bound (without an owner)."""
    return f"{name}={value!r} is out of range (allowed {bound})"


def ranges(annotation: Any) -> list[Range]:
    """The :class:`Range` bounds a type hint carries (``Annotated[int, Range(...)]``, also inside ``X | None``)."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return [m for m in annotation.__metadata__ if isinstance(m, Range)] + ranges(typing.get_args(annotation)[0])
    if origin in (typing.Union, types.UnionType):
        return [r for option in typing.get_args(annotation) for r in ranges(option)]
    return []


def check_bounds(values: Mapping[str, Any], bounds: Mapping[str, Range], owner: str = "") -> None:
    """Check every value that has a bound.

    Raises:
        UserError: For the first value outside its bound (see :meth:`Range.check`).
    """
    for name, bound in bounds.items():
        if name in values:
            bound.check(name, values[name], owner)


def bounded_count(name: str, value: Any, high: int, owner: str = "") -> int:
    """``value`` as a count in ``1..high``: an integer (a float such as ``1e3`` with no fraction counts).

    Raises:
        UserError: For anything else, naming the parameter, the value and the range.
    """
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and Range(1, high).contains(value)
    if not ok or not float(value).is_integer():
        raise UserError(f"{owner + ': ' if owner else ''}{name} must be an integer in 1..{high:,}, got {value!r}")
    return int(value)
