"""PandaReach (panda-gym): a Franka arm reaching one of several 3-D targets.

* :mod:`.env`: the goal-pinned env with a flat, goal-free observation.
* :mod:`.demos`: the SAC or scripted expert plus the regimes' action noise.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.domains.shifts import ACTION_SCALE, ACTION_SCALE_BOUND, check_action_scale

if TYPE_CHECKING:
    import numpy as np

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

BASE = (-0.6, 0.0, 0.0)  # panda-gym's robot base
# Metres from the base: at table height the end effector stretches to 0.815 m, so goals at 0.85 m are
# reached within 3.6 cm of the 5 cm success radius and goals at 0.875 m are missed by 6 cm (scripted expert).
REACH = 0.85
EXPERTS = ("sac", "scripted")


def check_reach(goal: Sequence[float]) -> None:
    """Raise unless ``goal`` is above the table and within the arm's reach."""
    if goal[2] < 0 or math.dist(goal, BASE) > REACH:
        raise UserError(f"goal {tuple(goal)} is out of the arm's reach (above the table, within {REACH} m of "
                        f"its base {BASE})")


def _non_negative(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
        raise UserError(f"{name} must be a number >= 0, got {value!r}")


class PandaReach:
    """The :class:`~grail_bench.domains.Domain` of panda-gym's reach task."""

    name = "panda_reach"
    goal_dim = 3
    env_defaults: Mapping[str, Any] = {"max_steps": 50, "distance_threshold": 0.05, "max_action": 1.0}
    # expert_seed: the SAC expert is part of the demonstrator, trained once per goal with this seed.
    regimes: Mapping[str, Mapping[str, Any]] = {
        "optimal": {"expert": "sac", "expert_steps": 15000, "expert_seed": 0},
        "gaussian": {"expert": "sac", "expert_steps": 15000, "expert_seed": 0, "sigma": 0.1},
        "uniform": {"expert": "sac", "expert_steps": 15000, "expert_seed": 0, "half_width": 0.1},
    }
    # Sizes of work, far above the published ones (50 steps, a 15,000-step expert).
    bounds: Mapping[str, Range] = {"max_steps": Range(1, 10_000), "expert_steps": Range(1, 10_000_000),
                                   **ACTION_SCALE_BOUND}
    ceiling_regimes: frozenset[str] = frozenset()  # a learned expert plus continuous noise: no likelihood
    test_params: Mapping[str, Any] = ACTION_SCALE  # test-time shifted dynamics (grail_bench.domains.shifts)
    noop_action = (0.0, 0.0, 0.0)  # the zero displacement of the end effector: the arm stays where it is
    cache_demos = True  # a seed's rollouts take minutes: generated once, kept on disk

    def check(self, regime: str, params: Mapping[str, Any], env_params: Mapping[str, Any],
              goals: Sequence[Goal]) -> None:
        if params["expert"] not in EXPERTS:
            raise UserError(f"expert must be one of {', '.join(EXPERTS)}, got {params['expert']!r}")
        for name in ("expert_steps", "expert_seed"):
            if isinstance(params[name], bool) or not isinstance(params[name], int) or params[name] < 0:
                raise UserError(f"{name} must be a non-negative integer, got {params[name]!r}")
        for name in ("sigma", "half_width"):
            if name in params:
                _non_negative(name, params[name])
        threshold = env_params["distance_threshold"]
        if isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or threshold <= 0:
            raise UserError(f"distance_threshold must be a number > 0, got {threshold!r}")
        max_action = env_params["max_action"]
        if isinstance(max_action, bool) or not isinstance(max_action, (int, float)) or not 0 < max_action <= 1:
            raise UserError(f"max_action must be in (0, 1], got {max_action!r}")
        for goal in goals:
            check_reach(goal)

    def check_test(self, test_params: Mapping[str, Any], env_params: Mapping[str, Any],
                   goals: Sequence[Goal]) -> None:
        """Validate the test shift (``test_action_scale``)."""
        check_action_scale(test_params)

    def make_env(self, goal: Goal, **env_params: Any):
        from grail_bench.domains.panda_reach.env import GRPandaReachEnv

        return GRPandaReachEnv(goal, **env_params)

    def generate_demos(self, task: GRTask, goal: Goal, n: int, rng: np.random.Generator):
        from grail_bench.domains.panda_reach.demos import generate_demos

        return generate_demos(task, goal, n, rng)

    def demonstrator(self, task: GRTask, goal: Goal):
        raise UserError(f"{task.id}: panda_reach demonstrators have no known likelihood")


DOMAIN = PandaReach()
