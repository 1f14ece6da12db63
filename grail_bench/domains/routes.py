"""Heading orders: how the biased regimes of the grid-like domains name each goal's preferred route.

A heading order such as ``"NE"`` ranks compass headings: of all shortest
routes, the biased demonstrator takes the one whose sequence of headings is
lexicographically first under that ranking (headings it does not name rank
after, in the order N, E, S, W).
"""

from __future__ import annotations

from typing import Any

from grail_bench.core.errors import UserError

COMPASS = "NESW"


def check_route(route: object) -> str:
    """A heading order, upper-cased.

    Raises:
        UserError: Unless it is distinct compass letters among N, E, S, W.
    """
    letters = route.upper() if isinstance(route, str) else ""
    if not letters or set(letters) - set(COMPASS) or len(set(letters)) != len(letters):
        raise UserError(f"route {route!r} must be distinct compass letters among N, E, S, W")
    return letters


def check_routes(routes: Any, n_goals: int) -> None:
    """Validate a biased regime's ``routes``: one heading order per goal.

    Raises:
        UserError: Naming what is wrong.
    """
    if not isinstance(routes, list) or len(routes) != n_goals:
        raise UserError(f"'routes' needs one heading order per goal ({n_goals}), got {routes!r}")
    for route in routes:
        check_route(route)


def ranking(route: str) -> str:
    """All four headings, best first: the route's, then the others in the order N, E, S, W."""
    order = check_route(route)
    return order + "".join(h for h in COMPASS if h not in order)
