"""PointMaze (gymnasium-robotics, MuJoCo): a ball pushed through a maze to one of several goal cells.

* :mod:`.maze`: the layout, shortest routes and parameter checks (no MuJoCo import).
* :mod:`.env`: the goal-pinned env with a goal-free observation.
* :mod:`.demos`: the route-following demonstrators (or a cached SAC expert).
* :mod:`.likelihood`: their exact likelihood, for the Bayes ceiling; :mod:`.policy`: their actions as a
  Gaussian per state, for the ``demonstrator`` recognizer.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Sequence

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.domains.point_maze.maze import check_params
from grail_bench.domains.shifts import ACTION_SCALE, ACTION_SCALE_BOUND, check_action_scale

if TYPE_CHECKING:
    import numpy as np

    from grail_bench.core.trajectory import Goal
    from grail_bench.domains.point_maze.policy import RoutePolicy
    from grail_bench.task.model import GRTask

# Three lanes each way around four pillars: most goals have several equally short routes.
PILLARS = ["#######", "#.....#", "#.#.#.#", "#.....#", "#.#.#.#", "#.....#", "#######"]
_EXPERT = {"expert": "scripted", "expert_steps": 30000, "expert_seed": 0}


class PointMaze:
    """The :class:`~grail_bench.domains.Domain` of gymnasium-robotics' PointMaze."""

    name = "point_maze"
    goal_dim = 2
    env_defaults: Mapping[str, Any] = {"maze": PILLARS, "start": [5, 1], "max_steps": 100, "action_repeat": 5,
                                       "reward_type": "dense"}
    regimes: Mapping[str, Mapping[str, Any]] = {
        "optimal": dict(_EXPERT),
        # One preferred heading order per goal, e.g. "NE" = north, then east (as in MiniGrid).
        "biased": {"routes": []},
        "noisy": {**_EXPERT, "sigma": 0.1},
    }
    # Sizes of work, far above the published ones (100-200 steps, a 30,000-step expert).
    bounds: Mapping[str, Range] = {"max_steps": Range(1, 10_000), "action_repeat": Range(1, 1_000),
                                   "expert_steps": Range(1, 10_000_000), **ACTION_SCALE_BOUND}
    # The scripted routes are deterministic; action noise has a density but no enumerable support.
    ceiling_regimes = frozenset({"optimal", "biased"})
    test_params: Mapping[str, Any] = ACTION_SCALE  # test-time shifted dynamics (grail_bench.domains.shifts)
    ceiling_shifts = frozenset(ACTION_SCALE)  # the scripted routes stay deterministic: their likelihood exact
    cache_demos = True  # a seed's rollouts take minutes: generated once, kept on disk
    noop_action = (0.0, 0.0)  # no force on the ball

    def check(self, regime: str, params: Mapping[str, Any], env_params: Mapping[str, Any],
              goals: Sequence[Goal]) -> None:
        check_params(regime, params, env_params, goals)
        if "expert" in params:
            if params["expert"] not in ("scripted", "sac"):
                raise UserError(f"expert must be 'scripted' or 'sac', got {params['expert']!r}")
            for name in ("expert_steps", "expert_seed"):
                value = params[name]
                if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                    raise UserError(f"{name} must be a non-negative integer, got {value!r}")

    def check_test(self, test_params: Mapping[str, Any], env_params: Mapping[str, Any],
                   goals: Sequence[Goal]) -> None:
        """Validate the test shift (``test_action_scale``)."""
        check_action_scale(test_params)

    def make_env(self, goal: Goal, **env_params: Any):
        from grail_bench.domains.point_maze.env import GRPointMazeEnv

        return GRPointMazeEnv(goal, **env_params)

    def generate_demos(self, task: GRTask, goal: Goal, n: int, rng: np.random.Generator):
        from grail_bench.domains.point_maze.demos import generate_demos

        return generate_demos(task, goal, n, rng)

    def demonstrator(self, task: GRTask, goal: Goal):
        from grail_bench.domains.point_maze.likelihood import RouteDemonstrator

        return RouteDemonstrator(task, goal)

    def demonstrator_policy(self, task: GRTask, goal: Goal, support: str = "everywhere") -> RoutePolicy:
        """The scripted, noise-free demonstrator's actions as a Gaussian per state (``optimal`` and ``biased``;
        see :mod:`.policy` for the approximation and the supports)."""
        from grail_bench.domains.point_maze.policy import demonstrator_policy

        return demonstrator_policy(task, goal, support)

    def check_demonstrator_policy(self, task: GRTask, support: str = "everywhere") -> None:
        """Refuse, in one line and without building anything, a task :meth:`demonstrator_policy` cannot serve."""
        from grail_bench.domains.point_maze.policy import check_policy

        check_policy(task, support)


DOMAIN = PointMaze()
