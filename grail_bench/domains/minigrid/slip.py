"""The MiniGrid demonstrators in a slipping room (``test_slip``), as exact probability models for the Bayes ceiling.

In a room where each step executes, with probability ``test_slip``, one of the three other actions drawn
uniformly, the demonstrator acts in closed loop (see :mod:`.demos`): it follows its plan, and plans anew by
its regime's rule where a slip leaves it off the plan. A demonstration is then a whole fixed-horizon episode of
``(x, y, direction, action)`` pairs, the action recorded being the demonstrator's, whatever the room executed.
:class:`SlipDemonstrator` enumerates every episode with its probability (every plan draw, every insertion
pattern, every slip outcome), so its likelihood is exact; the episodes multiply with the horizon and the slip,
so it is tractable on small rooms and short horizons only and refuses, in one line, beyond
:data:`MAX_BRANCHES`. Where the demonstrator acts by its state alone (``optimal`` drawing paths uniformly,
``biased``), :class:`MarkovSlipDemonstrator` gives the same likelihood in any room by dynamic programming
(the Monte Carlo ceiling's); the others have no ceiling beyond the enumeration.
"""

from __future__ import annotations

import json
from math import comb
from typing import TYPE_CHECKING, Iterator

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.minigrid.demos import optimal_successors, route, shortest_path_graph, test_env
from grail_bench.domains.minigrid.grid import STAY, TURN_PATTERNS, GridModel, State
from grail_bench.task.observation import Selection, n_observed

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

