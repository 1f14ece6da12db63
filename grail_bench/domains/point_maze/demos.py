"""PointMaze demonstrators: a route over the maze's cells, followed by a PD controller.

* ``optimal``: a shortest route drawn uniformly among all of them.
* ``biased`` (``routes``): one fixed shortest route per goal, chosen by a
  heading order as in MiniGrid (``"NE"``: north as long as a shortest route
  allows, then east), so two equally short routes around a wall block are not
  equally likely: the demonstrator always goes round the same side.
* ``noisy`` (``sigma``): ``optimal`` plus N(0, sigma^2) on each action
  dimension at every step, clipped to [-1, 1]; the clipped action is what the
  demonstration records. The controller is closed-loop, so noisy
  demonstrations still reach the goal.

The controller steers at the route's next corner (the goal last), tracking a
velocity towards it capped at :data:`CRUISE`; it is deterministic,
so without noise a route always gives the same trajectory. ``expert = "sac"``
replaces it by a SAC agent trained once per goal on the library's reward and
cached (``expert_steps``, ``expert_seed``); the route regimes then do not apply
and only ``optimal`` and ``noisy`` accept it.

Test demonstrations under ``test_action_scale`` (:mod:`grail_bench.domains.shifts`) are rolled out with the
scaled actuator; the controller, closed-loop, still steers, and one that fails to reach the goal is kept as
it is.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.seeding import EXPERT, goal_seed
from grail_bench.core.trajectory import rollout
from grail_bench.domains.point_maze.maze import Cell, Maze, biased_route, shortest_routes
from grail_bench.domains.shifts import action_scale_overrides

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

Controller = Callable[[np.ndarray], np.ndarray]
CRUISE, GAIN, CORNER = 3.0, 3.0, 0.15  # top speed (cells/s), gain, corner radius (cells)
SAC_NET = [64, 64]


def corners(maze: Maze, start: Cell, route: str) -> list[np.ndarray]:
    """Centres of the cells where the route turns, then the goal's (an empty route: the start's, its goal)."""
    points, cell = [], start
    for i, heading in enumerate(route):
        cell = maze.step(cell, heading)
        if i + 1 == len(route) or route[i + 1] != heading:
            points.append(maze.xy(cell))
    return points or [maze.xy(start)]


def route_controller(maze: Maze, start: Cell, route: str) -> Controller:
    """A PD controller visiting the route's corners in turn (stateful: use one per episode)."""
    targets = corners(maze, start, route)
    state = {"next": 0}

    def act(obs: np.ndarray) -> np.ndarray:
        position, velocity = obs[:2].astype(np.float64), obs[2:].astype(np.float64)
        while state["next"] < len(targets) - 1 and np.linalg.norm(targets[state["next"]] - position) < CORNER:
            state["next"] += 1
        offset = targets[state["next"]] - position
        distance = np.linalg.norm(offset)
        wanted = offset / distance * min(CRUISE, GAIN * distance) if distance > 1e-9 else np.zeros(2)
        return np.clip(GAIN * (wanted - velocity), -1.0, 1.0)

    return act


def sac_controller(task: GRTask, goal: Goal) -> Controller:
    """The goal's SAC expert, trained once per goal, expert seed, env and budget, then read from the cache."""
    from importlib.metadata import version

    from grail_bench.core import experts

    env = task.make_env(goal)
    try:
        key = {"goal": list(goal), "env": dict(task.env_params), "gymnasium-robotics": version("gymnasium-robotics")}
        return experts.sac_expert("point-maze-sac-expert", env, key, int(task.params["expert_steps"]),
                             goal_seed(int(task.params["expert_seed"]), goal, EXPERT), SAC_NET)
    finally:
        env.close()


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal under the task's regime (see module docstring)."""
    maze, start = Maze.parse(task.env_params["maze"]), tuple(task.env_params["start"])
    cell = (int(goal[0]), int(goal[1]))
    sigma = float(task.params.get("sigma", 0.0))
    env = task.make_env(goal, **action_scale_overrides(task.test_params))  # a test split's shifted dynamics
    expert = sac_controller(task, goal) if task.params.get("expert") == "sac" else None
    demos = []
    try:
        for _ in range(n):
            if expert is not None:
                controller = expert
            elif task.regime == "biased":
                controller = route_controller(maze, start, biased_route(
                    maze, start, cell, task.params["routes"][task.goal_index(goal)]))
            else:
                routes = shortest_routes(maze, start, cell)
                controller = route_controller(maze, start, routes[int(rng.integers(len(routes)))])

            def policy(obs: np.ndarray, t: int, act: Controller = controller) -> np.ndarray:
                noise = rng.normal(0.0, sigma, size=2) if sigma > 0 else 0.0
                return np.clip(act(obs) + noise, -1.0, 1.0).astype(np.float32)

            try:
                # under shifted dynamics a demonstration may fail: that is part of the shift
                demos.append(rollout(env, policy, require_success=not task.test_params))
            except RuntimeError as exc:
                if expert is None:
                    raise
                raise UserError(f"{task.id}: {exc}: the SAC expert is undertrained; raise expert_steps") from None
    finally:
        env.close()
    return demos
