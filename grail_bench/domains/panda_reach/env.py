"""PandaReach with a pinned goal: panda-gym's Franka arm reaching one of four 3-D targets.

The goal is pinned through the task's own ``_sample_goal``, so the reward, the
termination test and the rendered target all use it (setting ``task.goal``
after a reset would leave ``reset`` re-sampling it). The recognizers see a flat
observation, the end-effector position and velocity (6 floats); the goal is
hidden, or recognition would be trivial. Actions are 3-D end-effector
displacements in [-1, 1]; the reward is dense (minus the distance to the
goal). Episodes have a fixed horizon (``max_steps``, 50 as panda-gym's): success
does not end them, ``info["is_success"]`` reports it.

The default four goals sit in the corners of panda-gym's goal box, 0.2-0.35 m
apart (4-7 times the 5 cm success radius) and in four different directions
from the start (0.04, 0, 0.2), so every goal has its own motion from the first
step. The baselines' goal set (:data:`ALIGNED_GOALS`) lies outside that box and
has two goals in nearly the same direction from the start; any goal within
the arm's reach (:data:`~grail_bench.domains.panda_reach.REACH`) is accepted.
"""

from __future__ import annotations

import contextlib
import os
from typing import Any, Iterator, Sequence

import numpy as np
from gymnasium import Env, spaces

from grail_bench.core.errors import UserError
from grail_bench.domains.panda_reach import check_reach

GOALS = ((0.10, 0.10, 0.05), (0.10, -0.10, 0.05), (-0.05, 0.10, 0.25), (-0.05, -0.10, 0.25))
# gr_libs' PandaReach goals, with (-0.5, 0.2, 0.1) moved to (-0.4, 0.2, 0.1): the arm gets no closer than
# 4.4 cm to the original, at the edge of the 5 cm success radius, so demonstrations hovered there.
ALIGNED_GOALS = ((-0.5, -0.5, 0.1), (-0.4, 0.2, 0.1), (-0.1, 0.1, 0.1), (0.1, -0.1, 0.1))


@contextlib.contextmanager
def quiet_native_output() -> Iterator[None]:
    """Silence native writes to stdout and stderr (pybullet prints its build
    banner on import and its options on connect)."""
    import ctypes
    import sys

    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # nothing to silence
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            yield
    finally:
        ctypes.CDLL(None).fflush(None)  # buffered native output goes to /dev/null too
        for fd, target in zip(saved, (1, 2)):
            os.dup2(fd, target)
            os.close(fd)


with quiet_native_output():
    from panda_gym.envs.panda_tasks import PandaReachEnv


class GRPandaReachEnv(Env):
    """Goal-pinned PandaReach with a flat, goal-free observation.

    Args:
        goal: The 3-D target this env rewards.
        max_steps: Fixed episode horizon.
        distance_threshold: Success radius in metres (panda-gym's 0.05).
        max_action: Actions are clipped to ``[-max_action, max_action]`` (gr_libs' set uses 0.5).
        action_scale: Each step executes the (clipped) action times this, clipped again (test-time shifted
            dynamics, see :mod:`grail_bench.domains.shifts`; 1 for every env a recognizer builds).
        render_mode: ``"rgb_array"`` or ``None`` (pybullet runs headless).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, goal: Sequence[float] = GOALS[0], *, max_steps: int = 50, distance_threshold: float = 0.05,
                 max_action: float = 1.0, action_scale: float = 1.0, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise UserError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        target = np.asarray(goal, dtype=np.float64)
        if target.shape != (3,):
            raise UserError(f"goal must have 3 coordinates, got {goal!r}")
        self.goal = tuple(float(c) for c in target)
        self.max_steps = int(max_steps)
        self.render_mode = render_mode
        self.task = None  # set by GRTask.make_env
        check_reach(self.goal)
        if not 0 < max_action <= 1:
            raise UserError(f"max_action must be in (0, 1], got {max_action}")
        self.max_action = float(max_action)
        if not float(action_scale) > 0:
            raise UserError(f"action_scale must be a number > 0, got {action_scale!r}")
        self.action_scale = float(action_scale)
        with quiet_native_output():
            self._env = PandaReachEnv(render_mode="rgb_array", reward_type="dense", control_type="ee")
        reach = self._env.task
        reach.distance_threshold = float(distance_threshold)
        reach._sample_goal = target.copy  # pins reward, termination and the target
        # End-effector position (m) and velocity (m/s): well inside +-10 for this arm.
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(6,), dtype=np.float32)
        self.action_space = spaces.Box(-self.max_action, self.max_action, shape=(3,), dtype=np.float32)
        self._steps = 0

    @property
    def ee_position(self) -> np.ndarray:
        """Current end-effector position."""
        return np.asarray(self._env.robot.get_ee_position(), dtype=np.float64)

    @property
    def goal_in_state(self) -> np.ndarray:
        """The goal in the state's coordinates: the state begins with the end effector's position
        (goal-conditioned recognizers read it)."""
        return np.asarray(self.goal, dtype=np.float64)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, _ = self._env.reset(seed=seed, options=options)
        self._steps = 0
        return obs["observation"].astype(np.float32), {"is_success": False}

    def step(self, action: Any):
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (3,) or not np.all(np.isfinite(action)):
            raise ValueError(f"invalid action {action!r}; expected 3 finite numbers")
        executed = np.clip(action, -self.max_action, self.max_action)
        if self.action_scale != 1.0:  # test-time shifted dynamics (grail_bench.domains.shifts)
            executed = np.clip(self.action_scale * executed, -self.max_action, self.max_action).astype(np.float32)
        obs, reward, terminated, _, info = self._env.step(executed)
        self._steps += 1
        return (obs["observation"].astype(np.float32), float(reward), False, self._steps >= self.max_steps,
                {"is_success": bool(terminated)})

    def render(self) -> np.ndarray | None:
        return self._env.render() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self._env.close()
