"""The MiniGrid domain env: layout, dynamics, reward and the fixed horizon."""

from __future__ import annotations

import re

import numpy as np
import pytest

import grail_bench
from grail_bench.core.spaces import state_index
from grail_bench.domains.minigrid.env import GRMiniGridEnv
from grail_bench.domains.minigrid.grid import FORWARD, LEFT, RIGHT, STAY


def test_layout_matches_paper():
    env = GRMiniGridEnv((7, 1))
    env.reset(seed=0)
    assert env.state == (1, 4, 0)  # start (1, 4) facing east
    assert env.grid.get(7, 4).type == "wall"
    assert env.grid.get(7, 1).type == "goal"
    free = [(x, y) for x in range(9) for y in range(9) if env.model.free(x, y)]
    assert len(free) == 7 * 7 - 1


@pytest.mark.parametrize("task_id, goal", [
    ("GRAIL/MiniGrid-Optimal-v0", (7, 7)),
    ("GRAIL/MiniGrid-SimpleCrossing-Optimal-v0", (11, 11)),
    ("GRAIL/MiniGrid-LavaCrossing-Optimal-v0", (6, 5)),
])
def test_grid_model_mirrors_env_dynamics(task_id, goal):
    """Every state and action of the room: the pure-Python model, the env and its tables agree; entering lava ends
    the episode without reward and, with the fixed horizon, keeps the agent there."""
    task = grail_bench.make_task(task_id)
    env = task.make_env(goal, fixed_horizon=False).unwrapped
    absorbing = task.make_env(goal).unwrapped
    tables = absorbing.tabular_dynamics()
    space = absorbing.observation_space
    entered = 0
    for state in env.model.states():
        if state[:2] == goal or state[:2] in env.model.lava:
            continue
        for action in (LEFT, RIGHT, FORWARD, STAY):
            env.reset(seed=0)
            env.agent_pos, env.agent_dir = state[:2], state[2]
            obs, reward, terminated, _, info = env.step(action)
            nxt = env.model.step(state, action)
            assert tuple(obs.tolist()) == nxt, (state, action)
            index = state_index(np.array([state, nxt]), space)
            assert tables.next_state[index[0], action] == index[1]
            assert terminated == (nxt[:2] == goal or nxt[:2] in env.model.lava)
            assert info["is_success"] == (nxt[:2] == goal) == (reward > 0)
            if nxt[:2] in env.model.lava:
                entered += 1
                absorbing.reset(seed=0)
                absorbing.agent_pos, absorbing.agent_dir = state[:2], state[2]
                absorbing.step(action)
                for later in (LEFT, RIGHT, FORWARD, STAY):
                    obs, reward, terminated, _, info = absorbing.step(later)
                    assert tuple(obs.tolist()) == env.model.step(nxt, later) == nxt
                    assert (reward, terminated, info["is_success"]) == (0.0, False, False)
                assert (tables.next_state[index[1]] == index[1]).all() and not tables.success[index[1]].any()
    assert (entered > 0) == bool(env.model.lava)  # the lava rooms' checks ran


def test_reward_and_absorbing_fixed_horizon():
    env = GRMiniGridEnv((3, 4), max_steps=10)
    env.reset(seed=0)
    _, r1, term1, _, info1 = env.step(FORWARD)
    _, r2, term2, _, info2 = env.step(FORWARD)
    assert (r1, info1["is_success"]) == (0.0, False)
    assert r2 == pytest.approx(1 - 0.9 * 2 / 10)
    assert info2["is_success"] and not term2
    for t in range(3, 11):
        obs, r, term, trunc, info = env.step(FORWARD)  # absorbed: no movement, no reward
        assert tuple(obs.tolist()) == (3, 4, 0) and r == 0.0 and info["is_success"] and not term
        assert trunc == (t == 10)


def test_without_fixed_horizon_goal_terminates():
    env = GRMiniGridEnv((3, 4), fixed_horizon=False)
    env.reset(seed=0)
    env.step(FORWARD)
    *_, terminated, truncated, info = env.step(FORWARD)
    assert terminated and not truncated and info["is_success"]


@pytest.mark.parametrize("action", [4, -1, 1.5, "left"])
def test_invalid_action_is_rejected(action):
    env = GRMiniGridEnv((7, 1))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="invalid action"):
        env.step(action)


@pytest.mark.parametrize("kwargs", [{"goal": (7, 4)}, {"goal": (0, 0)}, {"goal": (1, 4)}, {"goal": (7, 1), "start_dir": 5}])
def test_bad_layout_is_rejected(kwargs):
    with pytest.raises(ValueError):
        GRMiniGridEnv(**kwargs)


def test_renders_rgb():
    env = GRMiniGridEnv((7, 1), render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8


@pytest.mark.parametrize("kwargs, why", [
    ({"start": [0, 4]}, "start [0, 4] must be a free cell"),
    ({"start": [7, 4]}, "start [7, 4] must be a free cell"),  # the obstacle
    ({"start_dir": 5}, "start_dir must be 0"),
    ({"size": 2}, "size must be an integer >= 3"),
    ({"obstacles": [[9, 9]]}, "obstacle [9, 9] lies outside"),
    ({"obstacles": [[7, 1]]}, "goal [7, 1] is not a free cell"),  # an obstacle on a goal
    ({"obstacles": [[7, 1, "lava"]]}, "goal [7, 1] is not a free cell"),  # lava on a goal
    ({"obstacles": [[1, 4, "lava"]]}, "start [1, 4] must be a free cell"),
    ({"obstacles": [[7, 4, "fire"]]}, 'each obstacle must be a wall [x, y] or lava [x, y, "lava"]'),
    ({"obstacles": [[7, 4], [7, 4, "lava"]]}, "cell [7, 4] is both a wall and lava"),
    ({"max_steps": -1}, "expected a positive integer"),
    ({"max_steps": 0}, "expected a positive integer"),
    ({"max_steps": 5.5}, "expected an integer"),
])
def test_env_parameters_are_checked_where_they_enter(kwargs, why):
    """gym.make's keyword arguments are validated like a card's, before any env is built."""
    import gymnasium as gym

    with pytest.raises(grail_bench.UserError, match=re.escape(why)):
        gym.make("GRAIL/MiniGrid-Biased-v0", **kwargs)
