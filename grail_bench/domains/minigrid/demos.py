"""Scripted MiniGrid demonstrators for the three behaviour regimes.

* ``optimal``: a shortest action sequence. ``route_choice`` reads the
  paper's "handcrafted to follow the shortest path to each goal": ``"uniform"``
  (the default: each demonstration draws one uniformly among all of them; a
  consistent preference among equally short paths is the paper's *biased*
  regime) or ``"fixed"`` (one path per goal, every demonstration follows it; of
  all shortest paths, the one going straight ahead first, see :func:`fixed_path`).
* ``biased``: one fixed shortest route per goal. A route is a heading order,
  e.g. ``"NE"``: of all shortest paths, the one whose sequence of forward-move
  headings is lexicographically smallest when north ranks before east (headings
  not named rank after, in the order N, E, S, W). ``"NE"`` for (7, 1) goes
  north, then east; ``"ES"`` for (7, 7) goes east, then south, as in the paper.
* ``suboptimal``: a shortest path (``route_choice`` as for ``optimal``);
  before each of its actions, with probability ``turn_prob`` (default 1.0:
  the paper inserts turns "before each action"), the agent inserts turns
  that leave its heading unchanged, so the cells it visits are those of the
  shortest path.
  ``turn_pattern`` reads the paper's "180-degree turns (left and right)":
  ``"left-right"`` (the default) is one left and one right in either order
  (2 actions, 180 degrees of turning in all); ``"around-and-back"`` turns
  around (two lefts or two rights) and back again (4 actions).

Every demonstration is rolled out in the goal's own env, so observations come
from the real dynamics; after the goal the agent stays until the horizon.

Test demonstrations of a task with shifted dynamics (``test_obstacles``,
``test_slip``, see :mod:`.grid`) are rolled out in the shifted room, planned in
it. Under ``test_slip`` the demonstrator acts in closed loop: it follows its
plan while the room does what it intends, and when a step slips it plans anew
from where it is, by its regime's rule (uniform: a shortest path drawn
uniformly from there; fixed or biased: the path its heading order prefers from
there; suboptimal: with its turn insertions). A slip into lava ends the
episode there, unsuccessful.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import rollout
from grail_bench.domains.minigrid.grid import (
    FORWARD,
    test_env_overrides,
    HEADINGS,
    LEFT,
    RIGHT,
    STAY,
    TURN_PATTERNS,
    GridModel,
    State,
)
from grail_bench.domains.routes import ranking

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

@lru_cache(maxsize=64)
def shortest_path_graph(model: GridModel, goal: tuple[int, int]) -> tuple[dict[State, int], dict[State, int]]:
    """Distance to ``goal`` and number of shortest action sequences, per state that reaches it.

    Stay is excluded, so every shortest sequence makes progress each step. Lava states are left out: the
    episode ends there, so no path through lava reaches the goal and the demonstrators never enter it.
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
    reach = {s: int(d) for s, d in dist.items() if d < np.inf}  # lava and cut-off states never reach the goal
    count: dict[State, int] = {}
    for s in sorted(reach, key=reach.__getitem__):
        count[s] = 1 if reach[s] == 0 else sum(count[t] for t in optimal_successors(model, reach, s).values())
    return reach, count


def optimal_successors(model: GridModel, dist: dict[State, float], state: State) -> dict[int, State]:
    """The actions (turns and forward) one step closer to the goal of ``dist``, with the states they lead to."""
    out = {}
    for a in (LEFT, RIGHT, FORWARD):
        nxt = model.step(state, a)
        if dist.get(nxt, np.inf) == dist[state] - 1:
            out[a] = nxt
    return out


def sample_shortest_path(model: GridModel, start: State, goal: tuple[int, int], rng: np.random.Generator) -> list[int]:
    """One shortest action sequence, uniformly among all of them."""
    dist, count = shortest_path_graph(model, goal)
    if start not in dist:
        raise UserError(f"goal {goal} is unreachable from {start}")
    actions, s = [], start
    while dist[s] > 0:
        succ = optimal_successors(model, dist, s)
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
        raise UserError(f"goal {goal} is unreachable from {start}")

    def walk(s: State) -> list[list[int]]:
        if dist[s] == 0:
            return [[]]
        return [[a, *rest] for a, nxt in sorted(optimal_successors(model, dist, s).items()) for rest in walk(nxt)]

    return walk(start)


