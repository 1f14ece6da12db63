"""The MiniGrid room in pure Python: actions, headings, dynamics and the regimes' parameters.

Nothing here imports minigrid, so task cards are validated without it.
Directions follow minigrid: 0 = east, 1 = south, 2 = west, 3 = north; ``y``
grows southwards.

Obstacles are minigrid's two kinds: a wall ``[x, y]`` blocks the cell, lava
``[x, y, "lava"]`` can be entered and ends the episode there (the agent is
absorbed in it, never reaching the goal). The demonstrators never enter lava:
its states cannot reach the goal, so no shortest path passes through them.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from grail_bench.core.errors import UserError
from grail_bench.domains.boltzmann import check_beta
from grail_bench.domains.routes import check_routes

LEFT, RIGHT, FORWARD, STAY = 0, 1, 2, 3
ACTION_NAMES = ("left", "right", "forward", "stay")
DIR_VEC = ((1, 0), (0, 1), (-1, 0), (0, -1))
HEADINGS = "ESWN"  # compass letter of each minigrid direction

State = tuple[int, int, int]
Cell = tuple[int, int]
LAVA = "lava"  # the obstacle kind of a lava cell, ``[x, y, "lava"]``


@dataclass(frozen=True)
class GridModel:
    """Pure-Python dynamics of the room, used for planning demonstrations.

    It mirrors :class:`GRMiniGridEnv` exactly (a test checks every state and
    action against the env).
    """

    size: int
    obstacles: frozenset[Cell]
    lava: frozenset[Cell] = frozenset()

    @classmethod
    def of(cls, size: int, obstacles: Sequence[Sequence[Any]]) -> GridModel:
        """The model of a ``size`` x ``size`` room with obstacles as the env takes them (see module docstring)."""
        walls, lava = split_obstacles(obstacles)
        return cls(int(size), walls, lava)

    def free(self, x: int, y: int) -> bool:
        """Whether the agent can enter a cell: inside the outer wall and not a wall (lava can be entered)."""
        return 0 < x < self.size - 1 and 0 < y < self.size - 1 and (x, y) not in self.obstacles

    def safe(self, x: int, y: int) -> bool:
        """Whether a cell can be entered and left: free and not lava (starts and goals lie on safe cells)."""
        return self.free(x, y) and (x, y) not in self.lava

    def states(self) -> list[State]:
        """Every state the agent can be in."""
        return [(x, y, d) for x in range(self.size) for y in range(self.size) for d in range(4) if self.free(x, y)]

    def step(self, state: State, action: int) -> State:
        """Successor of ``state`` under ``action`` (ignoring goal absorption)."""
        x, y, d = state
        if (x, y) in self.lava:
            return state  # the episode ended in the lava
        if action == LEFT:
            return x, y, (d - 1) % 4
        if action == RIGHT:
            return x, y, (d + 1) % 4
        if action == FORWARD:
            dx, dy = DIR_VEC[d]
            return (x + dx, y + dy, d) if self.free(x + dx, y + dy) else state
        return state

    def transition(self, state: State, action: int, slip: float = 0.0) -> dict[State, float]:
        """The successors of ``state`` under ``action`` with their probabilities when each step executes, with
        probability ``slip``, one of the three other actions drawn uniformly (as the env with ``slip`` does)."""
        out = {self.step(state, action): 1.0 - slip}
        for other in range(len(ACTION_NAMES)):
            if other != action:
                nxt = self.step(state, other)
                out[nxt] = out.get(nxt, 0.0) + slip / (len(ACTION_NAMES) - 1)
        return {s: p for s, p in out.items() if p > 0.0}


def split_obstacles(obstacles: Sequence[Sequence[Any]]) -> tuple[frozenset[Cell], frozenset[Cell]]:
    """Wall cells and lava cells of an ``obstacles`` list (``[x, y]`` a wall, ``[x, y, "lava"]`` lava).

    Raises:
        UserError: For an entry of another shape or kind.
    """
    if not isinstance(obstacles, (list, tuple)):
        raise UserError(f"obstacles must be a list of cells, got {obstacles!r}")
    walls, lava = set(), set()
    for o in obstacles:
        ok = isinstance(o, (list, tuple)) and len(o) in (2, 3) and (len(o) == 2 or o[2] == LAVA)
        if not ok or not all(isinstance(c, numbers.Integral) and not isinstance(c, bool) for c in o[:2]):
            raise UserError(f"each obstacle must be a wall [x, y] or lava [x, y, \"lava\"] of integers, got {o!r}")
        (lava if len(o) == 3 else walls).add((int(o[0]), int(o[1])))
    if walls & lava:
        raise UserError(f"cell {list(min(walls & lava))} is both a wall and lava")
    return frozenset(walls), frozenset(lava)


#: Test-time shifts of the dynamics (task parameters applied to the test demonstrations only), each with the value
#: that means "as in training": ``test_slip``, the probability that a step executes one of the three other
#: actions, drawn uniformly, instead of the demonstrator's (which is the action recorded); ``test_obstacles``,
#: the room's obstacles at test time (the same form as the ``obstacles`` env parameter; None: the task's own).
TEST_SHIFTS: dict[str, Any] = {"test_slip": 0.0, "test_obstacles": None}


def test_env_overrides(test_params: Mapping[str, Any]) -> dict[str, Any]:
    """The env keyword arguments of the test demonstrations' env under a task's test shifts."""
    out: dict[str, Any] = {}
    if test_params.get("test_slip"):
        out["slip"] = float(test_params["test_slip"])
    if test_params.get("test_obstacles") is not None:
        out["obstacles"] = test_params["test_obstacles"]
    return out


def check_slip(value: Any) -> None:
    """Refuse a ``test_slip`` that is no probability.

    Raises:
        UserError: Naming the value.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
        raise UserError(f"test_slip must be a probability in [0, 1], got {value!r}")


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
    elif regime == "boltzmann":
        check_beta(params["beta"])
    elif regime == "suboptimal":
        p = params["turn_prob"]
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0.0 <= p <= 1.0:
            raise UserError(f"turn_prob must be in [0, 1], got {p!r}")
        if params["turn_pattern"] not in TURN_PATTERNS:
            raise UserError(f"turn_pattern must be one of {', '.join(TURN_PATTERNS)}, got {params['turn_pattern']!r}")
