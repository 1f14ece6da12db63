"""The symbolic demonstrators' action distributions, as tables over every state (``optimal`` and ``biased``).

The reference recognizer ``demonstrator`` scores with them. Rows are indexed
by :func:`~grail_bench.core.spaces.state_index` of the observation, which is
the state's integer (:mod:`.strips`), so a table has ``2 ** n_fluents`` rows:
problems of at most 16 fluents (every built-in one) are served, larger ones
refused in one line. Distances to the goal come from a backward breadth-first
search over the whole transition table, and the number of optimal plans from
each state by dynamic programming over them.

* ``optimal``: at a state, each optimal operator (one step closer to the goal)
  with probability proportional to the number of optimal plans it starts:
  the uniform-over-optimal-plans demonstrator is Markov, and this is its policy.
* ``biased``: the first optimal operator by index (the lexicographically first
  optimal plan from that state).

Supports: ``"everywhere"`` gives these rows on every state that can reach the
goal; ``"demonstrated"`` only on the states the demonstrator from the initial
state visits (other rows uniform). Goal states (the episode has ended there)
and states that cannot reach the goal get uniform rows.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from grail_bench.domains.symbolic.strips import StripsModel

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask


def distances(table: np.ndarray, goal: int) -> np.ndarray:
    """Fewest operators from every state to one holding the goal mask (``inf`` where none)."""
    states = np.arange(len(table), dtype=np.int64)
    dist = np.where((states & goal) == goal, 0.0, np.inf)
    d = 0
    while True:
        frontier = np.isinf(dist) & (dist[table] == d).any(axis=1)
        if not frontier.any():
            return dist
        d += 1
        dist[frontier] = d


def optimal_actions(model: StripsModel, goal: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The transition table, the distances and the ``(S, A)`` mask of operators one step closer to the goal."""
    table = model.transition_table()
    dist = distances(table, goal)
    closer = (dist[table] == dist[:, None] - 1) & np.isfinite(dist)[:, None] & (dist[:, None] > 0)
    return table, dist, closer


def demonstrator_policy(task: GRTask, goal: Goal, support: str = "everywhere") -> np.ndarray:
    """The demonstrator's action probabilities of ``goal`` on every state (see the module docstring).

    Returns:
        ``(2 ** n_fluents, n_operators)`` probabilities; every row sums to 1.

    Raises:
        UserError: For an unknown support, the ``suboptimal`` regime or a problem of more than 16 fluents.
    """
    task.spec.check_demonstrator_policy(task, support)
    env = task.make_env(goal)
    base = env.unwrapped
    env.close()
    model, mask = base.model, base.goal_mask
    table, dist, closer = optimal_actions(model, mask)
    n_states, n_actions = table.shape
    probs = np.full((n_states, n_actions), 1.0 / n_actions)
    active = closer.any(axis=1)
    if task.regime == "biased":
        first = np.argmax(closer, axis=1)
        probs[active] = 0.0
        probs[np.flatnonzero(active), first[active]] = 1.0
    else:
        count = np.zeros(n_states)
        count[dist == 0] = 1.0
        for d in range(1, int(dist[np.isfinite(dist)].max(initial=0)) + 1):
            layer = np.flatnonzero(dist == d)
            count[layer] = (closer[layer] * count[table[layer]]).sum(axis=1)
        weights = closer * count[table]
        probs[active] = weights[active] / weights[active].sum(axis=1, keepdims=True)
    if support == "demonstrated":
        visited = np.zeros(n_states, dtype=bool)
        frontier = {model.init}
        while frontier:  # every state the demonstrator reaches with nonzero probability before the goal
            for s in frontier:
                visited[s] = True
            frontier = {int(table[s, a]) for s in frontier if active[s]
                        for a in np.flatnonzero(probs[s] > 0)} - set(np.flatnonzero(visited).tolist())
        probs[~(visited & active)] = 1.0 / n_actions
    return probs
