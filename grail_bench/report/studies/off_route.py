"""Off-route behaviour on MiniGrid: F1 of hand-built per-goal policies that differ only off their goal's route.

Each goal's policy copies its training demonstrations exactly on the states they visit (their empirical
actions) and does one of these elsewhere:

- ``uniform``: no preference (each of the 4 actions 1/4);
- ``goal-directed``: the actions that start a shortest path to its goal (uniform among them);
- ``forward``: always forward (a policy that extrapolates one action everywhere);
- ``avoid-others``: no preference among the actions the *other* goals' demonstrations do not take there
  (uniform where they take none or all). It is the only rule that reads other goals' demonstrations, which
  per-goal fitting never sees: it tests whether scoring actions can reach the paper's 4-goal numbers at all.

One more policy is goal-directed everywhere, its route included. Every policy mixes in 5 % of the
uniform distribution; an observed prefix scores its mean log-probability under each goal's policy, and ties
are broken at random (the harness would break exact ties towards the first goal). The recognizer is a
third-party plugin of the minimal contract (``fit`` + ``score``), registered for the study's runs only and
scored by the harness like any other; its rows stay in memory.

``grail-bench study off-route -t GRAIL/MiniGrid-Optimal-4Goals-v0 -t GRAIL/MiniGrid-Optimal-6Goals-v0``, or
with task parameters (``--param route_choice=fixed``), prints the table (10 seeds, the tasks' default protocol
and rounding).
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.minigrid.demos import optimal_successors, shortest_path_graph
from grail_bench.domains.minigrid.grid import FORWARD, STAY
from grail_bench.harness.api import evaluate
from grail_bench.recognizers.registry import register_recognizer, unregister_recognizer
from grail_bench.report.escape import md
from grail_bench.task import make_task
from grail_bench.task.observation import level_text

N_ACTIONS, EPS = 4, 0.05
NAME = "hand-built"  # the recognizer's name while the study runs
VARIANTS = {
    "route, uniform off it": {"off_route": "uniform"},
    "route, goal-directed off it": {"off_route": "goal-directed"},
    "route, forward off it": {"off_route": "forward"},
    "route, other goals' actions avoided off it": {"off_route": "avoid-others"},
    "goal-directed everywhere": {"off_route": "goal-directed", "copy_route": False},
}


class HandBuilt:
    """Per-goal tabular policies: the demonstrations' actions on their states, a fixed rule elsewhere.

    Args:
        off_route: What each policy does off its route: ``uniform``, ``goal-directed``, ``forward`` or
            ``avoid-others``.
        copy_route: Whether to copy the demonstrations' actions on their states at all.
    """

    def __init__(self, *, off_route: str = "uniform", copy_route: bool = True) -> None:
        self.config = {"off_route": off_route, "copy_route": copy_route}
        self.off_route, self.copy_route = off_route, copy_route

    def fit(self, demos: dict, env_factory: Any = None, *, seed: int = 0) -> None:
        """Tabulate each goal's route actions and keep its grid and distances to the goal."""
        self.rng = np.random.default_rng(seed)
        self.policies = {}
        for goal, trajectories in demos.items():
            cell = tuple(int(v) for v in goal)
            route: dict[tuple, np.ndarray] = {}
            for traj in trajectories if self.copy_route else ():
                for state, action in zip(traj.obs[:-1], traj.acts):
                    state = tuple(int(v) for v in state)
                    if state[:2] == cell:
                        break
                    route.setdefault(state, np.zeros(N_ACTIONS))[int(action)] += 1
            model = env_factory(goal).unwrapped.model
            self.policies[goal] = (model, cell, shortest_path_graph(model, cell)[0], route)
        self.others = {goal: [other[3] for g, other in self.policies.items() if g != goal] for goal in self.policies}

    def _probs(self, goal: Any, state: tuple) -> np.ndarray:
        model, cell, dist, route = self.policies[goal]
        p = np.zeros(N_ACTIONS)
        if state in route:
            p = route[state] / route[state].sum()
        elif self.off_route == "uniform":
            p[:] = 1 / N_ACTIONS
        elif self.off_route == "forward":
            p[FORWARD] = 1
        elif self.off_route == "avoid-others":
            taken = np.zeros(N_ACTIONS, dtype=bool)
            for other in self.others[goal]:
                if state in other:
                    taken |= other[state] > 0
            p[:] = 1 if taken.all() or not taken.any() else ~taken
            p /= p.sum()
        elif state[:2] == cell:
            p[STAY] = 1
        else:  # goal-directed: every action one step closer to the goal
            p[list(optimal_successors(model, dist, state))] = 1
            p /= p.sum()
        return (1 - EPS) * p + EPS / N_ACTIONS

    def score(self, observed: Any) -> dict:
        """Each goal's mean log-probability of the observed pairs, plus a tiny random tie-break."""
        pairs = [(tuple(int(v) for v in s), int(a)) for s, a in zip(observed.obs, observed.acts)]
        return {goal: float(np.mean([np.log(self._probs(goal, s)[a]) for s, a in pairs])) + 1e-9 * self.rng.random()
                for goal in self.policies}


def run(tasks: Sequence[str], params: Mapping[str, Any] | None = None, seeds: int = 10) -> str:
    """Each hand-built policy's F1 at each of a task's levels, as a Markdown table.

    Args:
        tasks: MiniGrid task IDs, in the table's order.
        params: Task parameters for every task (as ``gym.make`` takes them), e.g. ``{"route_choice": "fixed"}``.
        seeds: Seeds ``0 .. seeds - 1`` of every cell.

    Returns:
        One row per task and policy, after the header.

    Raises:
        UserError: Without a task, for a task outside MiniGrid, or for a parameter or seed count the harness
            refuses.
    """
    if not tasks:
        raise UserError("study off-route needs at least one MiniGrid task")
    for task in tasks:
        domain = make_task(task).domain
        if domain != "minigrid":
            raise UserError(f"study off-route builds MiniGrid policies; {task} is a {domain} task")
    register_recognizer(NAME, HandBuilt)
    try:
        lines = [f"| task | policy | F1 at each level ({seeds} seeds) |\n|---|---|---|"]
        for task in tasks:
            for name, config in VARIANTS.items():
                records = evaluate(task, [(NAME, config)], seeds=seeds, task_params=dict(params or {}))
                levels = " / ".join(f"{level_text(r.observability)}: {r.f1.mean:.2f}" for r in records)
                lines.append(f"| {md(task.removeprefix('GRAIL/'))} | {md(name)} | {levels} |")
    finally:
        unregister_recognizer(NAME)
    return "\n".join(lines) + "\n"
