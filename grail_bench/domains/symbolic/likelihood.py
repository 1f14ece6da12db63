"""The symbolic demonstrators as probability models, for the Bayes ceiling (``optimal`` and ``biased``).

A demonstration of one goal is an optimal plan: uniform among all of them
(``optimal``), or the lexicographically first (``biased``). Both supports are
enumerable from the optimal-plan DAG. An observation is a sequence of
``(state, operator)`` pairs a protocol picks from the plan (the env ends at the
goal, so the span is the plan under every protocol); the likelihood of an
ordered subset counts its embeddings in each plan.
"""

from __future__ import annotations

from math import comb
from typing import TYPE_CHECKING, Iterator

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.demos import plan_graph
from grail_bench.task.observation import Selection, n_observed

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

Pair = tuple[int, int]  # state, operator
Observation = tuple[Pair, ...]
#: Largest number of optimal plans the support enumerates.
MAX_PLANS = 100_000
LIKELIHOOD_REGIMES = ("optimal", "biased")


class GoalDemonstrator:
    """One goal's demonstrator under a task's regime.

    Raises:
        UserError: For the ``suboptimal`` regime (its likelihood is not stated) or more than
            :data:`MAX_PLANS` optimal plans.
    """

    action_size = 1
    enumerable = True

    def __init__(self, task: GRTask, goal: Goal) -> None:
        if task.regime not in LIKELIHOOD_REGIMES:
            raise UserError(f"{task.id}: the symbolic demonstrator's likelihood is stated for the "
                            f"{' and '.join(LIKELIHOOD_REGIMES)} regimes, not {task.regime!r}")
        env = task.make_env(goal)
        base = env.unwrapped
        env.close()
        self.model, self.regime = base.model, task.regime
        self.graph = plan_graph(base.model, base.goal_mask, base.model.init)
        if self.regime == "biased":
            self.plans = [tuple(self.graph.first())]
        else:
            if self.graph.n_plans > MAX_PLANS:
                raise UserError(f"{task.id}: goal {list(goal)} has {self.graph.n_plans} optimal plans; the exact "
                                f"likelihood enumerates at most {MAX_PLANS}")
            self.plans = [tuple(p) for p in self.graph.plans()]
        self._spans = {plan: self.pairs(plan) for plan in self.plans}
        # pair -> the plans (by position) that hold it: an observation is scored only against the plans holding
        # every observed pair (the others contribute exactly 0), so a grid's thousands of plans stay fast
        self._span_list = list(self._spans.values())
        self._holding: dict[Pair, set[int]] = {}
        for i, pairs in enumerate(self._span_list):
            for pair in pairs:
                self._holding.setdefault(pair, set()).add(i)

    def pairs(self, plan: tuple[int, ...]) -> list[Pair]:
        """The ``(state, operator)`` pairs of a plan played from the initial state."""
        states = self.model.plan_states(plan)
        return list(zip(states[:-1], plan))

    def support(self) -> Iterator[tuple[tuple[int, ...], float]]:
        """Every demonstration (plan) with its probability."""
        weight = 1.0 / len(self.plans)
        for plan in self.plans:
            yield plan, weight

    def sample(self, rng: np.random.Generator) -> tuple[int, ...]:
        """One demonstration's plan, drawn as the task's generator draws it."""
        return self.plans[0] if self.regime == "biased" else tuple(self.graph.sample(rng))

    def span(self, plan: tuple[int, ...], selection: Selection) -> list[Pair]:
        """The pairs a protocol samples from: the whole plan (episodes end at the goal)."""
        return self._spans[plan] if plan in self._spans else self.pairs(plan)

    def observations(self, plan: tuple[int, ...], selection: Selection) -> Iterator[tuple[Observation, float]]:
        """Every observation of one plan with its probability under the protocol."""
        return selection.observations(self.span(plan, selection))

    def sample_observation(self, rng: np.random.Generator, selection: Selection) -> Observation:
        """A demonstration and then its observation, both drawn as the harness draws them."""
        return selection.sample(self.span(self.sample(rng), selection), rng)

    def likelihood(self, observation: Observation, selection: Selection) -> float:
        """Probability that this goal's demonstrator yields ``observation`` under the protocol."""
        total = 0.0
        k = len(observation)
        spans = self._span_list
        holding = [self._holding.get(pair, set()) for pair in set(observation)]
        candidates = sorted(set.intersection(*holding)) if holding else range(len(spans))
        for pairs in (spans[i] for i in candidates):
            n = len(pairs)
            if n_observed(selection.level, n, selection.rounding) != k:
                continue
            if selection.random_subset:
                total += _embeddings(pairs, observation) / comb(n, k)
            else:
                total += float(tuple(pairs[:k]) == tuple(observation))
        return total / len(self.plans)


def _embeddings(pairs: list[Pair], observation: Observation) -> int:
    """How many index sets pick ``observation`` out of ``pairs`` in order."""
    ways = [1] + [0] * len(observation)  # ways[j]: embeddings of the first j observed pairs so far
    for pair in pairs:
        for j in range(len(observation), 0, -1):
            if observation[j - 1] == pair:
                ways[j] += ways[j - 1]
    return ways[-1]
