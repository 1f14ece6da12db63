"""The MiniGrid demonstrators' action distributions, as tables over every state of the room.

The reference recognizer ``demonstrator`` scores with them (perfect
imitation). A demonstration is a shortest path (see :mod:`.demos`) with, in
the ``suboptimal`` regime, turn insertions before its actions. A table row is
the demonstrator's *marginal* at a state: the expected number of times it
takes each action there, over its demonstrations and their insertions,
divided by the expected number of times it is there. It is exact: shortest
paths drawn uniformly are a flow over the shortest-path graph (each optimal
successor weighted by the number of shortest paths through it), the route
regimes walk their one route, and the insertions' expected counts are added in
closed form (nothing is sampled), all in rational arithmetic, so that goals
whose demonstrators act alike at a state get identical rows there (their
scores tie exactly, as the harness's tie rule expects). Without insertions the marginal is the
demonstrator's own policy (it is Markov); with them it is not, and the
marginal is what an imitator with unlimited demonstrations would estimate.

Two supports:

* ``"demonstrated"``: the marginal of the demonstrator from the task's start
  on the states it visits with nonzero probability (its arrival state on the
  goal included, where it stays); uniform over the actions on every other
  state.
* ``"everywhere"`` (goal-directed from every state): the same on those
  states; on every other state from which the goal is reachable, the marginal
  *at that state* of the demonstrator started there, drawing its path by the
  regime's own rule from there:

  - ``optimal``, ``route_choice="uniform"``: each optimal successor, weighted
    by the number of shortest paths through it;
  - ``optimal``, ``route_choice="fixed"``: the first action of the fixed path
    from that state (straight ahead first, from that state's heading);
  - ``biased``: the first action of the path the goal's heading order prefers
    from that state (the order is the goal's, whatever the heading);
  - ``suboptimal``: the path drawn as above (uniform or fixed, per
    ``route_choice``), with the regime's turn insertions before each of its
    actions; the row counts every visit to that state, the insertions'
    intermediate headings included.

  On the goal cell (every heading) the demonstrator stays (action 3, STAY), as
  the env absorbs it there; on walls and on states that cannot reach the goal
  (cut off by obstacles), lava included (the episode ends there), the row is uniform.
"""

from __future__ import annotations

from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.spaces import n_states, state_index
from grail_bench.domains.minigrid.demos import biased_path, fixed_path, optimal_successors, route, shortest_path_graph
from grail_bench.domains.minigrid.grid import STAY, TURN_PATTERNS, GridModel, State

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

#: The support modes of :func:`demonstrator_policy`.
SUPPORTS = ("everywhere", "demonstrated")
N_ACTIONS = 4
Counts = dict[State, list[Fraction]]  # state -> expected times each action is taken there


def demonstrator_policy(task: GRTask, goal: Goal, support: str = "everywhere") -> np.ndarray:
    """The demonstrator's action probabilities of ``goal`` on every state (see the module docstring).

    Args:
        task: A MiniGrid task (any regime).
        goal: One of its goals.
        support: ``"everywhere"`` or ``"demonstrated"``.

    Returns:
        ``(S, 4)`` probabilities, row ``i`` the state whose
        :func:`~grail_bench.core.spaces.state_index` in the env's observation space is ``i``; every row sums to 1.

    Raises:
        UserError: For an unknown support or regime.
    """
    check_policy(task, support)
    env = task.make_env(goal)
    base, space = env.unwrapped, env.observation_space
    env.close()
    model: GridModel = base.model
    start: State = (*base.start, base.start_dir)
    g = (int(goal[0]), int(goal[1]))
    planner = _Planner(task, goal, model, g)
    table = np.full((n_states(space), N_ACTIONS), 1.0 / N_ACTIONS)

    def put(state: State, counts: list[Fraction]) -> None:
        total = sum(counts)
        table[int(state_index(np.array([state]), space)[0])] = [float(c / total) for c in counts]

    demonstrated = planner.counts(start, route(task, goal, model, start))
    for state, counts in demonstrated.items():
        put(state, counts)
    if support == "everywhere":
        for state in model.states():
            if state in demonstrated:
                continue
            if state[:2] == g:
                put(state, [Fraction(int(a == STAY)) for a in range(N_ACTIONS)])
            elif state in planner.dist:
                put(state, planner.counts(state, planner.path_from(state), within=state[:2])[state])
    return table