N_ACTIONS = 4
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
        self.dist, self.count = shortest_path_graph(self.model, self.goal)
        self.reach = self.dist
        suboptimal = task.regime == "suboptimal"
        self.turn_prob = float(task.params["turn_prob"]) if suboptimal else 0.0
        self.patterns = TURN_PATTERNS[task.params["turn_pattern"]] if suboptimal else ()
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

    # -- the closed-loop demonstrator, its draws made when they are needed ------------------------------------
    # Drawing a plan whole (a shortest path, then an insertion before each of its actions) and drawing each piece
    # as the demonstrator reaches it give the same distribution: the path's next action uniformly among shortest
    # paths is each optimal successor weighted by the shortest paths through it, and the insertions are drawn
    # independently per action. Drawn lazily, the branches stay few.

    def fresh(self, state: State) -> tuple[tuple[int, ...] | None, tuple[int, ...], bool]:
        """The demonstrator's plan state from ``state``: its one route (None: drawn step by step), no turns
        pending, the insertion before its next action not drawn yet."""
        one = route(self.task, self.goal_arg, self.model, state)
        return (tuple(one) if one is not None else None), (), False

    def _actions(self, state: State, base: tuple[int, ...] | None, pending: tuple[int, ...],
                 drawn: bool) -> list[tuple[int, tuple[int, ...] | None, tuple[int, ...], bool, float]]:
        """The demonstrator's next action from a plan state, each with the plan state after it and its
        probability."""
        if pending:
            return [(pending[0], base, pending[1:], True, 1.0)]
        if not drawn and self.patterns:
            out = [] if self.turn_prob == 1.0 else self._actions(state, base, (), True)
            out = [(a, b, q, d, p * (1.0 - self.turn_prob)) for a, b, q, d, p in out]
            share = self.turn_prob / len(self.patterns)
            return out + [(pattern[0], base, tuple(pattern[1:]), True, share) for pattern in self.patterns]
        if base is not None:
            return [(base[0], base[1:], (), False, 1.0)] if base else [(STAY, base, (), False, 1.0)]
        if self.dist[state] == 0:
            return [(STAY, None, (), False, 1.0)]
        succ = optimal_successors(self.model, self.dist, state)
        total = sum(self.count[s] for s in succ.values())
        return [(a, None, (), False, self.count[s] / total) for a, s in sorted(succ.items())]

    def _enumerate(self) -> dict[Episode, float]:
        """Every episode with its probability, by walking the closed loop's branches (draws and slips)."""
        out: dict[Episode, float] = {}
        # (pairs so far as a linked list (earlier, pair), their count, state, plan state, expected state,
        # steps up to the goal or None, probability)
        stack = [(None, 0, self.start, self.fresh(self.start), None, None, 1.0)]
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
            if expect is not None and state != expect:  # a slip left the plan: plan anew from here
                plan = self.fresh(state)
            if state in self.reach:
                actions = self._actions(state, *plan)
            else:  # cut off from the goal: the demonstrator stays (the room may still slip)
                actions = [(STAY, *plan, 1.0)]
            for action, base, pending, drawn, share in actions:
                nxt_expect = self.model.step(state, action)
                for nxt, p in self.model.transition(state, action, self.slip).items():
                    hit = reached if reached is not None else (t + 1 if nxt[:2] == self.goal else None)
                    stack.append(((pairs, (*state, action)), t + 1, nxt, (base, pending, drawn), nxt_expect, hit,
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


class MarkovSlipDemonstrator:
    """A demonstrator whose action depends on its state only (``optimal`` drawing its paths uniformly,
    ``biased``) in the slipping test room, for rooms too large to enumerate: its likelihood is exact, by
    dynamic programming over time, state and observed pairs matched (the Monte Carlo ceiling's).

    In these regimes planning anew after a slip is acting by the same policy from the new state: the next
    action of a uniformly drawn shortest path is each optimal successor weighted by the shortest paths through
    it, and the route a heading order prefers from a state on it continues that route.

    Args:
        task: A MiniGrid task whose test parameters set ``test_slip``, in a Markov regime (see :func:`markov`).
        goal: One of its goals.
    """

    action_size = 1
    enumerable = False

    def __init__(self, task: GRTask, goal: Goal) -> None:
        env = test_env(task, goal)
        base = env.unwrapped
        model: GridModel = base.model
        self.start: State = (*base.start, base.start_dir)
        self.horizon = int(base.max_steps)
        slip = float(base.slip)
        env.close()
        g = (int(goal[0]), int(goal[1]))
        dist, count = shortest_path_graph(model, g)
        self.states = model.states()
        self.index = {s: i for i, s in enumerate(self.states)}
        n = len(self.states)
        self.policy = np.zeros((n, N_ACTIONS))
        self.moves = np.zeros((N_ACTIONS, n, n))  # moves[a, s, s']: the room's transition
        self.goal_states = np.array([s[:2] == g for s in self.states])
        for i, s in enumerate(self.states):
            absorbed = s[:2] == g or s[:2] in model.lava
            if absorbed or s not in dist:
                self.policy[i, STAY] = 1.0
            else:
                one = route(task, goal, model, s)
                if one is not None:
                    self.policy[i, one[0]] = 1.0
                else:
                    succ = optimal_successors(model, dist, s)
                    total = sum(count[t] for t in succ.values())
                    for a, t in succ.items():
                        self.policy[i, a] = count[t] / total
            for a in range(N_ACTIONS):
                outcomes = {s: 1.0} if absorbed else model.transition(s, a, slip)
                for t, p in outcomes.items():
                    self.moves[a, i, self.index[t]] += p
        from scipy.sparse import csr_matrix

        self._moved_by = [csr_matrix(self.moves[a].T) for a in range(N_ACTIONS)]  # a few successors per state

    def _episode(self, rng: np.random.Generator) -> Episode:
        """One episode drawn as the closed-loop demonstrator plays it."""
        i, pairs, reached = self.index[self.start], [], None
        for t in range(self.horizon):
            a = int(rng.choice(N_ACTIONS, p=self.policy[i]))
            pairs.append((*self.states[i], a))
            i = int(rng.choice(len(self.states), p=self.moves[a, i]))
            if reached is None and self.goal_states[i]:
                reached = t + 1
        return tuple(pairs), self.horizon if reached is None else reached

    def sample_observation(self, rng: np.random.Generator, selection: Selection) -> tuple:
        """An episode and then its observation, drawn as the harness draws them."""
        pairs, reached = self._episode(rng)
        return selection.sample(pairs if selection.horizon else pairs[:reached], rng)

    def likelihood(self, observation: tuple, selection: Selection) -> float:
        """Probability that this goal's demonstrator yields ``observation`` under the protocol."""
        k = len(observation)
        observed = []
        for pair in observation:
            state = tuple(int(c) for c in pair[:3])
            if state not in self.index:
                return 0.0
            observed.append((self.index[state], int(pair[3])))
        mass = np.zeros((len(self.states), k + 1))  # probability x ways the pairs so far spell the first j
        mass[self.index[self.start], 0] = 1.0
        total = 0.0

        def ends(n: int, m: np.ndarray) -> float:
            """What spans of ``n`` pairs, with ``m`` their mass, add to the likelihood."""
            if n_observed(selection.level, n, selection.rounding) != k:
                return 0.0
            return float(m[:, k].sum()) / (comb(n, k) if selection.random_subset else 1)

        for t in range(self.horizon):
            nxt = np.zeros_like(mass)
            for a in range(N_ACTIONS):
                acted = mass * self.policy[:, a:a + 1]
                if selection.random_subset:
                    emitted = acted.copy()
                    for j, (s, b) in enumerate(observed):
                        if b == a:
                            emitted[s, j + 1] += acted[s, j]
                elif t < k:  # a prefix: pair t must be observed pair t
                    emitted = np.zeros_like(acted)
                    s, b = observed[t]
                    if b == a:
                        emitted[s, t + 1] = acted[s, t]
                else:
                    emitted = acted
                nxt += self._moved_by[a] @ emitted
            if not selection.horizon:  # the span ends where the goal is reached
                total += ends(t + 1, nxt[self.goal_states])
                nxt[self.goal_states] = 0.0
            mass = nxt
        return total + ends(self.horizon, mass)


def markov(task: GRTask) -> bool:
    """Whether the task's demonstrator acts by its state alone (see :class:`MarkovSlipDemonstrator`)."""
    return task.regime == "biased" or (task.regime == "optimal" and task.params.get("route_choice") != "fixed")
