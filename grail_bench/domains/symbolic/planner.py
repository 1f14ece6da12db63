"""Optimal planning on a grounded :class:`~.strips.StripsModel` (unit action costs).

* :func:`astar`: one optimal plan, by A* with h_max (admissible) or the blind
  heuristic; ties are broken by insertion order, so the plan is the same every run.
* :func:`optimal_plan_graph`: every optimal plan at once, as the DAG of the
  states they visit (:class:`PlanGraph`), built by a breadth-first search pruned
  by h_max to ``depth + h_max <= optimal length``; it counts, samples and
  enumerates optimal plans.

Both stop with a one-line :class:`~grail_bench.core.errors.UserError` after
``node_limit`` expanded states, and when the goal is unreachable.
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass
from typing import Callable, Iterator, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.strips import StripsModel

NODE_LIMIT = 200_000
HEURISTICS = ("hmax", "blind")


def hmax_many(model: StripsModel, states: Sequence[int], goal: int) -> np.ndarray:
    """h_max of each state for the goal mask ``goal`` (unit costs): the first layer of the relaxed planning
    graph that holds the goal, ``inf`` where none does; all states at once, a layer per two matrix products."""
    pre, count, add = model.relaxed_arrays
    reached = model.bits(list(states))
    need = ~model.bits([goal])[0]
    h = np.full(len(reached), np.inf)
    active = np.arange(len(reached))
    layer = 0
    while active.size:
        now = reached[active]
        done = (now | need).all(axis=1)
        h[active[done]] = layer
        active, now = active[~done], now[~done]
        if not active.size:
            break
        applicable = (pre @ now.T.astype(np.float32)).T >= count
        grown = now | ((add.T @ applicable.T.astype(np.float32)).T > 0)
        moving = (grown != now).any(axis=1)  # a layer that adds nothing never reaches the goal
        active = active[moving]
        reached[active] = grown[moving]
        layer += 1
    return h


def hmax(model: StripsModel, state: int, goal: int) -> float:
    """h_max of one state for the goal mask ``goal``, as :func:`hmax_many` gives it, on bit masks (faster than
    the matrix products for a single state)."""
    reached, layer, relaxed = state, 0, model.relaxed_masks()
    while reached & goal != goal:
        grown = reached
        for pre, add in relaxed:
            if reached & pre == pre:
                grown |= add
        if grown == reached:
            return float("inf")
        reached, layer = grown, layer + 1
    return float(layer)


def _h(model: StripsModel, goal: int, heuristic: str) -> Callable[[list[int]], np.ndarray]:
    """The heuristic of a batch of states."""
    if heuristic not in HEURISTICS:
        raise UserError(f"unknown heuristic {heuristic!r}; choose one of {', '.join(HEURISTICS)}")
    if heuristic == "blind":
        return lambda states: np.array([0.0 if s & goal == goal else 1.0 for s in states])
    return lambda states: hmax_many(model, states, goal)


def _limit_error(node_limit: int) -> UserError:
    return UserError(f"the planner expanded its node limit of {node_limit} states without proving an optimal plan "
                     "(problem too large; raise node_limit)")


def astar(model: StripsModel, goal: int, start: int | None = None, *, heuristic: str = "hmax",
          node_limit: int = NODE_LIMIT) -> list[int]:
    """An optimal plan (operator indices) from ``start`` (default: the initial state) to the goal mask ``goal``.

    Raises:
        UserError: When the goal is unreachable or ``node_limit`` states were expanded.
    """
    start = model.init if start is None else start
    h = _h(model, goal, heuristic)
    tie = itertools.count()
    g: dict[int, int] = {start: 0}
    parent: dict[int, tuple[int, int]] = {}
    h0 = float(h([start])[0])
    if h0 == float("inf"):
        raise UserError("the goal is unreachable from the initial state")
    frontier = [(h0, next(tie), start)]
    closed: set[int] = set()
    while frontier:
        _, _, s = heapq.heappop(frontier)
        if s in closed:
            continue
        if s & goal == goal:
            plan = []
            while s != start:
                s, op = parent[s]
                plan.append(op)
            return plan[::-1]
        closed.add(s)
        if len(closed) > node_limit:
            raise _limit_error(node_limit)
        cost, better = g[s] + 1, {}
        for op, nxt in model.successors(s):
            if cost < g.get(nxt, cost + 1) and nxt not in better:
                better[nxt] = op
        if not better:
            continue
        for (nxt, op), hn in zip(better.items(), h(list(better))):
            if hn != float("inf"):
                g[nxt], parent[nxt] = cost, (s, op)
                heapq.heappush(frontier, (cost + hn, next(tie), nxt))
    raise UserError("the goal is unreachable from the initial state")


@dataclass(frozen=True)
class PlanGraph:
    """Every optimal plan from ``start`` to a goal, as a DAG over the states they visit.

    Attributes:
        start: The start state.
        goal: The goal mask.
        length: The optimal plan length.
        edges: State -> its ``(operator, next state)`` on some optimal plan, in operator order.
        count: State -> the number of optimal plans from it to the goal.
    """

    start: int
    goal: int
    length: int
    edges: dict[int, list[tuple[int, int]]]
    count: dict[int, int]

    @property
    def n_plans(self) -> int:
        return self.count[self.start]

    def sample(self, rng: np.random.Generator) -> list[int]:
        """One optimal plan, uniformly among all of them."""
        plan, s = [], self.start
        while s & self.goal != self.goal:
            options = self.edges[s]
            weights = np.array([self.count[n] for _, n in options], dtype=float)
            op, s = options[int(rng.choice(len(options), p=weights / weights.sum()))]
            plan.append(op)
        return plan

    def first(self) -> list[int]:
        """The lexicographically smallest optimal plan (by operator index): the ``biased`` demonstrator's."""
        plan, s = [], self.start
        while s & self.goal != self.goal:
            op, s = self.edges[s][0]
            plan.append(op)
        return plan

    def plans(self) -> Iterator[list[int]]:
        """Every optimal plan, in lexicographic order."""
        def walk(s: int) -> Iterator[list[int]]:
            if s & self.goal == self.goal:
                yield []
                return
            for op, nxt in self.edges[s]:
                for rest in walk(nxt):
                    yield [op, *rest]

        return walk(self.start)

    def step_probs(self, state: int) -> dict[int, float]:
        """The uniform demonstrator's next-operator distribution at ``state`` (a state of the graph, not a goal)."""
        total = self.count[state]
        return {op: self.count[n] / total for op, n in self.edges[state]}


