"""The PointMaze demonstrators' action distributions (noise-free, scripted): a Gaussian per state.

The reference recognizer ``demonstrator`` scores with them (perfect
imitation). The demonstrator of the ``optimal`` regime draws one shortest
route uniformly, that of ``biased`` follows its one preferred route; a PD
controller (:func:`~.demos.route_controller`) then steers through the route's
corners. Its actions are deterministic given the route, so its action
distribution at a state is a mixture of point masses, one per route that
passes there. It is stated as a Gaussian, an approximation:

* mean: the routes' actions there, weighted by their probabilities;
* std: their spread across those routes (the weighted standard deviation),
  at least :data:`STD_FLOOR` per action dimension (where one route passes, or
  all agree, the spread is zero and the floor is the std).

Two supports:

* ``"demonstrated"``: on the states of the demonstrator's rollouts from the
  task's start (matched exactly, float for float: the rollouts are
  deterministic, and the task's demonstrations are these very rollouts), the
  mixture above; elsewhere no preference: the mean and std of the uniform
  distribution on the action box [-1, 1]^2 (0 and 1/sqrt(3)).
* ``"everywhere"``: the same on those states; on any other state, the
  demonstrator as if it started there: from the cell holding the ball (the
  nearest free cell if rounding lands in a wall), the regime's routes to the
  goal from that cell (all shortest ones, equally likely, for ``optimal``;
  the goal's preferred one for ``biased``), each steered by a fresh controller
  aiming at its first corner (on the goal's cell, at the goal's centre), with
  the ball's observed position and velocity; mean and std as above.

The ``noisy`` regime and the SAC expert have no stated action distribution here.
"""

from __future__ import annotations

from fractions import Fraction
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.point_maze.demos import route_controller
from grail_bench.domains.point_maze.maze import Cell, Maze, biased_route, shortest_routes

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

#: The support modes of :func:`demonstrator_policy`.
SUPPORTS = ("everywhere", "demonstrated")
#: The smallest std stated per action dimension: the noise-free demonstrator has none, and a Gaussian needs one
#: (the smallest action noise of the suite's noisy PointMaze tasks).
STD_FLOOR = 0.1
UNIFORM_STD = 1.0 / np.sqrt(3.0)  # of the uniform distribution on [-1, 1]
ACTION_DIM = 2


def demonstrator_policy(task: GRTask, goal: Goal, support: str = "everywhere") -> RoutePolicy:
    """The demonstrator's action distribution of ``goal`` (see the module docstring).

    Raises:
        UserError: For an unknown support, the ``noisy`` regime or the SAC expert.
    """
    check_policy(task, support)
    return RoutePolicy(task, goal, support)


def check_policy(task: GRTask, support: str) -> None:
    """Refuse what :func:`demonstrator_policy` cannot serve, without a rollout.

    Raises:
        UserError: For an unknown support, the ``noisy`` regime or the SAC expert.
    """
    if support not in SUPPORTS:
        raise UserError(f"support must be one of {', '.join(SUPPORTS)}, got {support!r}")
    if task.regime not in ("optimal", "biased") or task.params.get("expert", "scripted") != "scripted":
        raise UserError(f"{task.id}: point_maze states its demonstrator's actions only for the scripted, "
                        "noise-free optimal and biased regimes")


class RoutePolicy:
    """One goal's demonstrator as a callable ``states (T, 4) -> (mean (T, 2), std (T, 2))``.

    Args:
        task: A PointMaze task, ``optimal`` or ``biased``, with the scripted expert.
        goal: One of its goals.
        support: ``"everywhere"`` or ``"demonstrated"``.
    """

    def __init__(self, task: GRTask, goal: Goal, support: str) -> None:
        from grail_bench.domains.point_maze.likelihood import RouteDemonstrator

        self.maze = Maze.parse(task.env_params["maze"])
        self.goal: Cell = (int(goal[0]), int(goal[1]))
        self.order = task.params["routes"][task.goal_index(goal)] if task.regime == "biased" else None
        self.everywhere = support == "everywhere"
        demonstrator = RouteDemonstrator(task, goal)
        weight = Fraction(1, len(demonstrator.routes))  # the routes are equally likely
        actions: dict[tuple[float, ...], dict[tuple[float, ...], Fraction]] = {}
        for route in demonstrator.routes:
            for pair in demonstrator.pairs(route):
                at = actions.setdefault(tuple(pair[:-ACTION_DIM]), {})
                at[tuple(pair[-ACTION_DIM:])] = at.get(tuple(pair[-ACTION_DIM:]), Fraction(0)) + weight
        self.demonstrated = {state: _mixture(at) for state, at in actions.items()}

    def __call__(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        states = np.asarray(states, dtype=np.float32)
        mean, std = np.zeros((len(states), ACTION_DIM)), np.full((len(states), ACTION_DIM), UNIFORM_STD)
        for t, state in enumerate(states):
            known = self.demonstrated.get(tuple(state.tolist()))
            if known is None and self.everywhere:
                known = self.as_if_started(state)
            if known is not None:
                mean[t], std[t] = known
        return mean, std

    def as_if_started(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The demonstrator's mixture at ``state`` had it started in the cell holding the ball."""
        cell = self.cell_of(state[:2])
        routes = _routes(self.maze, cell, self.goal, self.order)
        obs = state.astype(np.float64)
        at: dict[tuple[float, ...], Fraction] = {}
        for route in routes:
            action = tuple(route_controller(self.maze, cell, route)(obs).tolist())
            at[action] = at.get(action, Fraction(0)) + Fraction(1, len(routes))
        return _mixture(at)

    def cell_of(self, position: np.ndarray) -> Cell:
        """The free cell holding ``position`` (the nearest free cell's centre if it lands in a wall)."""
        rows, cols = len(self.maze.rows), len(self.maze.rows[0])
        cell = (int(np.floor(rows / 2 - position[1])), int(np.floor(position[0] + cols / 2)))
        if self.maze.free(cell):
            return cell
        return min(self.maze.cells(), key=lambda c: float(np.linalg.norm(self.maze.xy(c) - position)))


@lru_cache(maxsize=256)
def _routes(maze: Maze, cell: Cell, goal: Cell, order: str | None) -> tuple[str, ...]:
    """The demonstrator's routes from ``cell``: every shortest one, or the one ``order`` prefers."""
    if order is not None:
        return (biased_route(maze, cell, goal, order),)
    return tuple(shortest_routes(maze, cell, goal))


def _mixture(weights: dict[tuple[float, ...], Fraction]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and floored std of point masses at the actions of ``weights`` (action -> probability).

    Equal mixtures give equal results, bit for bit (the actions are taken in sorted order, a single one as it
    is), so goals whose demonstrators act alike at a state tie exactly there.
    """
    actions = sorted(weights)
    if len(actions) == 1:
        return np.array(actions[0]), np.full(ACTION_DIM, STD_FLOOR)
    w = np.array([float(weights[a] / sum(weights.values())) for a in actions])
    a = np.array(actions)
    mean = w @ a
    spread = np.sqrt(w @ (a - mean) ** 2)
    return mean, np.maximum(spread, STD_FLOOR)
