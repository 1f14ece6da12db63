"""The exact likelihood of PointMaze's noise-free demonstrators, for the Bayes ceiling.

Without noise, a route always gives the same trajectory (the controller and
MuJoCo are deterministic), so a goal's demonstrator is a uniform mixture over
its shortest routes (``optimal``) or one route (``biased``). Routes sharing
their first corner share their first pairs exactly, float for float, which is
where the ambiguity lies. An observation is a tuple of ``(state, action)``
pairs; within a trajectory no pair repeats, so an observation comes from a
route's span at most one way.
"""

from __future__ import annotations

from math import comb
from typing import TYPE_CHECKING, Iterator

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import goal_horizon, rollout
from grail_bench.domains.shifts import action_scale_overrides
from grail_bench.domains.point_maze.demos import route_controller
from grail_bench.domains.point_maze.maze import Maze, biased_route, shortest_routes
from grail_bench.task.observation import Selection, n_observed

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

Pair = tuple[float, ...]  # the state's 4 floats, then the action's 2


class RouteDemonstrator:
    """One goal's noise-free demonstrator (a :class:`~grail_bench.domains.base.GoalModel`).

    Args:
        task: A PointMaze task with the ``optimal`` or ``biased`` regime and the scripted expert.
        goal: One of its goals.
    """

    enumerable = True
    action_size = 2

    def __init__(self, task: GRTask, goal: Goal) -> None:
        if task.regime not in ("optimal", "biased") or task.params.get("expert", "scripted") != "scripted":
            raise UserError(f"{task.id}: only the scripted, noise-free demonstrators have a known likelihood")
        maze, start = Maze.parse(task.env_params["maze"]), tuple(task.env_params["start"])
        cell = (int(goal[0]), int(goal[1]))
        if task.regime == "biased":
            self.routes = [biased_route(maze, start, cell, task.params["routes"][task.goal_index(goal)])]
        else:
            self.routes = sorted(shortest_routes(maze, start, cell))
        env = task.make_env(goal, **action_scale_overrides(task.test_params))  # a test split's shifted dynamics
        self._pairs: dict[str, tuple[list[Pair], int]] = {}
        for route in self.routes:
            act = route_controller(maze, start, route)
            traj = rollout(env, lambda obs, t: np.clip(act(obs), -1.0, 1.0).astype(np.float32),
                           require_success=not task.test_params)
            pairs = [tuple(np.concatenate([o, a]).tolist()) for o, a in zip(traj.obs[:-1], traj.acts)]
            self._pairs[route] = (pairs, goal_horizon(traj))
        env.close()
        self._index = {route: {p: i for i, p in enumerate(pairs)} for route, (pairs, _) in self._pairs.items()}

    def support(self) -> Iterator[tuple[str, float]]:
        for route in self.routes:
            yield route, 1.0 / len(self.routes)

    def pairs(self, route: str) -> list[Pair]:
        """Every ``(state, action)`` pair of the route's rollout, over the whole horizon."""
        return self._pairs[route][0]

    def span(self, route: str, selection: Selection) -> list[Pair]:
        pairs, goal_step = self._pairs[route]
        return pairs if selection.horizon else pairs[:goal_step]

    def observations(self, route: str, selection: Selection) -> Iterator[tuple[tuple, float]]:
        return selection.observations(self.span(route, selection))

    def sample_observation(self, rng: np.random.Generator, selection: Selection) -> tuple:
        return selection.sample(self.span(self.routes[int(rng.integers(len(self.routes)))], selection), rng)

    def likelihood(self, observation: tuple, selection: Selection) -> float:
        total = 0.0
        for route in self.routes:
            pairs = self.span(route, selection)
            k = n_observed(selection.level, len(pairs), selection.rounding)
            if len(observation) != k:
                continue
            if not selection.random_subset:
                total += float(tuple(pairs[:k]) == observation)
                continue
            index = self._index[route]
            positions = [index.get(p, -1) for p in observation]
            limit = len(pairs)
            if all(0 <= a < b < limit for a, b in zip(positions, positions[1:])) and 0 <= positions[0] < limit:
                total += 1.0 / comb(len(pairs), k)
        return total / len(self.routes)
