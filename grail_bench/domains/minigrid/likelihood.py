"""The MiniGrid demonstrators as probability models: what the Bayes ceiling needs.

A demonstration of one goal is a shortest path (uniform among all of them, or
the one preferred route of the biased regime) with, before each path action
and with probability ``turn_prob``, one of the regime's turn insertions. An
observation is a sequence of ``(x, y, direction, action)`` pairs picked by an
observation protocol from the path up to the goal, or from the whole padded
horizon, where the agent stays on the goal. :class:`GoalDemonstrator` gives:

* the exact support of the demonstrator when it is small (optimal, biased);
* samples of observations, drawn exactly as the harness draws them;
* the exact likelihood of an observation, summed over every path and every
  insertion pattern without enumerating the insertions: a prefix is parsed
  against each path, a subset by dynamic programming.

The dynamics are deterministic, so the state after the last observed pair is
implied by it and is left out of an observation.
"""

from __future__ import annotations

from math import comb, fsum
from typing import TYPE_CHECKING, Iterator

import numpy as np

from grail_bench.domains.minigrid.demos import all_shortest_paths, insert_turns, route, sample_shortest_path, test_env
from grail_bench.domains.minigrid.grid import STAY, TURN_PATTERNS, GridModel, State
from grail_bench.task.observation import Selection, n_observed

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

Pair = tuple[int, int, int, int]  # x, y, direction, action
Observation = tuple[Pair, ...]


