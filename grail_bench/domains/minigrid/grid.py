"""The MiniGrid room in pure Python: actions, headings, dynamics and the regimes' parameters.

Nothing here imports minigrid, so task cards are validated without it.
Directions follow minigrid: 0 = east, 1 = south, 2 = west, 3 = north; ``y``
grows southwards.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from grail_bench.core.errors import UserError
from grail_bench.domains.routes import check_routes

LEFT, RIGHT, FORWARD, STAY = 0, 1, 2, 3
ACTION_NAMES = ("left", "right", "forward", "stay")
DIR_VEC = ((1, 0), (0, 1), (-1, 0), (0, -1))
HEADINGS = "ESWN"  # compass letter of each minigrid direction

State = tuple[int, int, int]


@dataclass(frozen=True)
class GridModel:
    """Pure-Python dynamics of the room, used for planning demonstrations.

    It mirrors :class:`GRMiniGridEnv` exactly (a test checks every state and
    action against the env).
    """

    size: int
    obstacles: frozenset[tuple[int, int]]

    def free(self, x: int, y: int) -> bool:
        """Whether a cell is inside the outer wall and not an obstacle."""
        return 0 < x < self.size - 1 and 0 < y < self.size - 1 and (x, y) not in self.obstacles

    def states(self) -> list[State]:
        """Every state the agent can be in."""
        return [(x, y, d) for x in range(self.size) for y in range(self.size) for d in range(4) if self.free(x, y)]

    def step(self, state: State, action: int) -> State:
        """Successor of ``state`` under ``action`` (ignoring goal absorption)."""
        x, y, d = state
        if action == LEFT:
            return x, y, (d - 1) % 4
        if action == RIGHT:
            return x, y, (d + 1) % 4
        if action == FORWARD:
            dx, dy = DIR_VEC[d]
            return (x + dx, y + dy, d) if self.free(x + dx, y + dy) else state
        return state


TURNS = (LEFT, RIGHT)
# Each pattern's insertions, drawn uniformly; every one leaves the heading unchanged.
TURN_PATTERNS: dict[str, tuple[tuple[int, ...], ...]] = {
    "left-right": ((LEFT, RIGHT), (RIGHT, LEFT)),
    "around-and-back": tuple((a, a, b, b) for a in TURNS for b in TURNS),
}


#: How the optimal and suboptimal demonstrators pick a shortest path: ``fixed`` (one per goal, straight ahead
#: first) or ``uniform`` (drawn anew for every demonstration among all of them).
ROUTE_CHOICES = ("fixed", "uniform")


def check_params(regime: str, params: Mapping[str, Any], n_goals: int) -> None:
    """Validate a MiniGrid regime's parameters.

    Raises:
        UserError: With the parameter's name and what is wrong.
    """
    if "route_choice" in params and params["route_choice"] not in ROUTE_CHOICES:
        raise UserError(f"route_choice must be one of {', '.join(ROUTE_CHOICES)}, got {params['route_choice']!r}")
    if regime == "biased":
        check_routes(params["routes"], n_goals)
    elif regime == "suboptimal":
        p = params["turn_prob"]
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0.0 <= p <= 1.0:
            raise UserError(f"turn_prob must be in [0, 1], got {p!r}")
        if params["turn_pattern"] not in TURN_PATTERNS:
            raise UserError(f"turn_pattern must be one of {', '.join(TURN_PATTERNS)}, got {params['turn_pattern']!r}")
