"""Scripted MiniGrid demonstrators for the three behaviour regimes.

* ``optimal``: a shortest action sequence drawn uniformly among all of them.
* ``biased``: one fixed shortest route per goal. A route is a heading order,
  e.g. ``"NE"``: of all shortest paths, the one whose sequence of forward-move
  headings is lexicographically smallest when north ranks before east (headings
  not named rank after, in the order N, E, S, W). ``"NE"`` for (7, 1) goes
  north, then east; ``"ES"`` for (7, 7) goes east, then south, as in the paper.
* ``suboptimal``: a uniformly drawn shortest path; before each of its actions,
  with probability ``turn_prob``, the agent turns around (two lefts or two
  rights, equally likely) and turns back (again two lefts or two rights), so
  it faces its path again: the cells it visits are those of the shortest path.

Every demonstration is rolled out in the goal's own env, so observations come
from the real dynamics; after the goal the agent stays until the horizon.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
from imitation.data.types import Trajectory

from grail_bench.domains.minigrid import FORWARD, HEADINGS, LEFT, RIGHT, STAY, GridModel, State

if TYPE_CHECKING:
    from grail_bench.task import Goal, GRTask

TURNS = (LEFT, RIGHT)


@lru_cache(maxsize=64)
def shortest_path_graph(model: GridModel, goal: tuple[int, int]) -> tuple[dict[State, int], dict[State, int]]:
    """Distance to ``goal`` and number of shortest action sequences, per state.

    Stay is excluded, so every shortest sequence makes progress each step.
    """
    states = model.states()
    dist = {s: (0 if s[:2] == goal else np.inf) for s in states}
    changed = True
    while changed:  # Bellman-Ford on a tiny unit-cost graph
        changed = False
        for s in states:
            if s[:2] == goal:
                continue
            best = 1 + min(dist[model.step(s, a)] for a in (LEFT, RIGHT, FORWARD))
            if best < dist[s]:
                dist[s], changed = best, True
    count: dict[State, int] = {}
    for s in sorted(states, key=lambda s: dist[s]):
        count[s] = 1 if dist[s] == 0 else sum(count[t] for t in _optimal_successors(model, dist, s).values())
    return {s: int(d) for s, d in dist.items() if d < np.inf}, count


def _optimal_successors(model: GridModel, dist: dict[State, float], state: State) -> dict[int, State]:
    out = {}
    for a in (LEFT, RIGHT, FORWARD):
        nxt = model.step(state, a)
        if dist[nxt] == dist[state] - 1:
            out[a] = nxt
    return out


def sample_shortest_path(model: GridModel, start: State, goal: tuple[int, int], rng: np.random.Generator) -> list[int]:
    """One shortest action sequence, uniformly among all of them."""
    dist, count = shortest_path_graph(model, goal)
    if start not in dist:
        raise ValueError(f"goal {goal} is unreachable from {start}")
    actions, s = [], start
    while dist[s] > 0:
        succ = _optimal_successors(model, dist, s)
        options = sorted(succ)
        weights = np.array([count[succ[a]] for a in options], dtype=float)
        a = options[int(rng.choice(len(options), p=weights / weights.sum()))]
        actions.append(a)
        s = succ[a]
    return actions


def all_shortest_paths(model: GridModel, start: State, goal: tuple[int, int]) -> list[list[int]]:
    """Every shortest action sequence from ``start`` to ``goal``."""
    dist, _ = shortest_path_graph(model, goal)
    if start not in dist:
        raise ValueError(f"goal {goal} is unreachable from {start}")

    def walk(s: State) -> list[list[int]]:
        if dist[s] == 0:
            return [[]]
        return [[a, *rest] for a, nxt in sorted(_optimal_successors(model, dist, s).items()) for rest in walk(nxt)]

    return walk(start)


def biased_path(model: GridModel, start: State, goal: tuple[int, int], route: str) -> list[int]:
    """The shortest path preferred by a heading order such as ``"NE"``."""
    route = route.upper()
    if not route or set(route) - set(HEADINGS) or len(set(route)) != len(route):
        raise ValueError(f"route {route!r} must be distinct compass letters among N, E, S, W")
    order = route + "".join(h for h in "NESW" if h not in route)
    rank = {HEADINGS.index(h): i for i, h in enumerate(order)}

    def key(actions: list[int]) -> tuple:
        s, headings = start, []
        for a in actions:
            if a == FORWARD:
                headings.append(rank[s[2]])
            s = model.step(s, a)
        return tuple(headings), tuple(actions)

    return min(all_shortest_paths(model, start, goal), key=key)


def insert_turns(actions: list[int], turn_prob: float, rng: np.random.Generator) -> list[int]:
    """Before each action, with probability ``turn_prob``, turn around and back."""
    out: list[int] = []
    for a in actions:
        if rng.random() < turn_prob:
            around, back = TURNS[int(rng.integers(2))], TURNS[int(rng.integers(2))]
            out += [around, around, back, back]
        out.append(a)
    return out


def rollout(env, actions: list[int]) -> Trajectory:
    """Play ``actions`` then stay until the horizon; return the trajectory."""
    obs, info = env.reset(seed=0)
    horizon = env.unwrapped.max_steps
    if len(actions) > horizon:
        raise ValueError(f"a {len(actions)}-action demonstration does not fit the horizon {horizon}")
    observations, acts, infos = [obs], [], []
    for t in range(horizon):
        a = actions[t] if t < len(actions) else STAY
        obs, _, terminated, truncated, info = env.step(a)
        observations.append(obs)
        acts.append(a)
        infos.append(info)
        if terminated or truncated:
            break
    if not infos[-1]["is_success"]:
        raise RuntimeError(f"demonstration did not reach goal {env.unwrapped.goal}")
    return Trajectory(obs=np.stack(observations), acts=np.array(acts, dtype=np.int64),
                      infos=np.array(infos, dtype=object), terminal=True)


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal under the task's regime (see module docstring)."""
    env = task.make_env(goal)
    base = env.unwrapped
    start = (*base.start, base.start_dir)
    g = (int(goal[0]), int(goal[1]))
    if task.regime == "optimal":
        plans = [sample_shortest_path(base.model, start, g, rng) for _ in range(n)]
    elif task.regime == "biased":
        routes = task.params["routes"]
        if len(routes) != len(task.goals):
            raise ValueError(f"{task.id}: 'routes' needs one heading order per goal ({len(task.goals)}), got {len(routes)}")
        plans = [biased_path(base.model, start, g, routes[task.goal_index(goal)])] * n
    elif task.regime == "suboptimal":
        p = float(task.params["turn_prob"])
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"{task.id}: turn_prob must be in [0, 1], got {p}")
        plans = [insert_turns(sample_shortest_path(base.model, start, g, rng), p, rng) for _ in range(n)]
    else:
        raise ValueError(f"{task.id}: minigrid has no regime {task.regime!r}")
    demos = [rollout(env, plan) for plan in plans]
    env.close()
    return demos
