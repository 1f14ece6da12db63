"""The maze in pure Python: cells, coordinates, shortest routes and the regimes' parameters.

Nothing here imports MuJoCo, so task cards are validated without it. A maze
is a list of equal-length strings, ``#`` for a wall and ``.`` for a free cell;
cells are ``(row, col)``, row 0 at the top. Coordinates follow
gymnasium-robotics with unit cells: a cell's centre is
``x = col + 0.5 - width / 2``, ``y = height / 2 - row - 0.5``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Mapping, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.routes import check_routes, ranking

#: The most rows or columns a maze has (the published mazes are 7x7 and 11x11; MuJoCo builds one body per cell).
MAX_SIDE = 64


Cell = tuple[int, int]
SUCCESS_RADIUS = 0.45  # the library's: the goal is reached within this distance
# Compass heading -> (row, col) step; routes name headings in order of preference, as in MiniGrid.
MOVES = {"N": (-1, 0), "E": (0, 1), "S": (1, 0), "W": (0, -1)}


@dataclass(frozen=True)
class Maze:
    """A maze layout.

    Args:
        rows: Equal-length strings of ``#`` (wall) and ``.`` (free).
    """

    rows: tuple[str, ...]

    @classmethod
    def parse(cls, rows: Sequence[str]) -> Maze:
        """Validate a layout given as strings.

        Raises:
            UserError: For ragged rows, unknown characters, an open border, or more than :data:`MAX_SIDE` rows or
                columns.
        """
        if (not isinstance(rows, (list, tuple)) or len(rows) < 3
                or not all(isinstance(r, str) and len(r) == len(rows[0]) for r in rows)):
            raise UserError("maze must be a list of at least 3 equal-length strings")
        if max(len(rows), len(rows[0])) > MAX_SIDE:
            raise UserError(f"maze is {len(rows)}x{len(rows[0])} cells, out of range (allowed at most {MAX_SIDE} "
                            "rows and columns)")
        if set("".join(rows)) - {"#", "."}:
            raise UserError("maze rows may hold only '#' (wall) and '.' (free)")
        if set(rows[0] + rows[-1] + "".join(r[0] + r[-1] for r in rows)) != {"#"}:
            raise UserError("the maze border must be walls")
        return cls(tuple(rows))

    @property
    def walls(self) -> list[list[int]]:
        """The layout as gymnasium-robotics' ``maze_map`` (1 = wall, 0 = free)."""
        return [[1 if ch == "#" else 0 for ch in row] for row in self.rows]

    def free(self, cell: Cell) -> bool:
        r, c = cell
        return 0 <= r < len(self.rows) and 0 <= c < len(self.rows[0]) and self.rows[r][c] == "."

    def cells(self) -> list[Cell]:
        return [(r, c) for r in range(len(self.rows)) for c in range(len(self.rows[0])) if self.free((r, c))]

    def xy(self, cell: Cell) -> np.ndarray:
        """Centre of a cell in the simulator's coordinates."""
        r, c = cell
        return np.array([c + 0.5 - len(self.rows[0]) / 2, len(self.rows) / 2 - r - 0.5])

    def step(self, cell: Cell, heading: str) -> Cell:
        dr, dc = MOVES[heading]
        return cell[0] + dr, cell[1] + dc


@lru_cache(maxsize=64)
def distances(maze: Maze, goal: Cell) -> dict[Cell, int]:
    """Shortest number of cell moves to ``goal`` from every cell that reaches it."""
    dist, frontier = {goal: 0}, [goal]
    while frontier:
        nxt = []
        for cell in frontier:
            for h in MOVES:
                n = maze.step(cell, h)
                if maze.free(n) and n not in dist:
                    dist[n] = dist[cell] + 1
                    nxt.append(n)
        frontier = nxt
    return dist


def shortest_routes(maze: Maze, start: Cell, goal: Cell) -> list[str]:
    """Every shortest route from ``start`` to ``goal`` as a string of headings (e.g. ``"NNEE"``)."""
    dist = distances(maze, goal)
    if start not in dist:
        raise UserError(f"goal {goal} cannot be reached from {start}")

    def walk(cell: Cell) -> list[str]:
        if cell == goal:
            return [""]
        return [h + rest for h in MOVES if dist.get(maze.step(cell, h), -1) == dist[cell] - 1
                for rest in walk(maze.step(cell, h))]

    return walk(start)


def biased_route(maze: Maze, start: Cell, goal: Cell, order: str) -> str:
    """The shortest route preferred by a heading order (see :mod:`grail_bench.domains.routes`)."""
    best = ranking(order)
    return min(shortest_routes(maze, start, goal), key=lambda route: [best.index(h) for h in route])


def check_params(regime: str, params: Mapping[str, Any], env_params: Mapping[str, Any],
                 goals: Sequence[Sequence[float]]) -> None:
    """Validate a PointMaze task's maze, start, goals and regime parameters.

    Raises:
        UserError: Naming what is wrong.
    """
    maze = Maze.parse(env_params["maze"])
    start = tuple(env_params["start"])
    if not maze.free(start):
        raise UserError(f"start {list(start)} is not a free cell of the maze")
    for goal in goals:
        cell = tuple(int(c) for c in goal)
        if any(float(c) != int(c) for c in goal) or not maze.free(cell):
            raise UserError(f"goal {list(goal)} must be a free cell (row, col) of the maze")
        if cell == start:
            raise UserError(f"goal {list(goal)} is the start cell")
        shortest_routes(maze, start, cell)
    if regime == "biased":
        check_routes(params["routes"], len(goals))
    if regime == "noisy":
        sigma = params["sigma"]
        if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or sigma < 0:
            raise UserError(f"sigma must be a number >= 0, got {sigma!r}")
    for name in ("max_steps", "action_repeat"):
        value = env_params[name]
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise UserError(f"{name} must be a positive integer, got {value!r}")
    if env_params["reward_type"] not in ("dense", "sparse"):
        raise UserError(f"reward_type must be 'dense' or 'sparse', got {env_params['reward_type']!r}")
