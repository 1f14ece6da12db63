"""Cards' ``goal_sets``: smaller goal sets of a task as IDs of their own, gr_libs' L1-L4, and existing IDs unchanged."""

from __future__ import annotations

import hashlib
import json

import pytest

import grail_bench
from grail_bench.harness.planning import config_hash, fitted_config
from grail_bench.task.cards import CardError, goal_set_id, parse_card
from grail_bench.task.model import GRTask
from grail_bench.task.registration import shipped_tasks

BIASED = """
domain = "minigrid"
[[task]]
id = "GRAIL/T-Biased-v0"
regime = "biased"
goals = [[7, 1], [7, 7], [7, 3]]
params = { routes = ["NE", "ES", "EN"] }
description = "three goals"
[task.goal_sets]
A = [[7, 7], [7, 1]]
"B.2" = [[7, 3], [7, 7]]
"""


def test_goal_sets_add_one_suffixed_id_per_set_with_their_goals_and_routes():
    base, a, b = parse_card(BIASED, "card.toml")
    assert [base.id, a.id, b.id] == ["GRAIL/T-Biased-v0", "GRAIL/T-Biased-A-v0", "GRAIL/T-Biased-B.2-v0"]
    assert base.goals == ((7, 1), (7, 7), (7, 3)) and base.params["routes"] == ["NE", "ES", "EN"]
    assert a.goals == ((7, 7), (7, 1)) and a.params["routes"] == ["ES", "NE"]  # each goal keeps its route
    assert b.goals == ((7, 3), (7, 7)) and b.params["routes"] == ["EN", "ES"]
    assert a.description == base.description and a.env_params == base.env_params and a.source == "card.toml"


def test_goal_sets_in_defaults_apply_to_every_task():
    text = ('domain = "minigrid"\n[defaults]\ngoals = [[7, 1], [7, 7], [7, 3]]\ngoal_sets = { L1 = [[7, 1], [7, 3]] }\n'
            '[[task]]\nid = "GRAIL/T-Optimal-v0"\nregime = "optimal"\n'
            '[[task]]\nid = "GRAIL/T-Suboptimal-v0"\nregime = "suboptimal"\nparams = { turn_prob = 0.5 }\n')
    tasks = parse_card(text, "card.toml")
    assert [(t.id, len(t.goals)) for t in tasks] == [("GRAIL/T-Optimal-v0", 3), ("GRAIL/T-Optimal-L1-v0", 2),
                                                     ("GRAIL/T-Suboptimal-v0", 3), ("GRAIL/T-Suboptimal-L1-v0", 2)]
    assert tasks[3].params["turn_prob"] == 0.5


def test_goal_set_id_inserts_the_name_before_the_version():
    assert goal_set_id("GRAIL/PandaReach-Gaussian-0.1-v0", "L3") == "GRAIL/PandaReach-Gaussian-0.1-L3-v0"
    assert goal_set_id("GRAIL/X-v12", "L1") == "GRAIL/X-L1-v12"


ONE = 'domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7],[7,3]]\n'


@pytest.mark.parametrize("goal_sets, where", [
    ("goal_sets = { L1 = [[7, 1], [5, 5]] }", "task[0].goal_sets.L1"),  # not one of the task's goals
    ("goal_sets = { L1 = [[7, 1]] }", "task[0].goal_sets.L1.goals"),  # one goal is no GR problem
    ("goal_sets = { L1 = [[7, 1], [7, 1]] }", "task[0].goal_sets.L1.goals"),
    ('goal_sets = { "L-1" = [[7, 1], [7, 7]] }', "task[0].goal_sets.L-1"),
    ("goal_sets = {}", "task[0].goal_sets"),
    ("goal_sets = [[7, 1], [7, 7]]", "task[0].goal_sets"),
])
def test_bad_goal_sets_name_the_file_and_the_set(goal_sets, where):
    with pytest.raises(CardError) as info:
        parse_card(ONE + goal_sets, "tasks/bad.toml")
    assert str(info.value).startswith(f"tasks/bad.toml: {where}:") and "\n" not in str(info.value)


def test_a_goal_set_clashing_with_an_id_is_a_duplicate():
    text = ONE + "goal_sets = { L1 = [[7, 1], [7, 7]] }\n" + ONE.split("\n", 1)[1].replace("T-v0", "T-L1-v0")
    with pytest.raises(CardError, match="'GRAIL/T-L1-v0' is defined twice"):
        parse_card(text, "tasks/bad.toml")