class GoalDemonstrator:
    """One goal's demonstrator under a task's regime.

    Args:
        task: A MiniGrid task.
        goal: One of its goals.
    """

    action_size = 1

    def __init__(self, task: GRTask, goal: Goal) -> None:
        env = test_env(task, goal)  # the room of the test demonstrations (its test_obstacles, if any)
        base = env.unwrapped
        self.model: GridModel = base.model
        self.start: State = (*base.start, base.start_dir)
        self.horizon: int = int(base.max_steps)
        env.close()
        self.goal = (int(goal[0]), int(goal[1]))
        self.regime = task.regime
        one = route(task, goal, self.model, self.start)
        self.fixed = one is not None  # every demonstration follows one path (else each draws its own)
        self.paths = [one] if self.fixed else all_shortest_paths(self.model, self.start, self.goal)
        suboptimal = task.regime == "suboptimal"
        self.turn_prob = float(task.params["turn_prob"]) if suboptimal else 0.0
        self.pattern = task.params["turn_pattern"] if suboptimal else None
        self.patterns = TURN_PATTERNS[self.pattern] if suboptimal else ()
        # Per path: the pairs of each of its actions with and without insertions, its stay-on-goal pair, and
        # every pair it can show.
        self._models = []
        for path in self.paths:
            blocks, pad_pair = self._path_blocks(path), self.goal_pair(path)
            shown = {pad_pair, *(p for own, insertions in blocks for p in [*own, *sum(insertions, [])])}
            self._models.append((blocks, pad_pair, frozenset(shown)))

    # -- the demonstrator's support and samples -------------------------------------------------------------

    @property
    def enumerable(self) -> bool:
        """Whether no insertions can happen, so the support is just the paths."""
        return self.turn_prob == 0.0

    def pairs(self, actions: list[int]) -> list[Pair]:
        """The ``(x, y, direction, action)`` pairs of an action sequence played from the start."""
        out, s = [], self.start
        for a in actions:
            out.append((*s, a))
            s = self.model.step(s, a)
        return out

    def goal_pair(self, actions: list[int], pairs: list[Pair] | None = None) -> Pair:
        """The pair repeated after the goal: the final state, staying (from ``pairs`` if already walked)."""
        pairs = self.pairs(actions) if pairs is None else pairs
        s = self.model.step(pairs[-1][:3], pairs[-1][3]) if pairs else self.start
        return (*s, STAY)

    def support(self) -> Iterator[tuple[list[int], float]]:
        """Every demonstration (action sequence) with its probability; only without insertions."""
        if not self.enumerable:
            raise ValueError("the support of a demonstrator with random turn insertions is not enumerated")
        weight = 1.0 / len(self.paths)
        for path in self.paths:
            yield list(path), weight

    def sample(self, rng: np.random.Generator) -> list[int]:
        """One demonstration's actions up to the goal, drawn as the task's generator draws it."""
        if self.fixed:
            path = list(self.paths[0])
        else:
            path = sample_shortest_path(self.model, self.start, self.goal, rng)
        if self.regime == "suboptimal":
            path = insert_turns(path, self.turn_prob, rng, self.pattern)
        return path

    def span(self, actions: list[int], selection: Selection) -> list[Pair]:
        """The pairs a protocol samples from: the path, plus the stay-on-goal padding for horizon protocols."""
        pairs = self.pairs(actions)
        if selection.horizon:
            pairs += [self.goal_pair(actions, pairs)] * (self.horizon - len(pairs))
        return pairs

    def observations(self, actions: list[int], selection: Selection) -> Iterator[tuple[Observation, float]]:
        """Every observation of one demonstration with its probability under the protocol."""
        return selection.observations(self.span(actions, selection))

    def sample_observation(self, rng: np.random.Generator, selection: Selection) -> Observation:
        """A demonstration and then its observation, both drawn as the harness draws them."""
        return selection.sample(self.span(self.sample(rng), selection), rng)

    # -- exact likelihood ---------------------------------------------------------------------------------

    def _path_blocks(self, path: list[int]) -> list[tuple[list[Pair], list[list[Pair]]]]:
        """Per path action: its own pair, and the pairs of each insertion followed by it."""
        blocks, s = [], self.start
        for a in path:
            insertions = []
            for pattern in self.patterns:
                pairs, t = [], s
                for turn in pattern:
                    pairs.append((*t, turn))
                    t = self.model.step(t, turn)
                insertions.append([*pairs, (*s, a)])  # the pattern leaves the heading as it was
            blocks.append(([(*s, a)], insertions))
            s = self.model.step(s, a)
        return blocks

    def likelihood(self, observation: Observation, selection: Selection) -> float:
        """Probability that this goal's demonstrator yields ``observation`` under the protocol."""
        if selection.random_subset:
            matches, observed = _matches(observation), set(observation)
            total = sum(self._subset_likelihood(blocks, pad_pair, observation, matches, selection)
                        for blocks, pad_pair, shown in self._models if observed <= shown)  # else impossible
        else:
            total = sum(self._prefix_likelihood(blocks, pad_pair, observation, selection)
                        for blocks, pad_pair, _ in self._models)
        return total / len(self.paths)

    def _padding(self, n: int, k: int, sel: Selection) -> int | None:
        """The stay-on-goal pairs after a demonstration of ``n`` pairs, or None when it cannot yield an
        observation of ``k`` pairs (longer than the horizon, or observed with another count)."""
        pad = self.horizon - n if sel.horizon else 0
        if pad < 0 or n_observed(sel.level, n + pad, sel.rounding) != k:
            return None
        return pad

    def _prefix_likelihood(self, blocks: list, pad_pair: Pair, obs: Observation, sel: Selection) -> float:
        # A prefix is parsed against the path: at each path action the observation continues either with the
        # action's own pair or with one of the insertions, so only a few insertion counts m stay alive. Once
        # the observation is used up, the remaining actions are free and m grows binomially.
        k, length = len(obs), len(blocks)
        step = len(self.patterns[0]) if self.patterns else 0
        share = self.turn_prob / len(self.patterns) if self.patterns else 0.0

        def free(m: int, done: int) -> float:
            """Probability that the actions after the first ``done`` give a length observed as k pairs."""
            rest = length - done
            return fsum(comb(rest, i) * self.turn_prob ** i * (1.0 - self.turn_prob) ** (rest - i)
                        for i in range(rest + 1) if self._padding(length + (m + i) * step, k, sel) is not None)

        out, alive = 0.0, {0: 1.0}  # insertions so far -> probability that every pair so far was observed
        for i, (own, insertions) in enumerate(blocks):
            nxt: dict[int, float] = {}
            for m, prob in alive.items():
                pos = i + m * step
                if pos >= k:
                    out += prob * free(m, i)
                    continue
                if own[0] == obs[pos] and self.turn_prob < 1.0:  # (turns before every action: never)
                    nxt[m] = nxt.get(m, 0.0) + (1.0 - self.turn_prob) * prob
                for pairs in insertions:
                    if tuple(pairs[:k - pos]) == obs[pos:pos + len(pairs)]:
                        nxt[m + 1] = nxt.get(m + 1, 0.0) + share * prob
            alive = nxt
        for m, prob in alive.items():  # every action emitted
            n = length + m * step
            if n >= k:
                out += prob * free(m, length)
            elif self._padding(n, k, sel) is not None and all(p == pad_pair for p in obs[n:]):
                out += prob  # the rest of the observation is the padding
        return out

    def _subset_likelihood(self, blocks: list, pad_pair: Pair, obs: Observation, matches: dict[Pair, np.ndarray],
                           sel: Selection) -> float:
        # a[m, j]: probability mass of demonstrations with m insertions so far, weighted by the number of
        # ways the pairs emitted so far match the first j observed pairs.
        k, length = len(obs), len(blocks)
        a = np.zeros((length + 1, k + 1))
        a[0, 0] = 1.0
        share = self.turn_prob / len(self.patterns) if self.patterns else 0.0
        for own, insertions in blocks:
            nxt = (1.0 - self.turn_prob) * _emit(a, own, matches)
            for pairs in insertions:
                nxt[1:] += share * _emit(a, pairs, matches)[:-1]
            a = nxt
        step = len(self.patterns[0]) if self.patterns else 0
        out = 0.0
        for m in range(length + 1):
            n = length + m * step
            pad = self._padding(n, k, sel)
            if pad is None:
                continue
            mass = 0.0
            for j in range(k + 1):  # the last k - j observed pairs fall in the padding
                if a[m, j] != 0.0 and all(p == pad_pair for p in obs[j:]):
                    mass += a[m, j] * comb(pad, k - j)
            out += mass / comb(n + pad, k)  # each size-k index set of the span is equally likely
        return out


def _emit(a: np.ndarray, pairs: list[Pair], matches: dict[Pair, np.ndarray]) -> np.ndarray:
    """The subset table after emitting ``pairs``: each may be skipped or, where observed, matched next."""
    for pair in pairs:
        match = matches.get(pair)
        if match is not None:  # else a pair the observation never shows: it is skipped
            b = a.copy()
            b[:, 1:] += a[:, :-1] * match
            a = b
    return a


def _matches(obs: Observation) -> dict[Pair, np.ndarray]:
    """Per distinct observed pair, the indicator of the observed positions that show it."""
    return {pair: np.array([o == pair for o in obs], dtype=float) for pair in set(obs)}
