"""MiniGrid demonstration generators: optimality, routes, inserted turns, seeding."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

import grail_bench
from grail_bench.domains.minigrid.grid import FORWARD, LEFT, RIGHT, STAY, GridModel

MODEL = GridModel(9, frozenset({(7, 4)}))
START = (1, 4, 0)


def bfs_length(goal: tuple[int, int]) -> int:
    """Shortest number of actions from the start to ``goal`` (independent BFS)."""
    seen, queue = {START}, deque([(START, 0)])
    while queue:
        s, d = queue.popleft()
        if s[:2] == goal:
            return d
        for a in (LEFT, RIGHT, FORWARD):
            t = MODEL.step(s, a)
            if t not in seen:
                seen.add(t)
                queue.append((t, d + 1))
    raise AssertionError("unreachable")


def steps_to_goal(traj) -> int:
    return next(i + 1 for i, info in enumerate(traj.infos) if info["is_success"])


def check_demo_shape(task, goal, traj) -> None:
    assert len(traj.acts) == task.env_params["max_steps"]
    assert len(traj.obs) == len(traj.acts) + 1
    assert tuple(traj.obs[-1][:2]) == goal
    t = steps_to_goal(traj)
    assert np.all(traj.acts[t:] == STAY)


@pytest.mark.parametrize("task_id", ["GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Optimal-6Goals-v0"])
def test_optimal_demos_are_shortest(task_id):
    task = grail_bench.make_task(task_id)
    for goal, trajs in task.generate_demos(seed=1).items():
        for traj in trajs:
            check_demo_shape(task, goal, traj)
            assert steps_to_goal(traj) == bfs_length(goal)


def test_uniform_route_choice_varies_among_shortest_paths():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    assert task.params["route_choice"] == "uniform"  # the default: no preference among equally short paths
    demos = task.generate_demos(seed=0, n_demos=30)
    for trajs in demos.values():
        assert len({tuple(t.acts) for t in trajs}) > 3


@pytest.mark.parametrize("task_id", ["GRAIL/MiniGrid-Optimal-6Goals-v0", "GRAIL/MiniGrid-Suboptimal-6Goals-v1"])
def test_fixed_route_choice_gives_one_route_per_goal_that_test_demos_follow_too(task_id):
    from grail_bench.core.trajectory import until_success

    task = grail_bench.make_task(task_id, route_choice="fixed")
    for seed in (0, 3):
        train, test = task.split(task.generate_demos(seed))
        for goal in task.goals:
            # The cells visited up to the goal, each once (insertions turn on the spot and add none).
            cells = {tuple(dict.fromkeys(tuple(o[:2].tolist()) for o in until_success(t).obs))
                     for t in [*train[goal], *test[goal]]}
            assert len(cells) == 1
            (visited,) = cells
            assert visited[1] == (2, 4)  # straight ahead (east) first, from the start (1, 4) facing east
    forward_first = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0", route_choice="fixed").generate_demos(0)
    assert {tuple(t.acts[:5]) for trajs in forward_first.values() for t in trajs} == {(FORWARD,) * 5}


@pytest.mark.parametrize("turn_prob", [0.0, 0.3, 1.0])
def test_the_insertion_probability_sets_the_mean_demo_length(turn_prob):
    from grail_bench.core.trajectory import goal_horizon

    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=turn_prob)
    path = {g: goal_horizon(t[0]) for g, t in task.with_overrides(turn_prob=0.0).generate_demos(0).items()}
    for goal, trajs in task.generate_demos(seed=0, n_demos=60).items():
        # Each of the path's actions gains a left-right pair (2 actions) with probability turn_prob.
        expected = path[goal] * (1 + 2 * turn_prob)
        assert np.mean([goal_horizon(t) for t in trajs]) == pytest.approx(expected, rel=0.08)


@pytest.mark.parametrize("task_id, params", [("GRAIL/MiniGrid-Optimal-v0", {}),
                                             ("GRAIL/MiniGrid-Suboptimal-v1", {"route_choice": "fixed"})])
def test_other_seed_other_demos(task_id, params):
    task = grail_bench.make_task(task_id, **params)
    a, b = task.generate_demos(seed=0), task.generate_demos(seed=1)
    assert any(not np.array_equal(ta.acts, tb.acts) for g in task.goals for ta, tb in zip(a[g], b[g]))


def test_bad_regime_parameters_are_clear():
    with pytest.raises(ValueError, match="route_choice must be one of fixed, uniform, got 'any'"):
        grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0", route_choice="any")
    with pytest.raises(ValueError, match="turn_prob must be in"):
        grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=1.5).generate_demos(0)
    with pytest.raises(ValueError, match="one heading order per goal"):
        grail_bench.make_task("GRAIL/MiniGrid-Biased-v0", routes=["NE"]).generate_demos(0)
    with pytest.raises(ValueError, match="compass letters"):
        grail_bench.make_task("GRAIL/MiniGrid-Biased-v0", routes=["NX", "ES"]).generate_demos(0)


def test_split_needs_test_demonstrations():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    with pytest.raises(ValueError, match="need more than n_train"):
        task.split(task.generate_demos(seed=0, n_demos=7))
