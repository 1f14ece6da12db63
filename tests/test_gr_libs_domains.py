"""gr_libs' GR problems as task cards: MiniGrid's crossings and PointMaze's FourRooms and Obstacles maps.

Every new ID's env goes through gymnasium's env checker and the seeded-rollout check with the others
(tests/test_registration.py runs them on every distinct env of the registered IDs); tests/test_goal_sets.py
checks gr_libs' smaller goal sets, L1-L4.
"""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

import grail_bench
from grail_bench.core.seeding import DEMOS, goal_rng
from grail_bench.core.trajectory import goal_horizon
from grail_bench.domains.minigrid.grid import FORWARD, LEFT, RIGHT
from grail_bench.domains.minigrid.vector import MiniGridVecEnv
from grail_bench.domains.point_maze.maze import Maze, biased_route
from grail_bench.harness.ceiling import bayes_ceiling

MINIGRID = ["GRAIL/MiniGrid-SimpleCrossing-Optimal-v0", "GRAIL/MiniGrid-SimpleCrossing-Biased-v0",
            "GRAIL/MiniGrid-SimpleCrossing-Suboptimal-v0", "GRAIL/MiniGrid-LavaCrossing-Optimal-v0",
            "GRAIL/MiniGrid-LavaCrossing-Suboptimal-v0"]
POINT_MAZE = [f"GRAIL/PointMaze-{layout}-{regime}-v0" for layout in ("FourRooms", "Obstacles")
              for regime in ("Optimal", "Biased", "Noisy-0.1", "Noisy-0.3")]

# gr_envs 1.0, gr_envs/minigrid_scripts/envs/dynamic_goal_crossing_custom.py, DynamicGoalCrossingCustom13Env._gen_grid:
# the obstacle cells it places for size 13 (Wall in SimpleCrossingS13N4) and otherwise (Lava in LavaCrossingS9N2).
GR_ENVS_CROSSING_13 = [(7, 1), (7, 2), (7, 3), (7, 4), (11, 4), (10, 4), (9, 4), (8, 11), (8, 10), (8, 9), (8, 8),
                       (2, 8), (3, 8), (4, 8), (5, 8)]
GR_ENVS_CROSSING_9 = [(2, 1), (2, 2), (2, 3), (2, 4), (5, 7), (5, 6), (5, 4), (5, 3)]
# gr_libs v1.0.3, gr_libs/problems/consts.py, PROBLEMS[...]["L5"]["G_0"]["goals"] (gr_envs' (x, y) cells).
GR_LIBS_GOALS = {
    "MiniGrid-SimpleCrossingS13N4": [(11, 1), (11, 11), (1, 11), (5, 9), (6, 1), (11, 3), (11, 5)],
    "MiniGrid-LavaCrossingS9N2": [(1, 3), (6, 5), (4, 7), (2, 5), (5, 2), (4, 5), (1, 1)],
    "PointMaze-FourRoomsEnvDense-11x11": [(4, 4), (7, 3), (3, 7), (8, 2), (2, 8), (3, 4), (4, 3)],
    "PointMaze-ObstaclesEnvDense-11x11": [(5, 5), (3, 6), (6, 3), (7, 4), (4, 7), (8, 8)],
}


