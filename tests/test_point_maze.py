"""PointMaze (gymnasium-robotics): the maze, the demonstrators and an end-to-end run."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import gymnasium as gym
import numpy as np
import pytest

import grail_bench
from grail_bench.core.trajectory import goal_horizon
from grail_bench.domains.point_maze.demos import route_controller
from grail_bench.domains.point_maze.maze import Maze, biased_route, shortest_routes
from grail_bench.harness.api import evaluate

IDS = ["GRAIL/PointMaze-Optimal-v0", "GRAIL/PointMaze-Biased-v0", "GRAIL/PointMaze-Noisy-0.1-v0",
       "GRAIL/PointMaze-Noisy-0.3-v0"]


def cells_visited(maze: Maze, traj) -> list[tuple[int, int]]:
    """The cells the ball passes through (nearest centre), consecutive repeats merged."""
    out = []
    for x, y in traj.obs[:, :2]:
        cell = (int(round(len(maze.rows) / 2 - y - 0.5)), int(round(x - 0.5 + len(maze.rows[0]) / 2)))
        if not out or out[-1] != cell:
            out.append(cell)
    return out


def route_cells(maze: Maze, start, route: str) -> list[tuple[int, int]]:
    cells = [start]
    for heading in route:
        cells.append(maze.step(cells[-1], heading))
    return cells


def test_shortest_routes_and_the_bias():
    maze = Maze.parse(grail_bench.make_task(IDS[0]).env_params["maze"])
    assert sorted(shortest_routes(maze, (5, 1), (1, 3))) == ["EENNNN", "NNEENN", "NNNNEE"]
    assert len(shortest_routes(maze, (5, 1), (1, 5))) == 6
    assert biased_route(maze, (5, 1), (1, 3), "NE") == "NNNNEE"
    assert biased_route(maze, (5, 1), (1, 3), "EN") == "EENNNN"


@pytest.mark.parametrize("task_id", IDS)
def test_every_demonstration_reaches_its_goal_within_the_horizon(task_id):
    task = grail_bench.make_task(task_id)
    demos = task.generate_demos(seed=0, n_demos=3)
    for goal, trajs in demos.items():
        for traj in trajs:
            assert len(traj.acts) == task.env_params["max_steps"]
            assert traj.infos[-1]["is_success"] and goal_horizon(traj) < len(traj.acts)
            assert np.linalg.norm(traj.obs[-1, :2] - Maze.parse(task.env_params["maze"]).xy(goal)) < 0.45


def test_the_biased_demonstrator_takes_its_route():
    task = grail_bench.make_task("GRAIL/PointMaze-Biased-v0")
    maze, start = Maze.parse(task.env_params["maze"]), tuple(task.env_params["start"])
    demos = task.generate_demos(seed=0, n_demos=2)
    for goal, order in zip(task.goals, task.params["routes"]):
        route = biased_route(maze, start, goal, order)
        for traj in demos[goal]:
            assert cells_visited(maze, traj) == route_cells(maze, start, route)


def test_optimal_routes_vary_and_stay_shortest():
    task = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    maze, start = Maze.parse(task.env_params["maze"]), tuple(task.env_params["start"])
    demos = task.generate_demos(seed=0, n_demos=10)
    goal = (1, 5)
    visited = {tuple(cells_visited(maze, t)) for t in demos[goal]}
    assert len(visited) > 1
    assert visited <= {tuple(route_cells(maze, start, r)) for r in shortest_routes(maze, start, goal)}


@pytest.mark.parametrize("sigma", [0.1, 0.3])
def test_noise_has_the_configured_distribution(sigma):
    task = grail_bench.make_task(f"GRAIL/PointMaze-Noisy-{sigma}-v0")
    maze, start = Maze.parse(task.env_params["maze"]), tuple(task.env_params["start"])
    residuals = []
    for goal, trajs in task.generate_demos(seed=0, n_demos=6).items():
        for traj in trajs:
            # Replay the noiseless controller of each shortest route on the recorded states; the demo's is the
            # one whose actions stay closest.
            best = None
            for route in shortest_routes(maze, start, goal):
                act = route_controller(maze, start, route)
                clean = np.array([act(o) for o in traj.obs[:-1]])
                err = np.abs(traj.acts - clean).mean()
                if best is None or err < best[0]:
                    best = (err, clean)
            clean = best[1]
            inside = np.abs(traj.acts) < 0.999  # unclipped actions show the noise as drawn
            residuals.append((traj.acts - clean)[inside])
    noise = np.concatenate(residuals)
    # Clipping at +-1 removes the tails beside saturated actions, so the spread is slightly under sigma.
    assert abs(noise.mean()) < 0.1 * sigma
    assert 0.75 * sigma < noise.std() < 1.1 * sigma


def test_parameters_are_checked_when_the_task_is_built():
    with pytest.raises(ValueError, match="goal \\[2, 2\\] must be a free cell"):
        grail_bench.make_task("GRAIL/PointMaze-Optimal-v0").__class__(
            id="GRAIL/T-v0", domain="point_maze", regime="optimal", goals=((2, 2), (1, 5)))
    with pytest.raises(ValueError, match="sigma must be a number >= 0"):
        grail_bench.make_task("GRAIL/PointMaze-Noisy-0.1-v0", sigma=-1)
    with pytest.raises(ValueError, match="the maze border must be walls"):
        grail_bench.make_task("GRAIL/PointMaze-Optimal-v0", maze=["#####", "#...#", "#...."])


def test_renders_in_a_fresh_process_with_a_headless_gl_backend():
    code = ("import gymnasium as gym, grail_bench; e = gym.make('GRAIL/PointMaze-Biased-v0', render_mode='rgb_array');"
            "e.reset(seed=0); print(e.render().shape)")
    env = {**os.environ, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    if "MuJoCo cannot render here" in out.stderr:
        pytest.skip("no EGL on this machine")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "(480, 480, 3)"


def test_envs_leave_no_files_in_the_temp_dir(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # where gymnasium-robotics writes the maze's MJCF
    env = gym.make("GRAIL/PointMaze-Optimal-v0")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()
    assert list(tmp_path.iterdir()) == []


def test_graql_refuses_continuous_states():
    with pytest.raises(ValueError, match="graql needs discrete observations"):
        evaluate("GRAIL/PointMaze-Optimal-v0", [("graql", {"episodes": 1})], seeds=1, observability=[1.0],
                 task_params={"n_demos": 2, "n_train": 1})


@pytest.mark.slow
def test_bc_beats_chance_end_to_end():
    (record,) = evaluate("GRAIL/PointMaze-Noisy-0.1-v0", [("bc", {"n_epochs": 10})], seeds=1, observability=[1.0],
                         task_params={"n_demos": 6, "n_train": 4})
    assert record.accuracy_mean > 0.2 + 0.15  # 5 goals: chance is 0.2


@pytest.mark.slow
@pytest.mark.parametrize("name, config", [("gail", {"total_timesteps": 1024}), ("airl", {"total_timesteps": 1024}),
                                          ("draco", {"ppo_steps": 1024}),
                                          ("draco", {"algorithm": "sac", "sac_steps": 600})])
def test_every_policy_recognizer_runs(name, config):
    (record,) = evaluate("GRAIL/PointMaze-Biased-v0", [(name, config)], seeds=1, observability=[0.5],
                         task_params={"n_demos": 3, "n_train": 2})
    assert record.n_seeds == 1 and 0.0 <= record.f1.mean <= 1.0
