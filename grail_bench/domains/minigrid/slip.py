"""The MiniGrid demonstrators in a slipping room (``test_slip``), as exact probability models for the Bayes ceiling.

In a room where each step executes, with probability ``test_slip``, one of the three other actions drawn
uniformly, the demonstrator acts in closed loop (see :mod:`.demos`): it follows its plan, and plans anew by
its regime's rule where a slip leaves it off the plan. A demonstration is then a whole fixed-horizon episode of
``(x, y, direction, action)`` pairs, the action recorded being the demonstrator's, whatever the room executed.
:class:`SlipDemonstrator` enumerates every episode with its probability (every plan draw, every insertion
pattern, every slip outcome), so its likelihood is exact; the episodes multiply with the horizon and the slip,
so it is tractable on small rooms and short horizons only and refuses, in one line, beyond
:data:`MAX_BRANCHES`.
"""

from __future__ import annotations

import itertools
import json
from math import comb
from typing import TYPE_CHECKING, Iterator

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.minigrid.demos import (
    all_shortest_paths,
    route,
    shortest_path_graph,
    test_env,
)
from grail_bench.domains.minigrid.grid import STAY, TURN_PATTERNS, GridModel, State
from grail_bench.task.observation import Selection, n_observed

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

Pair = tuple[int, int, int, int]
Episode = tuple[tuple[Pair, ...], int]  # the horizon's pairs, and how many of them lead up to the goal
#: Most branches (steps of partial episodes) one goal's demonstrator walks before the ceiling is refused as
#: intractable (about two seconds; a refusal is remembered for the rest of the process).
MAX_BRANCHES = 100_000
_refused: dict[str, str] = {}  # the demonstrators found intractable, by key: their refusal