def biased_path(model: GridModel, start: State, goal: tuple[int, int], route: str) -> list[int]:
    """The shortest path preferred by a heading order such as ``"NE"``."""
    rank = {HEADINGS.index(h): i for i, h in enumerate(ranking(route))}

    def key(actions: list[int]) -> tuple:
        s, headings = start, []
        for a in actions:
            if a == FORWARD:
                headings.append(rank[s[2]])
            s = model.step(s, a)
        return tuple(headings), tuple(actions)

    return min(all_shortest_paths(model, start, goal), key=key)


def insert_turns(actions: list[int], turn_prob: float, rng: np.random.Generator,
                 pattern: str = "left-right") -> list[int]:
    """Before each action, with probability ``turn_prob``, insert one of ``pattern``'s turn sequences."""
    insertions = TURN_PATTERNS[pattern]
    out: list[int] = []
    for a in actions:
        if rng.random() < turn_prob:
            out += insertions[int(rng.integers(len(insertions)))]
        out.append(a)
    return out


def play(env, actions: list[int]) -> Trajectory:
    """Play ``actions`` then stay until the horizon; the demonstration must reach the goal."""
    horizon = env.unwrapped.max_steps
    if len(actions) > horizon:
        raise UserError(f"a {len(actions)}-action demonstration does not fit the horizon {horizon} (max_steps)")
    return rollout(env, lambda obs, t: actions[t] if t < len(actions) else STAY, require_success=True)


def test_env(task: GRTask, goal: Goal):
    """The env of ``goal``'s demonstrations: the task's, shifted by its test shifts (a task's
    :meth:`~grail_bench.task.model.GRTask.test_task` carries them)."""
    return task.make_env(goal, **test_env_overrides(task.test_params))


def plan_from(task: GRTask, goal: Goal, model: GridModel, state: State, rng: np.random.Generator) -> list[int]:
    """A plan from ``state`` to ``goal`` drawn by the task's regime (see the module docstring)."""
    g = (int(goal[0]), int(goal[1]))
    one = route(task, goal, model, state)
    plan = list(one) if one is not None else sample_shortest_path(model, state, g, rng)
    if task.regime == "suboptimal":
        plan = insert_turns(plan, float(task.params["turn_prob"]), rng, task.params["turn_pattern"])
    return plan


def play_closed_loop(env, task: GRTask, goal: Goal, plan: list[int], rng: np.random.Generator) -> Trajectory:
    """Follow ``plan`` in a slipping env, planning anew from where a slip leaves the agent (the episode may
    end unsuccessful: in lava, or at the horizon)."""
    base = env.unwrapped
    g = (int(goal[0]), int(goal[1]))
    reach, _ = shortest_path_graph(base.model, g)
    state = {"plan": list(plan), "expect": None}

    def act(obs, t: int) -> int:
        here = (int(obs[0]), int(obs[1]), int(obs[2]))
        if here[:2] == g or here not in reach:
            return STAY  # at the goal, or in lava (absorbed there)
        if state["expect"] is not None and here != state["expect"]:  # the last step slipped
            state["plan"] = plan_from(task, goal, base.model, here, rng)
        if not state["plan"]:
            return STAY
        action = state["plan"].pop(0)
        state["expect"] = base.model.step(here, action)
        return action

    return rollout(env, act, seed=int(rng.integers(2**31)))


def fixed_path(model: GridModel, start: State, goal: tuple[int, int]) -> list[int]:
    """The one shortest path of the ``fixed`` route choice: straight ahead first.

    Of all shortest paths, the one that keeps the start heading longest, then
    the other headings in the order N, E, S, W (the heading order of the
    start direction's compass letter, see :func:`biased_path`): from the
    paper's start facing east, east first, then north or south to the goal.
    """
    return biased_path(model, start, goal, HEADINGS[start[2]])


def route(task: GRTask, goal: Goal, model: GridModel, start: State) -> list[int] | None:
    """The one path every demonstration of ``goal`` follows, or None when each draws its own."""
    g = (int(goal[0]), int(goal[1]))
    if task.regime == "biased":
        return biased_path(model, start, g, task.params["routes"][task.goal_index(goal)])
    if task.params.get("route_choice") == "fixed":
        return fixed_path(model, start, g)
    return None


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal under the task's regime (see module docstring)."""
    if task.regime not in ("optimal", "biased", "suboptimal"):
        raise UserError(f"{task.id}: minigrid has no regime {task.regime!r}")
    env = test_env(task, goal)
    base = env.unwrapped
    start = (*base.start, base.start_dir)
    if base.slip:
        demos = [play_closed_loop(env, task, goal, plan_from(task, goal, base.model, start, rng), rng)
                 for _ in range(n)]
    else:
        demos = [play(env, plan) for plan in [plan_from(task, goal, base.model, start, rng) for _ in range(n)]]
    env.close()
    return demos
