"""The symbolic goal env: a grounded STRIPS problem pursuing one of its candidate goals.

Observation: the true fluents as a 0/1 vector in the model's fluent order,
``MultiDiscrete([2] * n_fluents)`` (gymnasium's checker accepts it, BC one-hot
encodes it, GRAQL indexes it: its table has ``2 ** n_fluents`` rows). Action:
``Discrete(n_operators)``, one ground operator each; an inapplicable one
leaves the state unchanged. The episode terminates when the goal holds (reward
1, ``info["is_success"]``) and is truncated after ``max_steps``.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from grail_bench.core.errors import UserError
from grail_bench.core.tabular import TabularDynamics
from grail_bench.domains.symbolic.dataset import load_problem
from grail_bench.domains.symbolic.generator import BUILTIN, builtin_problem
from grail_bench.domains.symbolic.problem import GRProblem


def load(spec: str) -> GRProblem:
    """The problem an env parameter names: a built-in name or the path of an archive or folder, loaded once
    per process (and again when the file changes), so every goal env of a task shares one grounded model.

    Raises:
        UserError: For an unknown name, a missing path or a malformed archive.
    """
    if spec in BUILTIN:
        return _load(spec, 0.0)
    path = Path(spec)
    return _load(str(path.resolve()), path.stat().st_mtime if path.exists() else 0.0)


@lru_cache(maxsize=32)
def _load(spec: str, mtime: float) -> GRProblem:
    return builtin_problem(spec) if spec in BUILTIN else load_problem(spec)


class SymbolicEnv(gym.Env):
    """One candidate goal of a symbolic goal-recognition problem.

    Args:
        goal: ``(i,)``: the index of the goal among the problem's hypotheses.
        problem: A built-in problem name or the path of an archive or folder in the dataset's layout.
        max_steps: Episode horizon.

    Attributes:
        problem: The :class:`~.problem.GRProblem`.
        model: Its grounded :class:`~.strips.StripsModel`.
        goal_index: The goal's index among ``problem.hypotheses``.
        goal_mask: The state bits the goal requires.
    """

    metadata: dict[str, Any] = {"render_modes": ["ansi"], "render_fps": 1}

    def __init__(self, goal: Sequence[float] = (0,), *, problem: str = "blocks", max_steps: int = 50,
                 render_mode: str | None = None) -> None:
        self.problem: GRProblem = load(problem)
        self.model = self.problem.model
        index = int(goal[0])
        if not 0 <= index < len(self.problem.hypotheses):
            raise UserError(f"goal [{index}] is not among the problem's {len(self.problem.hypotheses)} hypotheses")
        self.goal_index = index
        self.goal_mask = self.problem.goal_masks[index]
        if self.model.init & self.goal_mask == self.goal_mask:
            raise UserError(f"{self.problem.name}: hypothesis {index} already holds initially")
        if isinstance(max_steps, bool) or int(max_steps) < 1:
            raise UserError(f"max_steps must be a positive integer, got {max_steps!r}")
        self.max_steps = int(max_steps)
        self.render_mode = render_mode
        self.task = None  # set by GRTask.make_env
        self.observation_space = spaces.MultiDiscrete([2] * self.model.n_fluents)
        self.action_space = spaces.Discrete(self.model.n_operators)
        self.state = self.model.init
        self.steps = 0

    @property
    def goal(self) -> tuple[int]:
        return (self.goal_index,)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.state, self.steps = self.model.init, 0
        return self.model.vector(self.state), {"is_success": False}

    def step(self, action: Any):
        if not self.action_space.contains(action):
            raise ValueError(f"invalid action {action!r}; expected an integer in [0, {self.action_space.n})")
        self.state = self.model.step(self.state, int(action))
        self.steps += 1
        success = self.state & self.goal_mask == self.goal_mask
        truncated = not success and self.steps >= self.max_steps
        return self.model.vector(self.state), float(success), success, truncated, {"is_success": success}

    def render(self) -> str:
        """The true fluents, one atom text per line."""
        from grail_bench.domains.symbolic.pddl_text import atom_text

        return "\n".join(atom_text(a) for a in sorted(self.model.atoms(self.state)))

    def tabular_dynamics(self) -> TabularDynamics:
        """The problem as tables over every state index (tabular learners step these instead of the env).

        Raises:
            UserError: For problems with more than 16 fluents.
        """
        table = self.model.transition_table()
        states = np.arange(len(table), dtype=np.int64)[:, None]
        success = ((table & self.goal_mask) == self.goal_mask) & ((states & self.goal_mask) != self.goal_mask)
        return TabularDynamics(table, success, self.model.init, self.max_steps, lambda t: 1.0)

    def allowed_actions(self) -> np.ndarray:
        """``(2 ** n_fluents, n_operators)``: the operators applicable in each state (an inapplicable one leaves
        the state as it is; no plan takes it). The Boltzmann demonstrator draws among these only.

        Raises:
            UserError: For problems with more than 16 fluents.
        """
        return self.model.applicable_table()