def optimal_plan_graph(model: StripsModel, goal: int, start: int | None = None, *,
                       node_limit: int = NODE_LIMIT) -> PlanGraph:
    """The DAG of every optimal plan from ``start`` (default: the initial state) to the goal mask.

    Raises:
        UserError: When the goal is unreachable or ``node_limit`` states were expanded.
    """
    start = model.init if start is None else start
    length = len(astar(model, goal, start, node_limit=node_limit))
    depth: dict[int, int] = {start: 0}
    layer, forward = [start], {}
    for d in range(length):
        if len(forward) + len(layer) > node_limit:
            raise _limit_error(node_limit)
        for s in layer:
            # an edge to a state reached at an earlier depth lies on no optimal plan
            forward[s] = [(op, n) for op, n in model.successors(s) if depth.get(n, d + 1) == d + 1]
        fresh = sorted({n for s in layer for _, n in forward[s] if n not in depth})
        if fresh:
            within = hmax_many(model, fresh, goal) <= length - d - 1
            layer = [n for n, ok in zip(fresh, within) if ok]
        else:
            layer = []
        depth.update((n, d + 1) for n in layer)
    count: dict[int, int] = {s: 1 for s in layer if s & goal == goal}
    edges: dict[int, list[tuple[int, int]]] = {}
    for s in sorted(forward, key=lambda s: -depth[s]):
        kept = [(op, n) for op, n in forward[s] if n in count]
        if kept:
            edges[s], count[s] = kept, sum(count[n] for _, n in kept)
    return PlanGraph(start=start, goal=goal, length=length, edges=edges, count=count)
