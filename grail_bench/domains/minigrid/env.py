"""The paper's MiniGrid domain: a 9x9 room, one obstacle, goal-pinned envs (other rooms, walls and lava through
the parameters).

Observations are the compact state ``(x, y, direction)`` as a ``MultiDiscrete``
space (SB3 and imitation one-hot encode it); actions are ``Discrete(4)``:
turn left, turn right, move forward, stay. Directions follow minigrid:
0 = east, 1 = south, 2 = west, 3 = north; ``y`` grows southwards.

With ``fixed_horizon=True`` (the default, needed by GAIL and AIRL) reaching the
goal does not end the episode: the agent is absorbed there, every further
action is a no-op with zero reward, and the episode is truncated after
``max_steps``. ``info["is_success"]`` tells whether the goal has been reached.

With ``slip`` (test-time shifted dynamics, see :mod:`grail_bench.domains.minigrid`; 0 for every env a
recognizer builds) each step before the goal or lava executes, with probability ``slip``, one of the three
other actions drawn uniformly instead of the one given (from the env's ``np_random``, seeded by ``reset``).

Lava (``[x, y, "lava"]`` obstacles) ends the episode when entered, as in
minigrid, with no reward: the episode terminates, or with ``fixed_horizon``
the agent is absorbed in the lava, as at the goal, until the horizon (and
``is_success`` stays false).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium import spaces  # imported first: gymnasium hides pygame's banner for minigrid
from minigrid.core.actions import Actions
from minigrid.core.grid import Grid
from minigrid.core.mission import MissionSpace
from minigrid.core.world_object import Goal, Lava, Wall
from minigrid.minigrid_env import MiniGridEnv

from grail_bench.core.errors import UserError
from grail_bench.core.spaces import all_states, state_index
from grail_bench.core.tabular import TabularDynamics
from grail_bench.domains.minigrid.grid import ACTION_NAMES, GridModel, State

_TO_MINIGRID = (Actions.left, Actions.right, Actions.forward, Actions.done)


def _mission() -> str:
    return "reach the goal"


class GRMiniGridEnv(MiniGridEnv):
    """Goal-pinned navigation in the paper's room.

    Args:
        goal: The ``(x, y)`` cell this env rewards.
        size: Side of the square grid, outer walls included.
        start: Start cell of the agent.
        start_dir: Start direction (0 = east).
        obstacles: Interior obstacle cells: ``[x, y]`` a wall, ``[x, y, "lava"]`` lava.
        max_steps: Episode horizon.
        fixed_horizon: Absorb at the goal instead of terminating.
        slip: Probability that a step executes another action than the one given (see the module docstring).
        render_mode: ``"rgb_array"``, ``"human"`` or ``None``.
    """

    def __init__(
        self,
        goal: Sequence[int] = (7, 1),
        *,
        size: int = 9,
        start: Sequence[int] = (1, 4),
        start_dir: int = 0,
        obstacles: Sequence[Sequence[Any]] = ((7, 4),),
        max_steps: int = 60,
        fixed_horizon: bool = True,
        slip: float = 0.0,
        render_mode: str | None = None,
    ) -> None:
        self.model = GridModel.of(size, obstacles)
        if not 0.0 <= float(slip) <= 1.0:
            raise UserError(f"slip must be a probability in [0, 1], got {slip!r}")
        self.slip = float(slip)
        self.goal = (int(goal[0]), int(goal[1]))
        self.start = (int(start[0]), int(start[1]))
        self.start_dir = int(start_dir)
        for name, cell in (("goal", self.goal), ("start", self.start)):
            if not self.model.safe(*cell):
                raise UserError(f"{name} {cell} is not a free cell of the {size}x{size} room (a wall or lava)")
        if self.goal == self.start:
            raise UserError("goal and start must differ")
        if not 0 <= self.start_dir < 4:
            raise UserError(f"start_dir must be in 0..3, got {start_dir}")
        self.fixed_horizon = bool(fixed_horizon)
        self.task = None  # set by GRTask.make_env
        self._absorbed = self._success = False
        super().__init__(
            mission_space=MissionSpace(mission_func=_mission),
            width=self.model.size, height=self.model.size, max_steps=int(max_steps),
            see_through_walls=True, render_mode=render_mode,
        )
        self.observation_space = spaces.MultiDiscrete([self.model.size, self.model.size, 4])
        self.action_space = spaces.Discrete(len(ACTION_NAMES))

    def _gen_grid(self, width: int, height: int) -> None:
        self.grid = Grid(width, height)
        self.grid.wall_rect(0, 0, width, height)
        for x, y in self.model.obstacles:
            self.grid.set(x, y, Wall())
        for x, y in self.model.lava:
            self.grid.set(x, y, Lava())
        self.put_obj(Goal(), *self.goal)
        self.agent_pos = self.start
        self.agent_dir = self.start_dir

    def gen_obs(self) -> np.ndarray:
        """The compact state ``(x, y, direction)``."""
        return np.array([self.agent_pos[0], self.agent_pos[1], self.agent_dir], dtype=np.int64)

    @property
    def goal_in_state(self) -> np.ndarray:
        """The goal in the state's coordinates: it is the first two, ``(x, y)`` (goal-conditioned recognizers
        read it)."""
        return np.asarray(self.goal, dtype=np.float64)

    def vector_copies(self, n_envs: int):
        """``n_envs`` copies of this env stepped at once in numpy (an SB3 ``VecEnv``, same transitions)."""
        self._deterministic("vector copies")
        from grail_bench.domains.minigrid.vector import MiniGridVecEnv

        return MiniGridVecEnv(self, n_envs)

    def tabular_dynamics(self) -> TabularDynamics:
        """The room as tables over state indices (tabular learners step these instead of the env).

        Cells outside the free area are never entered; their rows stay in place, as do those of lava, where the
        episode has ended without reward (absorbed, as the env with ``fixed_horizon`` keeps it).
        """
        self._deterministic("tabular dynamics")
        states = all_states(self.observation_space)
        n_actions = int(self.action_space.n)
        next_state = np.tile(np.arange(len(states))[:, None], (1, n_actions))
        success = np.zeros(next_state.shape, dtype=bool)
        for i, (x, y, d) in enumerate(states.tolist()):
            if not self.model.free(x, y) or (x, y) == self.goal:
                continue  # the goal is never left: reaching it ends the episode
            for a in range(n_actions):
                nx, ny, nd = self.model.step((x, y, d), a)
                next_state[i, a] = int(state_index(np.array([[nx, ny, nd]]), self.observation_space)[0])
                success[i, a] = (nx, ny) == self.goal
        start = int(state_index(np.array([[*self.start, self.start_dir]]), self.observation_space)[0])
        horizon = int(self.max_steps)
        # minigrid's reward for reaching the goal (MiniGridEnv._reward), the same float operations
        return TabularDynamics(next_state, success, start, horizon, lambda t: 1 - 0.9 * (t / horizon))

    def _deterministic(self, what: str) -> None:
        if self.slip:
            raise UserError(f"{what} step the room's deterministic dynamics; this env slips (slip={self.slip:g})")

    @property
    def state(self) -> State:
        """Current ``(x, y, direction)`` as a tuple."""
        return int(self.agent_pos[0]), int(self.agent_pos[1]), int(self.agent_dir)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._absorbed = self._success = False
        obs, info = super().reset(seed=seed, options=options)
        return obs, {**info, "is_success": False}

    def step(self, action: Any):
        if not self.action_space.contains(action):
            raise ValueError(f"invalid action {action!r}; expected an integer in [0, {self.action_space.n})")
        if self._absorbed:
            self.step_count += 1
            truncated = self.step_count >= self.max_steps
            return self.gen_obs(), 0.0, False, truncated, {"is_success": self._success}
        executed = int(action)
        if self.slip and self.np_random.random() < self.slip:
            executed = [a for a in range(len(ACTION_NAMES)) if a != executed][int(self.np_random.integers(3))]
        obs, reward, terminated, truncated, info = super().step(_TO_MINIGRID[executed])
        if terminated:  # the goal or lava
            self._absorbed = self.fixed_horizon
            self._success = tuple(self.agent_pos) == self.goal
        info["is_success"] = self._success
        return obs, float(reward), terminated and not self.fixed_horizon, truncated, info