def check_policy(task: GRTask, support: str) -> None:
    """Refuse what :func:`demonstrator_policy` cannot serve, without building anything.

    Raises:
        UserError: For an unknown support or regime.
    """
    if support not in SUPPORTS:
        raise UserError(f"support must be one of {', '.join(SUPPORTS)}, got {support!r}")
    if task.regime not in ("optimal", "biased", "suboptimal", "boltzmann"):
        raise UserError(f"{task.id}: minigrid has no regime {task.regime!r}")


class _Planner:
    """One goal's demonstrator under a task's regime, from any start state."""

    def __init__(self, task: GRTask, goal: Goal, model: GridModel, g: tuple[int, int]) -> None:
        self.model, self.goal = model, g
        self.dist, self.n_paths = shortest_path_graph(model, g)
        self.order = task.params["routes"][task.goal_index(goal)] if task.regime == "biased" else None
        self.fixed = task.regime == "biased" or task.params.get("route_choice") == "fixed"
        suboptimal = task.regime == "suboptimal"
        self.turn_prob = Fraction(task.params["turn_prob"]) if suboptimal else Fraction(0)
        self.patterns = TURN_PATTERNS[task.params["turn_pattern"]] if suboptimal else ()

    def path_from(self, state: State) -> list[int] | None:
        """The one path the regime's rule takes from ``state``, or None when the path is drawn uniformly."""
        if self.order is not None:
            return biased_path(self.model, state, self.goal, self.order)
        if self.fixed:
            return fixed_path(self.model, state, self.goal)
        return None

    def path_flow(self, start: State, path: list[int] | None, within: tuple[int, int] | None = None) -> Counts:
        """Expected times each path action is taken at each state (and STAY on arrival at the goal), for
        demonstrations from ``start`` following ``path``, or drawn uniformly among shortest paths if None; with
        ``within``, only while they are on that cell."""
        flow: Counts = {}

        def add(state: State, action: int, mass: Fraction) -> None:
            flow.setdefault(state, [Fraction(0)] * N_ACTIONS)[action] += mass

        if path is not None:
            state = start
            for action in path:
                if within is not None and state[:2] != within:
                    return flow
                add(state, action, Fraction(1))
                state = self.model.step(state, action)
            add(state, STAY, Fraction(1))
            return flow
        layer = {start: Fraction(1)}
        while layer:  # every optimal successor is one step closer: the layers are the distances
            nxt: dict[State, Fraction] = {}
            for state, mass in layer.items():
                if within is not None and state[:2] != within:
                    continue
                if self.dist[state] == 0:
                    add(state, STAY, mass)
                    continue
                succ = optimal_successors(self.model, self.dist, state)
                total = sum(self.n_paths[s] for s in succ.values())
                for action, s in succ.items():
                    share = mass * Fraction(self.n_paths[s], total)
                    add(state, action, share)
                    nxt[s] = nxt.get(s, Fraction(0)) + share
            layer = nxt
        return flow

    def counts(self, start: State, path: list[int] | None, within: tuple[int, int] | None = None) -> Counts:
        """Expected times each action is taken at each state by demonstrations from ``start`` (see
        :meth:`path_flow`), with the regime's turn insertions before every path action.

        Insertions never leave their cell: with ``within``, the counts of that cell's states are exact."""
        flow = self.path_flow(start, path, within)
        out = {state: list(row) for state, row in flow.items()}
        if not self.patterns or self.turn_prob == 0:
            return out
        for state, row in flow.items():
            visits = sum(row) - row[STAY]  # times a path action is taken here, each preceded by an insertion
            if visits == 0:
                continue
            share = visits * self.turn_prob / len(self.patterns)
            for pattern in self.patterns:
                s = state
                for turn in pattern:
                    out.setdefault(s, [Fraction(0)] * N_ACTIONS)[turn] += share
                    s = self.model.step(s, turn)
        return out