# gr_libs 1.0.3, gr_libs/problems/consts.py: PROBLEMS[domain][problem][L1..L4]["G_0"]["goals"], as written there.
# PointMaze goals are its (x, y); the cards' are (row, col) = (y, x).
GR_LIBS = {
    "MiniGrid-SimpleCrossing": [[(11, 1), (11, 11), (1, 11)], [(11, 1), (11, 11), (1, 11), (5, 9)],
                                [(11, 1), (11, 11), (1, 11), (5, 9), (6, 1)],
                                [(11, 1), (11, 11), (1, 11), (5, 9), (6, 1), (11, 3)]],
    "MiniGrid-LavaCrossing": [[(1, 3), (6, 5), (4, 7)], [(1, 3), (6, 5), (4, 7), (2, 5)],
                              [(1, 3), (6, 5), (4, 7), (2, 5), (5, 2)],
                              [(1, 3), (6, 5), (4, 7), (2, 5), (5, 2), (4, 5)]],
    "PointMaze-FourRooms": [[(4, 4), (7, 3), (3, 7)], [(4, 4), (7, 3), (3, 7), (8, 2)],
                            [(4, 4), (7, 3), (3, 7), (8, 2), (2, 8)], [(4, 4), (7, 3), (3, 7), (8, 2), (2, 8), (3, 4)]],
    "PointMaze-Obstacles": [[(5, 5), (7, 4), (4, 7)], [(5, 5), (3, 6), (7, 4)], [(5, 5), (3, 6), (7, 4), (4, 7)],
                            [(3, 6), (6, 3), (7, 4), (4, 7), (8, 8)]],
    "PandaReach-GrLibs": [[(-0.1, -0.1, 0.1), (-0.1, 0.1, 0.1), (0.2, 0.2, 0.1)],
                          [(-0.5, -0.5, 0.1), (-0.5, 0.2, 0.1), (-0.1, 0.1, 0.1), (0.1, -0.1, 0.1)],
                          [(-0.5, -0.5, 0.1), (-0.1, -0.1, 0.1), (-0.5, 0.2, 0.1), (-0.1, 0.1, 0.1), (0.2, -0.2, 0.1),
                           (0.2, 0.2, 0.1)],
                          [(-0.3, -0.3, 0.1), (-0.1, -0.1, 0.1), (-0.3, 0.2, 0.1), (-0.1, 0.1, 0.1), (0.1, -0.1, 0.1),
                           (0.2, 0.2, 0.1)]],
    "Parking": [[(1,), (11,), (21,)], [(1,), (8,), (14,), (21,)], [(1,), (8,), (11,), (18,)],
                [(4,), (8,), (11,), (14,), (18,)]],
}
REGIMES = {"MiniGrid-SimpleCrossing": ("Optimal", "Biased", "Suboptimal"),
           "MiniGrid-LavaCrossing": ("Optimal", "Suboptimal"),
           "PointMaze-FourRooms": ("Optimal", "Biased", "Noisy-0.1", "Noisy-0.3"),
           "PointMaze-Obstacles": ("Optimal", "Biased", "Noisy-0.1", "Noisy-0.3"),
           "PandaReach-GrLibs": ("Optimal", "Gaussian-0.1", "Gaussian-0.3", "Uniform-0.1", "Uniform-0.3"),
           "Parking": ("Optimal", "Noisy-0.1", "Noisy-0.3")}


@pytest.mark.parametrize("problem", sorted(GR_LIBS))
def test_gr_libs_levels_are_its_goal_sets_in_every_regime(problem):
    for regime in REGIMES[problem]:
        largest = grail_bench.make_task(f"GRAIL/{problem}-{regime}-v0")  # the unsuffixed ID is L5
        for level, expected in enumerate(GR_LIBS[problem], start=1):
            task = grail_bench.make_task(f"GRAIL/{problem}-{regime}-L{level}-v0")
            goals = [(y, x) for x, y in expected] if problem.startswith("PointMaze") else expected
            assert task.goals == tuple(goals), (problem, regime, level)
            assert set(task.goals) < set(largest.goals)
            same = {k: v for k, v in largest.params.items() if k != "routes"}
            assert {k: v for k, v in task.params.items() if k != "routes"} == same
            assert (task.env_params, task.observability, task.protocol, task.rounding) == (
                largest.env_params, largest.observability, largest.protocol, largest.rounding)


def _digest(task: GRTask) -> str:
    """What identifies a task's results: its domain, regime, goals and every parameter."""
    payload = {"domain": task.domain, "regime": task.regime, "goals": task.goals, "params": dict(task.params),
               "env": dict(task.env_params), "n_demos": task.n_demos, "n_train": task.n_train,
               "observability": task.observability, "protocol": task.protocol, "rounding": task.rounding}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:12]


