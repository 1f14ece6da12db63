"""Speed targets (``make bench``): medians are what the README and notes report.

Targets (2-core CPU): BC-GRAIL scores a 30-step observation against 6 goals in
<= 100 us and fits a goal in <= 1 s; GRAQL fits a goal in <= 10 s and scores
in <= 100 us.
"""

from __future__ import annotations

import numpy as np
import pytest
from imitation.data.types import Trajectory

import grail_bench
from grail_bench.recognizers import make_recognizer
from grail_bench.recognizers._torch import single_thread

TASK = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-6Goals-v0")
TRAIN, TEST = TASK.split(TASK.generate_demos(seed=0))
GOAL = TASK.goals[0]


def thirty_steps() -> Trajectory:
    traj = TEST[GOAL][0]
    return Trajectory(obs=traj.obs[:31], acts=traj.acts[:30], infos=None, terminal=False)


@pytest.fixture(scope="module")
def bc():
    rec = make_recognizer("bc")
    rec.fit(TRAIN, TASK.make_env, seed=0)
    return rec


@pytest.fixture(scope="module")
def graql():
    rec = make_recognizer("graql")
    rec.fit(TRAIN, TASK.make_env, seed=0)
    return rec


def test_bc_score_30_steps_6_goals(benchmark, bc):
    observed = thirty_steps()
    scores = benchmark(bc.score, observed)
    assert len(scores) == 6


def test_bc_fit_one_goal(benchmark, bc):
    def fit():
        with single_thread():
            return bc.train_policy(GOAL, TRAIN[GOAL], TASK.make_env, seed=1)

    benchmark.pedantic(fit, rounds=5, warmup_rounds=1)


def test_graql_score_30_steps_6_goals(benchmark, graql):
    scores = benchmark(graql.score, thirty_steps())
    assert len(scores) == 6


def test_graql_fit_one_goal(benchmark):
    rec = make_recognizer("graql")
    benchmark.pedantic(rec.fit, args=({GOAL: TRAIN[GOAL], TASK.goals[1]: []}, TASK.make_env),
                       kwargs={"seed": 0}, rounds=3)  # two goals per round: see the per-goal median / 2


def test_minigrid_env_step(benchmark):
    env = TASK.make_env(GOAL)
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 3, size=1 << 16)
    state = {"i": 0}

    def step():
        i = state["i"] = (state["i"] + 1) % len(actions)
        _, _, terminated, truncated, _ = env.step(int(actions[i]))
        if terminated or truncated:
            env.reset()

    benchmark(step)
