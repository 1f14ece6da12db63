"""Copies of one goal's MiniGrid room stepped at once: a step is a handful of array operations.

PPO-based learners (GAIL, AIRL, DRACO on discrete actions) collect their
rollouts from ``n_envs`` copies of a goal's env. :class:`MiniGridVecEnv` is
an SB3 ``VecEnv`` (the interface SB3 and imitation train on) over the room's
dynamics held in arrays; its transitions, rewards, flags and infos equal those
of :class:`~grail_bench.domains.minigrid.env.GRMiniGridEnv` copies in SB3's
``DummyVecEnv`` (tested step by step), auto-reset conventions included
(``terminal_observation``, ``TimeLimit.truncated``), so a training run gives
the same model with either.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from grail_bench.domains.minigrid.grid import DIR_VEC, FORWARD, LEFT, RIGHT

_TURN = np.zeros(4, dtype=np.int64)
_TURN[LEFT], _TURN[RIGHT] = -1, 1


class MiniGridVecEnv(VecEnv):
    """``n_envs`` copies of a goal env, stepped in numpy.

    Args:
        env: The goal env to copy (it stays the template: attributes are read from it).
        n_envs: Number of copies.
    """

    def __init__(self, env: Any, n_envs: int) -> None:
        self.template = env  # before VecEnv's constructor, which reads the render mode from it
        super().__init__(n_envs, env.observation_space, env.action_space)
        size = env.model.size
        self._free = np.array([[env.model.free(x, y) for y in range(size)] for x in range(size)])
        self._lava = np.array([[(x, y) in env.model.lava for y in range(size)] for x in range(size)])
        self._dir_vec = np.array(DIR_VEC, dtype=np.int64)
        self._goal = np.array(env.goal, dtype=np.int64)
        self._start = np.array([*env.start, env.start_dir], dtype=np.int64)
        self._max_steps = int(env.max_steps)
        self._fixed_horizon = bool(env.fixed_horizon)
        self._state = np.tile(self._start, (n_envs, 1))
        self._steps = np.zeros(n_envs, dtype=np.int64)
        self._absorbed = np.zeros(n_envs, dtype=bool)
        self._success = np.zeros(n_envs, dtype=bool)
        self._actions = np.zeros(n_envs, dtype=np.int64)

    def reset(self) -> np.ndarray:
        self._state[:] = self._start
        self._steps[:] = 0
        self._absorbed[:] = False
        self._success[:] = False
        self.reset_infos = [{"is_success": False} for _ in range(self.num_envs)]
        self._reset_seeds()  # the room has no randomness; seeds are accepted and spent as SB3 expects
        self._reset_options()
        return self._state.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)

    def step_wait(self) -> VecEnvStepReturn:
        actions, state = self._actions, self._state
        if ((actions < 0) | (actions >= self.action_space.n)).any():
            raise ValueError(f"invalid actions {actions!r}; expected integers in [0, {self.action_space.n})")
        was_absorbed = self._absorbed.copy()
        active = ~was_absorbed
        self._steps += 1
        state[:, 2] = np.where(active, (state[:, 2] + _TURN[actions]) % 4, state[:, 2])
        ahead = state[:, :2] + self._dir_vec[state[:, 2]]
        moves = active & (actions == FORWARD) & self._free[ahead[:, 0], ahead[:, 1]]
        state[moves, :2] = ahead[moves]
        reached = moves & (state[:, 0] == self._goal[0]) & (state[:, 1] == self._goal[1])
        burnt = moves & self._lava[state[:, 0], state[:, 1]]  # lava ends the episode, without reward
        # minigrid's reward for reaching the goal, 1 - 0.9 * steps / max_steps (float64, stored as float32 as SB3 does)
        rewards = np.where(reached, 1 - 0.9 * (self._steps / self._max_steps), 0.0).astype(np.float32)
        terminated = (reached | burnt) & (not self._fixed_horizon)
        if self._fixed_horizon:
            self._absorbed |= reached | burnt
        self._success |= reached
        truncated = self._steps >= self._max_steps
        dones = terminated | truncated
        infos = [{"is_success": s, "TimeLimit.truncated": t}
                 for s, t in zip(self._success.tolist(), (truncated & ~terminated).tolist())]
        obs = state.copy()
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = obs[i].copy()
            state[i], self._steps[i], self._absorbed[i], self._success[i] = self._start, 0, False, False
            obs[i] = self._start
            self.reset_infos[i] = {"is_success": False}
        return obs, rewards, dones, infos

    def close(self) -> None:
        self.template.close()

    def _indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else list(indices)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The template env's attribute, once per index (every copy shares its configuration)."""
        return [getattr(self.template, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"MiniGridVecEnv copies share one configuration; {attr_name!r} cannot be set per copy")

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        raise AttributeError(f"MiniGridVecEnv holds no env objects to call {method_name!r} on")

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._indices(indices)]