def gr_envs_maze(kind: str, width: int = 11, height: int = 11) -> list[str]:
    """gr_envs 1.0's 11x11 maps (gr_envs/wrappers/point_maze_wrapper.py, gen_four_rooms_env and
    gen_maze_with_obstacles with maze_register.py's obstacles), its ``env[y][x]`` as rows of ``#`` and ``.``."""
    env = [[int(x in (0, width - 1) or y in (0, height - 1)) for x in range(width)] for y in range(height)]
    if kind == "four_rooms":
        for y in range(1, height - 1):
            env[y][width // 2] = 1 if y != height // 4 and y != height * 3 // 4 else 0
        for x in range(1, width - 1):
            env[height // 2][x] = 1 if x != width // 4 and x != width * 3 // 4 else 0
    else:
        for x, y in [(2, 2), (2, 3), (2, 4), (3, 2), (3, 3), (3, 4), (4, 2), (4, 3), (4, 4)]:
            env[y][x] = 1
    return ["".join("#" if wall else "." for wall in row) for row in env]


@pytest.mark.parametrize("layout, size, start, kind, cells", [
    ("SimpleCrossing", 13, (1, 1), "wall", GR_ENVS_CROSSING_13),
    ("LavaCrossing", 9, (3, 1), "lava", GR_ENVS_CROSSING_9),
])
def test_crossing_layouts_are_gr_envs(layout, size, start, kind, cells):
    """The room minigrid builds from the cards holds gr_envs' obstacles, start and gr_libs' goals, cell for cell."""
    name = {"SimpleCrossing": "MiniGrid-SimpleCrossingS13N4", "LavaCrossing": "MiniGrid-LavaCrossingS9N2"}[layout]
    for task_id in [t for t in MINIGRID if layout in t]:
        task = grail_bench.make_task(task_id)
        assert task.goals == tuple(GR_LIBS_GOALS[name])
        env = task.make_env().unwrapped
        env.reset(seed=0)
        assert env.state == (*start, 0)  # facing east, as gr_envs' agent_dir = 0
        grid = {(x, y): (env.grid.get(x, y).type if env.grid.get(x, y) else "empty")
                for x in range(size) for y in range(size)}
        border = {c for c in grid if c[0] in (0, size - 1) or c[1] in (0, size - 1)}
        assert {c for c, t in grid.items() if t == kind} - border == set(cells)
        assert {c for c, t in grid.items() if t not in ("empty", "goal")} == border | set(cells)
        env.close()


@pytest.mark.parametrize("layout, kind", [("FourRooms", "four_rooms"), ("Obstacles", "obstacles")])
def test_maze_maps_are_gr_envs(layout, kind):
    """The cards' maps, start and goals are gr_envs' and gr_libs', (x, y) read as (row, col) = (y, x)."""
    gr_name = f"PointMaze-{layout}EnvDense-11x11"
    for task_id in [t for t in POINT_MAZE if layout in t]:
        task = grail_bench.make_task(task_id)
        assert list(task.env_params["maze"]) == gr_envs_maze(kind)
        assert tuple(task.env_params["start"]) == (1, 1)
        assert task.goals == tuple((y, x) for x, y in GR_LIBS_GOALS[gr_name])


@pytest.mark.parametrize("task_id", MINIGRID)
def test_minigrid_demonstrations_are_seeded_and_never_touch_lava(task_id):
    task = grail_bench.make_task(task_id)
    first, again, other = (task.generate_demos(seed=s, n_demos=3) for s in (0, 0, 1))
    lava = task.make_env().unwrapped.model.lava
    for goal, trajs in first.items():
        for traj, twin in zip(trajs, again[goal]):
            np.testing.assert_array_equal(traj.obs, twin.obs)
            np.testing.assert_array_equal(traj.acts, twin.acts)
            assert traj.infos[-1]["is_success"]
            assert tuple(traj.obs[goal_horizon(traj), :2]) == goal
            assert not {tuple(o[:2]) for o in traj.obs.tolist()} & lava
    if task.regime == "suboptimal":  # random turns: another seed, other demonstrations
        assert any(not np.array_equal(a.acts, b.acts) for g in first for a, b in zip(first[g], other[g]))


def test_biased_crossing_routes_follow_their_headings():
    """East along the top for the top-half goals, south down the left wall for the others."""
    task = grail_bench.make_task("GRAIL/MiniGrid-SimpleCrossing-Biased-v0")
    demos = task.generate_demos(seed=0, n_demos=1)
    assert tuple(demos[(11, 1)][0].obs[1]) == (2, 1, 0)  # forward, east
    assert tuple(demos[(11, 11)][0].obs[2]) == (1, 2, 1)  # right, forward: south


@pytest.mark.parametrize("fixed_horizon", [True, False])
def test_vectorised_lava_room_equals_the_env(fixed_horizon):
    """The numpy copies burn in lava as the env does: no reward, the episode over (or absorbed), no success."""
    task = grail_bench.make_task("GRAIL/MiniGrid-LavaCrossing-Optimal-v0")
    make = lambda: task.make_env((6, 5), max_steps=12, fixed_horizon=fixed_horizon).unwrapped  # noqa: E731
    n = 8
    vector, single = MiniGridVecEnv(make(), n), DummyVecEnv([make for _ in range(n)])
    np.testing.assert_array_equal(vector.reset(), single.reset())
    rng, burnt, lava = np.random.default_rng(0), 0, vector.template.model.lava
    for _ in range(300):
        actions = rng.choice([LEFT, RIGHT, FORWARD], size=n, p=[0.25, 0.25, 0.5])
        got, want = vector.step(actions), single.step(actions)
        for a, b in zip(got[:3], want[:3]):
            np.testing.assert_array_equal(a, b)
        for info, expected in zip(got[3], want[3]):
            assert info.keys() == expected.keys()
            for key, value in expected.items():
                np.testing.assert_array_equal(info[key], value)
        ends = [info.get("terminal_observation", obs) for obs, info in zip(got[0], got[3])]
        burnt += sum(tuple(s[:2]) in lava for s in np.asarray(ends).tolist())
    assert burnt > 10  # the comparison covered lava, not only wandering


def test_lava_demonstrator_policy_never_steps_into_lava():
    """From every safe state, the demonstrator's table gives no weight to an action that enters lava."""
    task = grail_bench.make_task("GRAIL/MiniGrid-LavaCrossing-Optimal-v0")
    env = task.make_env().unwrapped
    from grail_bench.core.spaces import state_index

    for goal in task.goals:
        table = task.spec.demonstrator_policy(task, goal)
        for state in env.model.states():
            if state[:2] in env.model.lava:
                continue
            row = table[int(state_index(np.array([state]), env.observation_space)[0])]
            assert row.sum() == pytest.approx(1.0)
            entering = [a for a in (LEFT, RIGHT, FORWARD) if env.model.step(state, a)[:2] in env.model.lava]
            assert all(row[a] == 0.0 for a in entering), (goal, state)


@pytest.mark.parametrize("task_id, protocol", [
    ("GRAIL/MiniGrid-LavaCrossing-Optimal-v0", "subset"),
    ("GRAIL/MiniGrid-SimpleCrossing-Biased-v0", "prefix"),
])
def test_bayes_ceilings_on_the_crossings(task_id, protocol):
    """Exact ceilings at gr_libs' levels: above chance, never falling with more observed, perfect on whole paths."""
    task = grail_bench.make_task(task_id)
    ceilings = [bayes_ceiling(task, protocol, p, method="exact").accuracy for p in task.observability]
    assert ceilings[0] > 1 / len(task.goals)
    assert ceilings == sorted(ceilings) and ceilings[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("task_id", POINT_MAZE)
def test_point_maze_demonstrations_are_seeded_and_reach_every_goal(task_id):
    """One demonstration per goal reaches it within the card's horizon; the first goal's, generated again from
    the same seed's stream (not the demonstration cache), is the same to the last bit."""
    task = grail_bench.make_task(task_id)
    demos = task.generate_demos(seed=0, n_demos=1)
    maze = Maze.parse(task.env_params["maze"])
    for goal, (traj,) in demos.items():
        assert traj.infos[-1]["is_success"]
        assert np.linalg.norm(traj.obs[goal_horizon(traj), :2] - maze.xy(goal)) <= 0.45
        assert len(traj.acts) == task.env_params["max_steps"]
    goal = task.goals[0]
    (again,) = task.spec.generate_demos(task, goal, 1, goal_rng(0, goal, DEMOS))
    np.testing.assert_array_equal(demos[goal][0].obs, again.obs)
    np.testing.assert_array_equal(demos[goal][0].acts, again.acts)


def test_point_maze_biased_routes_go_round_one_side():
    """The preferred routes differ by heading where the maps give a choice (the bias is visible)."""
    task = grail_bench.make_task("GRAIL/PointMaze-Obstacles-Biased-v0")
    maze, start = Maze.parse(task.env_params["maze"]), tuple(task.env_params["start"])
    routes = {goal: biased_route(maze, start, goal, order) for goal, order in zip(task.goals, task.params["routes"])}
    assert routes[(3, 6)].startswith("E") and routes[(7, 4)].startswith("S")
    assert routes[(8, 8)] == "SSSSSSSEEEEEEE"


def test_point_maze_bayes_ceiling_on_four_rooms():
    """The ceiling machinery serves the new maps (biased: one rollout per goal)."""
    task = grail_bench.make_task("GRAIL/PointMaze-FourRooms-Biased-v0")
    ceiling = bayes_ceiling(task, "prefix", 0.3)
    assert ceiling.method == "exact" and 1 / len(task.goals) < ceiling.accuracy <= 1.0
