"""Scripted symbolic demonstrators for the three behaviour regimes.

* ``optimal``: an optimal plan drawn uniformly among all optimal plans (from
  the DAG of every optimal plan, each successor weighted by the number of
  optimal plans through it).
* ``biased``: the lexicographically first optimal plan by operator index, the
  same for every demonstration: one consistent preference among optimal plans.
* ``suboptimal``: an optimal plan drawn as for ``optimal``; before each of its
  actions, with probability ``detour_prob``, a detour of two actions that undo
  each other (the first changes the state, the second restores it; drawn
  uniformly among every such pair there, and never through the goal), so the
  demonstration visits the plan's states with excursions of one step.

Every demonstration is rolled out in the goal's own env; it ends when the goal holds.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import rollout
from grail_bench.domains.symbolic.planner import PlanGraph, optimal_plan_graph
from grail_bench.domains.symbolic.strips import StripsModel

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

REGIMES = ("optimal", "biased", "suboptimal")


@lru_cache(maxsize=64)
def plan_graph(model: StripsModel, goal: int, start: int) -> PlanGraph:
    """Every optimal plan from ``start`` to the goal mask ``goal`` (cached)."""
    return optimal_plan_graph(model, goal, start)


def detours(model: StripsModel, state: int, goal: int) -> list[tuple[int, int]]:
    """Every pair of operators whose first changes ``state`` (not into a goal state) and whose second restores it."""
    out = []
    for op, nxt in model.successors(state):
        if nxt == state or nxt & goal == goal:
            continue
        out += [(op, back) for back, prev in model.successors(nxt) if prev == state]
    return out


def insert_detours(model: StripsModel, plan: list[int], goal: int, prob: float, rng: np.random.Generator) -> list[int]:
    """Before each action of ``plan``, with probability ``prob``, one detour drawn uniformly (if there is one)."""
    out, state = [], model.init
    for op in plan:
        if rng.random() < prob:
            options = detours(model, state, goal)
            if options:
                out += options[int(rng.integers(len(options)))]
        out.append(op)
        state = model.apply(state, op)
    return out


def demo_plan(task: GRTask, graph: PlanGraph, model: StripsModel, rng: np.random.Generator) -> list[int]:
    """One demonstration's actions under the task's regime."""
    if task.regime == "biased":
        return graph.first()
    plan = graph.sample(rng)
    if task.regime == "suboptimal":
        plan = insert_detours(model, plan, graph.goal, float(task.params["detour_prob"]), rng)
    return plan


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal under the task's regime (see the module docstring)."""
    if task.regime not in REGIMES:
        raise UserError(f"{task.id}: the symbolic domain has no regime {task.regime!r}")
    env = task.make_env(goal)
    base = env.unwrapped
    graph = plan_graph(base.model, base.goal_mask, base.model.init)
    demos = []
    for _ in range(n):
        plan = demo_plan(task, graph, base.model, rng)
        if len(plan) > base.max_steps:
            raise UserError(f"a {len(plan)}-action demonstration does not fit the horizon {base.max_steps} (max_steps)")
        demos.append(rollout(env, lambda obs, t: plan[t], require_success=True))
    env.close()
    return demos