# Every ID registered before goal sets existed, with its digest then: adding goal sets changed none of them.
BEFORE_GOAL_SETS = {
    "GRAIL/MiniGrid-Biased-4Goals-v0": "5bd54c89b669",
    "GRAIL/MiniGrid-Biased-6Goals-v0": "549cc228a320",
    "GRAIL/MiniGrid-Biased-v0": "b73cc4579fe7",
    "GRAIL/MiniGrid-LavaCrossing-Optimal-v0": "28b44e46b287",
    "GRAIL/MiniGrid-LavaCrossing-Suboptimal-v0": "c337b0309882",
    "GRAIL/MiniGrid-Optimal-12Goals-v0": "235441d91034",
    "GRAIL/MiniGrid-Optimal-24Goals-v0": "08315dcc70b8",
    "GRAIL/MiniGrid-Optimal-4Goals-v0": "7984aeda76ee",
    "GRAIL/MiniGrid-Optimal-6Goals-v0": "a675ff12d19f",
    "GRAIL/MiniGrid-Optimal-v0": "0b8ee9ca673b",
    "GRAIL/MiniGrid-SimpleCrossing-Biased-v0": "6f9257f2d6c9",
    "GRAIL/MiniGrid-SimpleCrossing-Optimal-v0": "253e22cf3766",
    "GRAIL/MiniGrid-SimpleCrossing-Suboptimal-v0": "b3588a4de988",
    "GRAIL/MiniGrid-Suboptimal-4Goals-v1": "2def8f015d0d",
    "GRAIL/MiniGrid-Suboptimal-6Goals-v1": "1b8b970a9fa6",
    "GRAIL/MiniGrid-Suboptimal-v1": "34d376b07086",
    "GRAIL/PandaReach-Aligned-Gaussian-0.1-v0": "3a8cb34a2d71",
    "GRAIL/PandaReach-Aligned-Gaussian-0.3-v0": "fc445cc64cd2",
    "GRAIL/PandaReach-Aligned-Optimal-v0": "32c757b3fcfe",
    "GRAIL/PandaReach-Aligned-Uniform-0.1-v0": "58e2817064b9",
    "GRAIL/PandaReach-Aligned-Uniform-0.3-v0": "fb78353e65d6",
    "GRAIL/PandaReach-Gaussian-0.1-12Goals-v0": "5509d1bed87c",
    "GRAIL/PandaReach-Gaussian-0.1-8Goals-v0": "eaa6791d8e26",
    "GRAIL/PandaReach-Gaussian-0.1-v0": "7acdc53c25e2",
    "GRAIL/PandaReach-Gaussian-0.3-v0": "a87e13e821de",
    "GRAIL/PandaReach-Optimal-v0": "fa862073f7d4",
    "GRAIL/PandaReach-Uniform-0.1-v0": "7ff361146ea1",
    "GRAIL/PandaReach-Uniform-0.3-v0": "05285eda94e0",
    "GRAIL/PointMaze-Biased-v0": "9e7c52a6958f",
    "GRAIL/PointMaze-FourRooms-Biased-v0": "d0d7bf6a900c",
    "GRAIL/PointMaze-FourRooms-Noisy-0.1-v0": "4573f8a0c0e7",
    "GRAIL/PointMaze-FourRooms-Noisy-0.3-v0": "c826750a331c",
    "GRAIL/PointMaze-FourRooms-Optimal-v0": "71697a97b5d5",
    "GRAIL/PointMaze-Noisy-0.1-v0": "0f15bdc7955f",
    "GRAIL/PointMaze-Noisy-0.3-v0": "56ee6e202dcb",
    "GRAIL/PointMaze-Obstacles-Biased-v0": "248014e4689e",
    "GRAIL/PointMaze-Obstacles-Noisy-0.1-v0": "9f07fbdf0aaf",
    "GRAIL/PointMaze-Obstacles-Noisy-0.3-v0": "471c4ba7e62d",
    "GRAIL/PointMaze-Obstacles-Optimal-v0": "da3f058cd3ac",
    "GRAIL/PointMaze-Optimal-10Goals-v0": "40e3ba87f988",
    "GRAIL/PointMaze-Optimal-v0": "13b75327dfca",
    "GRAIL/Symbolic-Blocks-Optimal-v0": "1eafc2187b26",
    "GRAIL/Symbolic-Blocks-Suboptimal-v0": "329f75f2684d",
    "GRAIL/Symbolic-Grid-Biased-v0": "7ee4affe5bc1",
    "GRAIL/Symbolic-Grid-Optimal-v0": "6e2cfba01c3e",
    "GRAIL/Symbolic-Grid-Suboptimal-v0": "f6c743e6086d",
    "GRAIL/Symbolic-Logistics-Biased-v0": "60fbdc126bfb",
    "GRAIL/Symbolic-Logistics-Optimal-v0": "7af17112b519",
    "GRAIL/Symbolic-Logistics-Suboptimal-v0": "803b4d1b6c27",
}


def test_existing_ids_are_unchanged():
    tasks = shipped_tasks()
    assert set(BEFORE_GOAL_SETS) <= set(tasks)
    assert {i: _digest(tasks[i]) for i in BEFORE_GOAL_SETS} == BEFORE_GOAL_SETS


@pytest.mark.parametrize("task_id, stored", [("GRAIL/MiniGrid-SimpleCrossing-Optimal-v0", "7510655cdd34"),
                                             ("GRAIL/PointMaze-Obstacles-Noisy-0.3-v0", "ce8b4766898d"),
                                             ("GRAIL/PandaReach-Aligned-Gaussian-0.1-v0", "3bd6cc9b80a5")])
def test_stored_configuration_hashes_are_unchanged(task_id, stored):
    assert config_hash(fitted_config(grail_bench.make_task(task_id), "bc", {})) == stored