class SlipDemonstrator:
    """One goal's demonstrator in the task's slipping test room (a task's ``test_task()``).

    Args:
        task: A MiniGrid task whose test parameters set ``test_slip``.
        goal: One of its goals.

    Raises:
        UserError: When its episodes take more than :data:`MAX_BRANCHES` steps to enumerate.
    """

    action_size = 1
    enumerable = True

    def __init__(self, task: GRTask, goal: Goal) -> None:
        env = test_env(task, goal)
        base = env.unwrapped
        self.model: GridModel = base.model
        self.slip = float(base.slip)
        self.start: State = (*base.start, base.start_dir)
        self.horizon = int(base.max_steps)
        fixed_horizon = base.fixed_horizon
        env.close()
        if not fixed_horizon:
            raise UserError(f"{task.id}: the slipping demonstrator's likelihood is stated for fixed-horizon "
                            "episodes (fixed_horizon = true)")
        self.task, self.goal_arg = task, goal
        self.goal = (int(goal[0]), int(goal[1]))
        self.reach, _ = shortest_path_graph(self.model, self.goal)
        self._plans: dict[State, list[tuple[tuple[int, ...], float]]] = {}
        key = json.dumps([task.regime, task.params, task.env_params, task.test_params, self.goal, MAX_BRANCHES],
                         sort_keys=True, default=str)
        if key in _refused:
            raise UserError(_refused[key])
        try:
            self.episodes = self._enumerate()
        except UserError as exc:
            _refused[key] = str(exc)
            raise
        self._probs = np.array(list(self.episodes.values()))
        self._keys = list(self.episodes)

    # -- the closed-loop demonstrator's plans ----------------------------------------------------------------

    def plans(self, state: State) -> list[tuple[tuple[int, ...], float]]:
        """Every plan the regime draws from ``state`` with its probability (see :func:`.demos.plan_from`)."""
        if state not in self._plans:
            self._plans[state] = self._draws(state)
        return self._plans[state]

    def _draws(self, state: State) -> list[tuple[tuple[int, ...], float]]:
        one = route(self.task, self.goal_arg, self.model, state)
        paths = [one] if one is not None else all_shortest_paths(self.model, state, self.goal)
        base = [(tuple(p), 1.0 / len(paths)) for p in paths]
        if self.task.regime != "suboptimal":
            return base
        turn_prob = float(self.task.params["turn_prob"])
        patterns = TURN_PATTERNS[self.task.params["turn_pattern"]]
        options = [((), 1.0 - turn_prob)] * (turn_prob < 1.0) + [(p, turn_prob / len(patterns)) for p in patterns]
        out: dict[tuple[int, ...], float] = {}
        for path, weight in base:
            for choice in itertools.product(options, repeat=len(path)):
                plan = tuple(a for (turns, _), action in zip(choice, path) for a in (*turns, action))
                prob = weight
                for _, share in choice:
                    prob *= share
                out[plan] = out.get(plan, 0.0) + prob
        return list(out.items())

    def _enumerate(self) -> dict[Episode, float]:
        """Every episode with its probability, by walking the closed loop's branches (plans and slips)."""
        out: dict[Episode, float] = {}
        # (pairs so far as a linked list (earlier, pair), their count, state, plan left, expected state, steps up
        # to the goal or None, probability)
        stack = [(None, 0, self.start, plan, None, None, p) for plan, p in self.plans(self.start)]
        walked = 0
        while stack:
            walked += 1
            if walked > MAX_BRANCHES:
                raise UserError(f"{self.task.id}: the slipping demonstrator of goal {list(self.goal)} has too many "
                                f"episodes to enumerate (over {MAX_BRANCHES:,} steps); its exact likelihood is for "
                                "small rooms and short horizons")
            pairs, t, state, plan, expect, reached, prob = stack.pop()
            if t == self.horizon:
                key = (_unlink(pairs), self.horizon if reached is None else reached)
                out[key] = out.get(key, 0.0) + prob
                continue
            if state[:2] == self.goal or state[:2] in self.model.lava:  # absorbed: no move, no slip
                stack.append(((pairs, (*state, STAY)), t + 1, state, plan, None, reached, prob))
                continue
            branches = [(plan, 1.0)]
            if state not in self.reach:
                branches = [((), 1.0)]
            elif expect is not None and state != expect:  # a slip left the plan: plan anew from here
                branches = self.plans(state)
            for left, share in branches:
                action = left[0] if left else STAY
                nxt_expect = self.model.step(state, action)
                for nxt, p in self.model.transition(state, action, self.slip).items():
                    hit = reached if reached is not None else (t + 1 if nxt[:2] == self.goal else None)
                    stack.append(((pairs, (*state, action)), t + 1, nxt, left[1:], nxt_expect, hit,
                                  prob * share * p))
        return out

    # -- the GoalModel protocol ------------------------------------------------------------------------------

    def support(self) -> Iterator[tuple[Episode, float]]:
        """Every episode with its probability."""
        yield from self.episodes.items()

    def span(self, episode: Episode, selection: Selection) -> tuple[Pair, ...]:
        """The pairs a protocol samples from: the whole horizon, or those up to the goal."""
        pairs, reached = episode
        return pairs if selection.horizon else pairs[:reached]

    def observations(self, episode: Episode, selection: Selection) -> Iterator[tuple[tuple, float]]:
        """Every observation of one episode with its probability under the protocol."""
        return selection.observations(self.span(episode, selection))

    def sample_observation(self, rng: np.random.Generator, selection: Selection) -> tuple:
        """An episode and then its observation, both drawn by their probabilities."""
        episode = self._keys[int(rng.choice(len(self._keys), p=self._probs / self._probs.sum()))]
        return selection.sample(self.span(episode, selection), rng)

    def likelihood(self, observation: tuple, selection: Selection) -> float:
        """Probability that this goal's demonstrator yields ``observation`` under the protocol."""
        return sum(p * observation_prob(self.span(e, selection), observation, selection)
                   for e, p in self.episodes.items())


def _unlink(pairs: tuple | None) -> tuple[Pair, ...]:
    """The pairs of a linked list ``(earlier, pair)``, in order."""
    out = []
    while pairs is not None:
        pairs, pair = pairs
        out.append(pair)
    return tuple(reversed(out))


def observation_prob(span: tuple, observation: tuple, selection: Selection) -> float:
    """Probability that a protocol observes ``observation`` of ``span``: the prefix, or the ordered subsets
    that spell it (counted by dynamic programming) among all of its size."""
    n, k = len(span), len(observation)
    if n_observed(selection.level, n, selection.rounding) != k:
        return 0.0
    if not selection.random_subset:
        return float(tuple(span[:k]) == tuple(observation))
    ways = [1] + [0] * k  # ways[j]: index sets of the span so far that spell the first j observed pairs
    for pair in span:
        for j in range(k, 0, -1):
            if observation[j - 1] == pair:
                ways[j] += ways[j - 1]
    return ways[k] / comb(n, k)
