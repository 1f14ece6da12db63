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


def test_optimal_demos_vary_among_shortest_paths():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    demos = task.generate_demos(seed=0, n_demos=30)
    for trajs in demos.values():
        assert len({tuple(t.acts) for t in trajs}) > 3


def test_biased_demos_follow_their_route():
    task = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
    demos = task.generate_demos(seed=5)
    north_then_east = [LEFT, FORWARD, FORWARD, FORWARD, RIGHT] + [FORWARD] * 6
    east_then_south = [FORWARD] * 5 + [RIGHT, FORWARD, FORWARD, FORWARD, LEFT, FORWARD]
    for goal, expected in (((7, 1), north_then_east), ((7, 7), east_then_south)):
        for traj in demos[goal]:
            check_demo_shape(task, goal, traj)
            assert traj.acts[: len(expected)].tolist() == expected
            assert steps_to_goal(traj) == len(expected) == bfs_length(goal)


@pytest.mark.parametrize("turn_prob", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("pattern, width", [("around-and-back", 4), ("left-right", 2)])
def test_suboptimal_demos_keep_the_path_and_add_turns(turn_prob, pattern, width):
    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-6Goals-v0", turn_prob=turn_prob, turn_pattern=pattern)
    total_extra = 0
    for goal, trajs in task.generate_demos(seed=2).items():
        shortest = bfs_length(goal)
        for traj in trajs:
            check_demo_shape(task, goal, traj)
            t = steps_to_goal(traj)
            acts = traj.acts[:t].tolist()
            # Remove each inserted excursion: turns netting 0 (around and back: LL/RR then LL/RR;
            # left-right: LR or RL). A shortest path never holds such a window.
            core, i = [], 0
            while i < len(acts):
                window = acts[i:i + width]
                turns = len(window) == width and all(a in (LEFT, RIGHT) for a in window)
                if turns and (window[0] == window[1] and window[2] == window[3] if width == 4
                              else window[0] != window[1]):
                    i += width
                    continue
                core.append(acts[i])
                i += 1
            assert len(core) == shortest, "what is left must be a shortest path"
            cells = [tuple(o[:2]) for o in traj.obs[: t + 1]]
            moved = [c for c, n in zip(cells, cells[1:]) if c != n]
            assert len(moved) == core.count(FORWARD)
            total_extra += t - shortest
            if turn_prob == 1.0:
                assert t == (width + 1) * shortest
    if turn_prob == 0.0:
        assert total_extra == 0
    else:
        assert total_extra > 0


@pytest.mark.parametrize("task_id", grail_bench.task_ids())
def test_same_seed_same_demos(task_id):
    fast = {"expert": "scripted"} if "PandaReach" in task_id else {}  # SAC experts train for minutes
    task = grail_bench.make_task(task_id, **fast)
    n = 3 if fast else None
    a, b = task.generate_demos(seed=7, n_demos=n), task.generate_demos(seed=7, n_demos=n)
    for goal in task.goals:
        for ta, tb in zip(a[goal], b[goal]):
            assert np.array_equal(ta.obs, tb.obs) and np.array_equal(ta.acts, tb.acts)


@pytest.mark.parametrize("task_id", ["GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Suboptimal-v0"])
def test_other_seed_other_demos(task_id):
    task = grail_bench.make_task(task_id)
    a, b = task.generate_demos(seed=0), task.generate_demos(seed=1)
    assert any(not np.array_equal(ta.acts, tb.acts) for g in task.goals for ta, tb in zip(a[g], b[g]))


def test_bad_regime_parameters_are_clear():
    with pytest.raises(ValueError, match="turn_prob must be in"):
        grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v0", turn_prob=1.5).generate_demos(0)
    with pytest.raises(ValueError, match="one heading order per goal"):
        grail_bench.make_task("GRAIL/MiniGrid-Biased-v0", routes=["NE"]).generate_demos(0)
    with pytest.raises(ValueError, match="compass letters"):
        grail_bench.make_task("GRAIL/MiniGrid-Biased-v0", routes=["NX", "ES"]).generate_demos(0)


def test_split_needs_test_demonstrations():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    with pytest.raises(ValueError, match="need more than n_train"):
        task.split(task.generate_demos(seed=0, n_demos=7))
