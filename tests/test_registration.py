"""Registry-driven checks over every GRAIL/ ID (the Minigrid way)."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import grail_bench
from grail_bench.task.registration import register_envs

TASK_IDS = grail_bench.task_ids()
EXPECTED = {
    "GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Biased-v0", "GRAIL/MiniGrid-Suboptimal-v0",
    "GRAIL/MiniGrid-Optimal-4Goals-v0", "GRAIL/MiniGrid-Optimal-6Goals-v0",
    "GRAIL/MiniGrid-Suboptimal-4Goals-v0", "GRAIL/MiniGrid-Suboptimal-6Goals-v0",
    "GRAIL/PointMaze-Optimal-v0", "GRAIL/PointMaze-Biased-v0", "GRAIL/PointMaze-Noisy-0.1-v0",
    "GRAIL/PointMaze-Noisy-0.3-v0",
}


def test_paper_task_ids_are_registered():
    assert EXPECTED <= set(TASK_IDS)


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_check_env(task_id):
    env = gym.make(task_id)
    # MuJoCo renders only with a GL backend chosen before it is imported: tests/test_point_maze.py checks it
    # in a fresh process.
    mujoco = env.unwrapped.task.domain == "point_maze"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=mujoco)
    env.close()


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_same_seed_same_rollout(task_id):
    def rollout(seed: int) -> list:
        env = gym.make(task_id)
        env.action_space.seed(seed)
        obs, _ = env.reset(seed=seed)
        out = [obs.tolist()]
        for _ in range(80):
            obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            out.append((obs.tolist(), reward, terminated, truncated))
            if terminated or truncated:
                obs, _ = env.reset()
                out.append(obs.tolist())
        return out

    assert rollout(3) == rollout(3)
    assert rollout(3) != rollout(4)


@pytest.mark.parametrize("task_id", TASK_IDS)
def test_env_carries_its_task(task_id):
    env = gym.make(task_id)
    task = env.unwrapped.task
    assert task == grail_bench.make_task(task_id)
    assert task.id == task_id
    assert env.unwrapped.goal == task.goals[0]
    json.loads(gym.spec(task_id).to_json())  # registered kwargs are JSON-only


def test_biased_task_matches_issue_example():
    env = gym.make("GRAIL/MiniGrid-Biased-v0")
    task = env.unwrapped.task
    assert task.goals == ((7, 1), (7, 7))
    demos = task.generate_demos(seed=0)
    assert [len(d) for d in demos.values()] == [10, 10]
    train, test = task.split(demos)
    assert [len(v) for v in train.values()] == [7, 7]
    assert [len(v) for v in test.values()] == [3, 3]
    assert task.make_env((7, 1)).unwrapped.goal == (7, 1)


def test_make_env_pins_the_requested_goal():
    env = gym.make("GRAIL/MiniGrid-Optimal-6Goals-v0", goal=[5, 7])
    assert env.unwrapped.goal == (5, 7)
    with pytest.raises(ValueError, match="not a goal"):
        grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0").make_env((3, 3))


def test_regime_parameters_override_through_make():
    env = gym.make("GRAIL/MiniGrid-Suboptimal-v0", turn_prob=0.9)
    assert env.unwrapped.task.params["turn_prob"] == 0.9
    assert grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v0", turn_prob=0.1).params["turn_prob"] == 0.1
    assert gym.make("GRAIL/MiniGrid-Optimal-v0", max_steps=80).unwrapped.max_steps == 80


def test_unknown_override_is_a_clear_error():
    with pytest.raises(ValueError, match="cannot apply parameter 'turn_probability'"):
        gym.make("GRAIL/MiniGrid-Suboptimal-v0", turn_probability=0.9)


def test_make_task_rejects_overrides_it_cannot_apply():
    with pytest.raises(ValueError, match="'render_mode' .*applies to gym.make, not to a task"):
        grail_bench.make_task("GRAIL/MiniGrid-Biased-v0", render_mode="rgb_array")
    with pytest.raises(ValueError, match="params: turn_prob must be in"):
        grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v0", turn_prob=2)
    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v0", turn_prob=0.5, max_steps=80, n_demos=12)
    assert (task.params["turn_prob"], task.env_params["max_steps"], task.n_demos) == (0.5, 80, 12)


@pytest.mark.parametrize("bad_id", ["GRAIL/MiniGrid-Nope-v0", "GRAIL/MiniGrid-Biased-v9", "NOPE/MiniGrid-Biased-v0"])
def test_unknown_ids_raise_gymnasiums_error(bad_id):
    with pytest.raises(gym.error.Error):
        gym.make(bad_id)
    with pytest.raises(gym.error.Error):
        grail_bench.make_task(bad_id)


def test_non_grail_id_is_not_a_task():
    with pytest.raises(ValueError, match="not a GRAIL/ task"):
        grail_bench.make_task("CartPole-v1")


def test_registration_is_idempotent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
        register_envs()
    assert grail_bench.task_ids() == TASK_IDS


@pytest.mark.parametrize("first_import", ["gymnasium", "grail_bench"])
def test_fresh_interpreter(first_import):
    code = (
        f"import {first_import}\n"
        "import sys, gymnasium as gym\n"
        "env = gym.make('GRAIL/MiniGrid-Biased-v0')\n"
        "assert env.unwrapped.task.goals == ((7, 1), (7, 7))\n"
        "assert 'torch' not in sys.modules, 'registration must stay light'\n"
        "assert 'grail_bench.domains.point_maze.env' not in sys.modules and 'pybullet' not in sys.modules\n"
        "env = gym.make('GRAIL/PointMaze-Biased-v0')\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
    assert out.stderr == ""


def test_observation_space_is_compact():
    env = gym.make("GRAIL/MiniGrid-Optimal-v0")
    assert isinstance(env.observation_space, gym.spaces.MultiDiscrete)
    assert env.observation_space.nvec.tolist() == [9, 9, 4]
    assert env.action_space == gym.spaces.Discrete(4)
    obs, _ = env.reset(seed=0)
    assert np.array_equal(obs, [1, 4, 0])


def test_every_domain_package_satisfies_the_domain_protocol():
    from grail_bench.domains import Domain, available_domains, get_domain

    assert {"minigrid", "panda_reach", "point_maze"} <= set(available_domains())
    for name in available_domains():
        domain = get_domain(name)
        assert isinstance(domain, Domain) and domain.name == name
        assert isinstance(domain.goal_dim, int) and domain.regimes and isinstance(domain.env_defaults, dict)
    tasks = [grail_bench.make_task(t) for t in TASK_IDS]
    assert {t.domain for t in tasks} == set(available_domains())  # every domain has a card
