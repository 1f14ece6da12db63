"""``prp``: plan recognition as planning (Ramírez & Geffner, AAAI 2010).

"Probabilistic plan recognition using off-the-shelf classical planners" scores a candidate goal ``G`` by
how much more an optimal plan for ``G`` costs when it must embed the observed actions ``O`` than when it
must not:

* ``c(G, O)``: the cost of an optimal plan for ``G`` that embeds ``O`` (its actions appear in the plan in
  order, as a subsequence, other actions between them allowed);
* ``c(G, ¬O)``: the cost of an optimal plan for ``G`` that does not embed ``O``;
* ``Δ = c(G, O) − c(G, ¬O)`` and ``P(O | G) = 1 / (1 + exp(β Δ))`` (a Boltzmann likelihood; ``β = 1`` as
  the paper's default, :attr:`PRPConfig.beta`); the score is ``log P(O | G) + log P(G)`` with a uniform
  prior, so ``softmax`` of the scores is the paper's posterior ``P(G | O)``.

Infinite costs, as the paper treats them: when no plan for ``G`` embeds ``O``, ``Δ = ∞`` and ``P(O | G) = 0``;
when every plan for ``G`` embeds ``O``, ``Δ = −∞`` and ``P(O | G) = 1``. The harness needs finite scores,
so ``log 0`` is :data:`LOG_ZERO`, below any score a finite ``Δ`` gives.

The paper compiles ``O`` into the planning problem (a fluent ``p_i`` per observation, set by the
``i``-th observed action through a conditional effect when ``p_{i-1}`` holds) and calls an off-the-shelf
planner twice, on the goals ``G ∧ p_m`` and ``G ∧ ¬p_m``. Here both costs are exact: an A* search over the
product of the model's states and ``j``, the number of observations matched so far (the compiled problem's
``p_j``); taking an action advances ``j`` when it is the next observed one (matching greedily, as the
conditional effects do, decides embedding exactly: a plan embeds ``O`` iff greedy matching reaches ``m``).
Its heuristic is the planner's h_max on the model part (admissible and consistent), raised to ``m − j``
for ``c(G, O)`` (each unmatched observation costs an action); the searches stop with a one-line error after
:attr:`PRPConfig.node_limit` expanded nodes.

It reads the observed actions only (``channels = {"pairs", "actions"}``) and learns nothing from
demonstrations: ``fit`` reads the grounded model and the goals' state masks from the task's envs, and a task
of another domain is refused where the run is planned (``check_task``). Nothing is learnt per goal, so ``set_goals`` takes any of the task's
hypotheses, fitted or not (zero-shot goals).
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass
from typing import Annotated, Any, Callable, Mapping, Sequence

import numpy as np

from grail_bench.contrib.strips_base import StripsRecognizer
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Goal
from grail_bench.domains.symbolic.planner import NODE_LIMIT, hmax
from grail_bench.domains.symbolic.strips import StripsModel

#: ``log P(O | G)`` when ``P(O | G) = 0`` (no plan for ``G`` embeds ``O``): finite, below any finite Δ's.
LOG_ZERO = -1e9

INF = float("inf")


@dataclass(frozen=True)
class PRPConfig:
    """Plan recognition as planning's settings.

    Attributes:
        beta: The likelihood's rationality ``β`` in ``P(O | G) = 1 / (1 + exp(β Δ))`` (the paper's default: 1).
        node_limit: Nodes (model state, observations matched) one cost search may expand.
    """

    beta: float = 1.0
    node_limit: Annotated[int, Range(1, 10_000_000)] = NODE_LIMIT

    def __post_init__(self) -> None:
        if not (math.isfinite(self.beta) and self.beta > 0):
            raise UserError(f"beta must be a positive number, got {self.beta}")
        if self.node_limit < 1:
            raise UserError(f"node_limit must be a positive integer, got {self.node_limit}")


def embedding_cost(model: StripsModel, goal: int, observed: Sequence[int], *, embed: bool,
                   h: Callable[[int], float] | None = None, node_limit: int = NODE_LIMIT) -> float:
    """``c(G, O)`` (``embed=True``) or ``c(G, ¬O)`` (``embed=False``), exactly, from the model's initial state.

    Args:
        model: The grounded model.
        goal: The goal's state mask.
        observed: The observed operators ``O``, in order.
        embed: Whether the plan must embed ``O`` as a subsequence, or must not.
        h: An admissible, consistent estimate of a state's cost to ``goal`` (default: h_max).
        node_limit: Nodes the search may expand.

    Returns:
        The optimal cost, or ``inf`` when no such plan exists.

    Raises:
        UserError: After ``node_limit`` expanded nodes, in one line.
    """
    h = h or (lambda s: hmax(model, s, goal))
    m = len(observed)

    def estimate(s: int, j: int) -> float:
        hs = h(s)
        return max(hs, m - j) if embed else hs

    start = (model.init, 0)
    h0 = estimate(*start)
    if h0 == INF:
        return INF
    tie = itertools.count()
    best: dict[tuple[int, int], int] = {start: 0}
    frontier = [(h0, next(tie), 0, start)]
    closed: set[tuple[int, int]] = set()
    while frontier:
        _, _, cost, node = heapq.heappop(frontier)
        if node in closed:
            continue
        s, j = node
        if s & goal == goal and (j == m) == embed:
            return float(cost)
        closed.add(node)
        if len(closed) > node_limit:
            raise UserError(f"prp: a cost search expanded its node limit of {node_limit} (state, observations "
                            "matched) nodes without proving an optimal cost (problem too large; raise node_limit)")
        for op, nxt in model.successors(s):
            child = (nxt, j + 1 if j < m and op == observed[j] else j)
            if cost + 1 < best.get(child, cost + 2):
                hc = estimate(*child)
                if hc == INF:
                    continue
                best[child] = cost + 1
                heapq.heappush(frontier, (cost + 1 + hc, next(tie), cost + 1, child))
    return INF


def log_likelihood(cost_with: float, cost_without: float, beta: float = 1.0) -> float:
    """``log P(O | G) = −log(1 + exp(β Δ))``, ``Δ = c(G, O) − c(G, ¬O)``; :data:`LOG_ZERO` when ``c(G, O)`` is
    infinite, 0 when only ``c(G, ¬O)`` is."""
    if cost_with == INF:
        return LOG_ZERO
    if cost_without == INF:
        return 0.0
    return -float(np.logaddexp(0.0, beta * (cost_with - cost_without)))


class PRPRecognizer(StripsRecognizer):
    """Plan recognition as planning: each goal's likelihood from the cost difference of embedding ``O`` or not.

    Settings: :class:`PRPConfig`. ``fit`` needs no demonstrations (it reads the model from ``env_factory``);
    scores are ``log P(O | G) + log(1 / K)`` (see the module docstring).
    """

    name = "prp"
    paper_name = "PRP (Ramírez & Geffner 2010)"
    Config = PRPConfig
    config: PRPConfig

    def fitted(self) -> None:
        self._h: list[dict[int, float]] = [{} for _ in self.goals]  # h_max per goal, memoised over states
        self._costs: dict[tuple[int, tuple[int, ...]], tuple[float, float]] = {}

    def _heuristic(self, k: int) -> Callable[[int], float]:
        memo, goal, model = self._h[k], self.goal_masks[k], self.model

        def h(state: int) -> float:
            if state not in memo:
                memo[state] = hmax(model, state, goal)
            return memo[state]

        return h

    def goal_costs(self, k: int, observed: Sequence[int]) -> tuple[float, float]:
        """``(c(G, O), c(G, ¬O))`` of the ``k``-th goal (memoised per observed sequence)."""
        key = (k, tuple(observed))
        if key not in self._costs:
            h = self._heuristic(k)
            self._costs[key] = tuple(  # type: ignore[assignment]
                embedding_cost(self.model, self.goal_masks[k], observed, embed=embed, h=h,
                               node_limit=self.config.node_limit) for embed in (True, False))
        return self._costs[key]

    def costs(self, observed: Any) -> dict[Goal, tuple[float, float]]:
        """Every goal's ``(c(G, O), c(G, ¬O))`` for an observed trajectory."""
        ops = self.observed_operators(observed)
        return {goal: self.goal_costs(k, ops) for k, goal in enumerate(self.goals)}

    def score(self, observed: Any) -> Mapping[Goal, float]:
        """``log P(O | G) + log(1 / K)`` per goal, from the observed actions.

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For a malformed observation, or a search past its node limit.
        """
        prior = -math.log(len(self.goals)) if self.goals else 0.0
        return {goal: log_likelihood(c_with, c_without, self.config.beta) + prior
                for goal, (c_with, c_without) in self.costs(observed).items()}
