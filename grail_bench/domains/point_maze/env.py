"""PointMaze (gymnasium-robotics) with a pinned goal, a fixed start and a goal-free observation.

A force-controlled ball (MuJoCo) moves through a maze of unit cells. The
recognizers see the ball's position and velocity (4 floats); the goal is
hidden, or recognition would be trivial. Actions are 2-D forces in [-1, 1].
The reward is the library's (``dense``: ``exp(-distance to the goal)``;
``sparse``: 1 within 0.45 of it). Start and goal sit at their cells' centres,
without the library's position noise. Episodes run a fixed horizon
(``max_steps``): reaching the goal does not end them, and
``info["is_success"]`` says whether the ball has been within 0.45 of the goal.
"""

from __future__ import annotations

import contextlib
import os
from typing import Any, Sequence

import numpy as np
from gymnasium import Env, spaces
from gymnasium_robotics.envs.maze.point_maze import PointMazeEnv

from grail_bench.core.errors import UserError
from grail_bench.domains.point_maze.maze import SUCCESS_RADIUS, Maze


class GRPointMazeEnv(Env):
    """Goal-pinned PointMaze.

    Args:
        goal: The ``(row, col)`` cell this env rewards.
        maze: Layout rows (see :mod:`grail_bench.domains.point_maze.maze`).
        start: Start cell ``(row, col)``.
        max_steps: Fixed episode horizon.
        action_repeat: Simulator steps (of 10 ms) per env step, each with the same action; the
            library's is 1, at which crossing a cell takes 20 steps or more.
        reward_type: The library's ``"dense"`` or ``"sparse"`` reward.
        action_scale: Each step executes the action times this, clipped to [-1, 1] (test-time shifted
            dynamics, see :mod:`grail_bench.domains.shifts`; 1 for every env a recognizer builds).
        render_mode: ``"rgb_array"`` or ``None``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, goal: Sequence[int], *, maze: Sequence[str], start: Sequence[int], max_steps: int = 100,
                 action_repeat: int = 5, reward_type: str = "dense", action_scale: float = 1.0,
                 render_mode: str | None = None) -> None:
        if not float(action_scale) > 0:
            raise UserError(f"action_scale must be a number > 0, got {action_scale!r}")
        self.action_scale = float(action_scale)
        if render_mode not in (None, "rgb_array"):
            raise UserError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.maze = Maze.parse(maze)
        self.goal = (int(goal[0]), int(goal[1]))
        self.start = (int(start[0]), int(start[1]))
        for name, cell in (("goal", self.goal), ("start", self.start)):
            if not self.maze.free(cell):
                raise UserError(f"{name} {list(cell)} is not a free cell of the maze")
        self.max_steps = int(max_steps)
        self.render_mode = render_mode
        self.task = None  # set by GRTask.make_env
        self._env = PointMazeEnv(maze_map=self.maze.walls, render_mode=render_mode, reward_type=reward_type,
                                 continuing_task=True, reset_target=False)
        # The library writes the maze's MJCF to $TMPDIR and never deletes it; MuJoCo has loaded it by now.
        with contextlib.suppress(OSError):
            os.remove(self._env.tmp_xml_file_path)
        self._env.position_noise_range = 0.0  # start and goal at their cells' centres
        self._env.point_env.frame_skip = int(action_repeat)
        self._options = {"goal_cell": np.array(self.goal), "reset_cell": np.array(self.start)}
        self.goal_xy = self.maze.xy(self.goal)
        # Position (inside the maze, half its size from the centre) and velocity (the library caps it near 5).
        bound = max(10.0, float(max(len(self.maze.rows), len(self.maze.rows[0]))))
        self.observation_space = spaces.Box(-bound, bound, shape=(4,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._steps, self._reached = 0, False

    @property
    def goal_in_state(self) -> np.ndarray:
        """The goal cell's centre in the state's coordinates: the state begins with the ball's ``(x, y)``
        (goal-conditioned recognizers read it)."""
        return np.asarray(self.goal_xy, dtype=np.float64)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, _ = self._env.reset(seed=seed, options=self._options)
        self._steps, self._reached = 0, False
        return obs["observation"].astype(np.float32), {"is_success": False}

    def step(self, action: Any):
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (2,) or not np.all(np.isfinite(action)):
            raise ValueError(f"invalid action {action!r}; expected 2 finite numbers")
        executed = np.clip(action, -1.0, 1.0)
        if self.action_scale != 1.0:
            executed = np.clip(self.action_scale * executed, -1.0, 1.0).astype(np.float32)
        obs, reward, _, _, _ = self._env.step(executed)
        self._steps += 1
        position = obs["achieved_goal"]
        self._reached = self._reached or bool(np.linalg.norm(position - self.goal_xy) <= SUCCESS_RADIUS)
        return (obs["observation"].astype(np.float32), float(reward), False, self._steps >= self.max_steps,
                {"is_success": self._reached})

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        import mujoco

        try:
            return self._env.render()
        except mujoco.FatalError as exc:
            raise UserError(f"MuJoCo cannot render here ({exc}); set MUJOCO_GL to egl or osmesa on a machine "
                            "with that library") from None

    def close(self) -> None:
        self._env.close()
