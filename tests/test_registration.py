"""Registry-driven checks over every GRAIL/ ID (the Minigrid way)."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import grail_bench
from grail_bench.task.registration import register_envs

TASK_IDS = grail_bench.task_ids()


def _one_per_env(task_ids: list[str]) -> list[str]:
    """The first ID of each distinct env: ``gym.make(id)`` builds ``domain.make_env(goals[0], **env_params)``,
    so IDs that differ only in their regime or later goals (a card's regimes, its ``goal_sets``) build the
    same env, and checking one checks them all."""
    seen: dict[str, str] = {}
    for task_id in task_ids:
        task = grail_bench.make_task(task_id)
        seen.setdefault(json.dumps([task.env_key, task.goals[0]]), task_id)
    return list(seen.values())


ENV_IDS = _one_per_env(TASK_IDS)
EXPECTED = {
    "GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Biased-v0", "GRAIL/MiniGrid-Suboptimal-v1",
    "GRAIL/MiniGrid-Optimal-4Goals-v0", "GRAIL/MiniGrid-Optimal-6Goals-v0",
    "GRAIL/MiniGrid-Suboptimal-4Goals-v1", "GRAIL/MiniGrid-Suboptimal-6Goals-v1",
    "GRAIL/PointMaze-Optimal-v0", "GRAIL/PointMaze-Biased-v0", "GRAIL/PointMaze-Noisy-0.1-v0",
    "GRAIL/PointMaze-Noisy-0.3-v0",
}


def test_paper_task_ids_are_registered():
    assert EXPECTED <= set(TASK_IDS)


@pytest.mark.parametrize("task_id", ENV_IDS)
def test_check_env(task_id):
    env = gym.make(task_id)
    # MuJoCo renders only with a GL backend chosen before it is imported: tests/test_point_maze.py checks it
    # in a fresh process.
    mujoco = env.unwrapped.task.domain == "point_maze"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # minigrid's human mode asks pygame-ce for its default font by a system name it does not find; pygame-ce
        # then uses the font it bundles (the same text is drawn).
        warnings.filterwarnings("ignore", message="The system font 'freesansbold.ttf' couldn't be found",
                                category=UserWarning)
        check_env(env.unwrapped, skip_render_check=mujoco)
    env.close()


@pytest.mark.parametrize("task_id", ENV_IDS)
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
    env = gym.make("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=0.9)
    assert env.unwrapped.task.params["turn_prob"] == 0.9
    assert grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=0.1).params["turn_prob"] == 0.1
    assert gym.make("GRAIL/MiniGrid-Optimal-v0", max_steps=80).unwrapped.max_steps == 80


def test_unknown_override_is_a_clear_error():
    with pytest.raises(ValueError, match="cannot apply parameter 'turn_probability'"):
        gym.make("GRAIL/MiniGrid-Suboptimal-v1", turn_probability=0.9)


def test_make_task_rejects_overrides_it_cannot_apply():
    with pytest.raises(ValueError, match="'render_mode' .*applies to gym.make, not to a task"):
        grail_bench.make_task("GRAIL/MiniGrid-Biased-v0", render_mode="rgb_array")
    with pytest.raises(ValueError, match="params: turn_prob must be in"):
        grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=2)
    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=0.5, max_steps=80, n_demos=12)
    assert (task.params["turn_prob"], task.env_params["max_steps"], task.n_demos) == (0.5, 80, 12)


@pytest.mark.parametrize("bad_id, hint", [
    ("GRAIL/MiniGrid-Nope-v0", ""),
    ("GRAIL/MiniGrid-Biased-v9", "; did you mean GRAIL/MiniGrid-Biased-v0"),
    ("NOPE/MiniGrid-Biased-v0", "; did you mean GRAIL/MiniGrid-Biased-v0"),
])
def test_unknown_ids_are_one_line_with_close_ids(bad_id, hint):
    with pytest.raises(gym.error.Error):
        gym.make(bad_id)  # gymnasium's own lookup, as for any ID
    with pytest.raises(grail_bench.UserError) as info:
        grail_bench.make_task(bad_id)
    assert str(info.value).startswith(f"unknown task {bad_id!r}{hint}") and "\n" not in str(info.value)
    assert grail_bench.task.find_task(bad_id) is None


def test_unknown_task_on_the_command_line_is_one_line(tmp_path):
    from typer.testing import CliRunner

    from grail_bench.cli import app

    result = CliRunner().invoke(app, ["export", "-t", "GRAIL/Nope-v0", "--out", str(tmp_path)], env={"COLUMNS": "200"})
    assert result.exit_code == 2 and result.stderr.count("\n") == 1 and "unknown task 'GRAIL/Nope-v0'" in result.stderr


def test_non_grail_id_is_not_a_task():
    with pytest.raises(ValueError, match="is a gymnasium env but not a grail-bench task"):
        grail_bench.make_task("CartPole-v1")
    with pytest.raises(grail_bench.UserError, match="a task ID is a string"):
        grail_bench.make_task(3)


@pytest.mark.parametrize("task_id, name, value, why", [
    ("GRAIL/MiniGrid-Biased-v0", "max_steps", -1, "expected a positive integer, got -1"),
    ("GRAIL/MiniGrid-Biased-v0", "max_steps", 0, "expected a positive integer, got 0"),
    ("GRAIL/MiniGrid-Biased-v0", "max_steps", 5.5, "expected an integer, got 5.5"),
    ("GRAIL/MiniGrid-Biased-v0", "max_steps", True, "expected an integer, got True"),
    ("GRAIL/MiniGrid-Biased-v0", "size", "9", "expected an integer, got '9'"),
    ("GRAIL/MiniGrid-Biased-v0", "fixed_horizon", 1, "expected true or false, got 1"),
    ("GRAIL/MiniGrid-Biased-v0", "start", 3, "expected a list, got 3"),
    ("GRAIL/PandaReach-Optimal-v0", "max_steps", 0, "expected a positive integer, got 0"),
    ("GRAIL/PandaReach-Optimal-v0", "distance_threshold", float("nan"), "expected a finite number, got nan"),
    ("GRAIL/PointMaze-Optimal-v0", "reward_type", 1, "expected a string, got 1"),
])
def test_env_parameters_are_checked_like_the_cards(task_id, name, value, why):
    message = f"{task_id}: env.{name}: {why}"
    with pytest.raises(grail_bench.UserError) as info:
        grail_bench.make_task(task_id, **{name: value})
    assert str(info.value) == message
    if task_id.startswith("GRAIL/MiniGrid"):
        with pytest.raises(grail_bench.UserError, match=f"env.{name}: "):
            gym.make(task_id, **{name: value})


def test_env_parameters_of_the_right_kind_pass():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0", max_steps=80, start=[1, 3])
    assert (task.env_params["max_steps"], task.env_params["start"]) == (80, [1, 3])
    assert grail_bench.make_task("GRAIL/PandaReach-Optimal-v0", distance_threshold=1).env_params["distance_threshold"] == 1


@pytest.mark.parametrize("task_id, overrides", [
    ("GRAIL/MiniGrid-Suboptimal-v1", {}),
    ("GRAIL/MiniGrid-Suboptimal-v1", {"turn_prob": 0.5, "max_steps": 80, "n_demos": 12, "n_train": 9}),
    ("GRAIL/MiniGrid-Biased-v0", {"routes": ["EN", "ES"], "obstacles": []}),
    ("GRAIL/PandaReach-Gaussian-0.1-v0", {"expert": "scripted", "sigma": 0.3}),
])
def test_overrides_round_trip_and_name_the_variant(task_id, overrides):
    base = grail_bench.make_task(task_id)
    task = grail_bench.make_task(task_id, **overrides)
    diff = task.overrides_against(base)
    assert base.with_overrides(**diff.as_dict()) == task
    assert set(diff) == {k for k, v in overrides.items() if base.settings()[k] != v}
    assert grail_bench.task.variant(base, dict(overrides)) == diff.label()


def test_variant_reads_like_the_overrides():
    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1")
    assert grail_bench.task.variant(task, {"turn_prob": 0.5, "route_choice": "fixed"}) == \
        'route_choice="fixed" turn_prob=0.5'
    assert grail_bench.task.variant(task, {"turn_prob": 1.0}) == ""
    assert grail_bench.task.variant(task, {"turn_prob": 7}) == ""  # not a task any more: no reading


def test_the_task_layer_has_no_import_circle():
    out = subprocess.run([str(Path(sys.executable).parent / "lint-imports"), "--contract", "task-layers"],
                         capture_output=True, text=True, timeout=120, cwd=Path(__file__).parents[1])
    assert out.returncode == 0 and "the task layer is acyclic KEPT" in out.stdout, out.stdout + out.stderr


def test_registration_is_idempotent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
        register_envs()
    assert grail_bench.task_ids() == TASK_IDS


def _fresh(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("make", [
    "import gymnasium as gym\nenv = gym.make('grail_bench:GRAIL/MiniGrid-Biased-v0')",
    "import gymnasium as gym, grail_bench\nenv = gym.make('GRAIL/MiniGrid-Biased-v0')",
    "import gymnasium as gym, grail_bench\ngym.register_envs(grail_bench)\nenv = gym.make('GRAIL/MiniGrid-Biased-v0')",
], ids=["module-prefix", "import", "register_envs"])
def test_each_gymnasium_way_to_make_a_task_works_in_a_fresh_interpreter(make):
    code = (
        f"{make}\n"
        "import sys\n"
        "assert env.unwrapped.task.goals == ((7, 1), (7, 7))\n"
        "assert 'torch' not in sys.modules, 'registration must stay light'\n"
        "assert 'grail_bench.domains.point_maze.env' not in sys.modules and 'pybullet' not in sys.modules\n"
        "env = gym.make('GRAIL/PointMaze-Biased-v0')\n"
        "print('ok')\n"
    )
    out = _fresh(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
    assert out.stderr == ""


def test_import_gymnasium_prints_nothing_and_loads_no_task():
    """Gymnasium 1.x loads no plugin on import: nothing of the suite runs, so nothing it has can print or break."""
    out = _fresh("import gymnasium as gym\nimport sys\nassert 'grail_bench' not in sys.modules\n"
                 "assert not any(i.startswith('GRAIL/') for i in gym.registry)\n")
    assert (out.returncode, out.stdout, out.stderr) == (0, "", "")


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
