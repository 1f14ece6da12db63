"""``bip``, Bayesian inverse planning: its likelihood is the Boltzmann demonstrator's, its fit recovers the
demonstrator's rationality, and it refuses what it cannot value exactly."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import grail_bench
from grail_bench.contrib.bip import LOG_ZERO, BIPRecognizer
from grail_bench.core.errors import UserError
from grail_bench.core.spaces import state_index
from grail_bench.core.trajectory import Trajectory
from grail_bench.domains.boltzmann import BoltzmannDemonstrator, BETA
from grail_bench.task.model import GRTask
from grail_bench.task.observation import Selection, n_observed, observe


def observation_space(task: GRTask):
    env = task.make_env(task.goals[0])
    env.close()
    return env.observation_space


def minigrid(beta: float, goals=((7, 1), (7, 7), (7, 3))) -> GRTask:
    return GRTask(id="GRAIL/MiniGrid-Boltzmann-v0", domain="minigrid", regime="boltzmann", goals=goals,
                  params={"beta": beta}, n_demos=40, n_train=30)


def symbolic(beta: float) -> GRTask:
    return GRTask(id="GRAIL/Symbolic-Blocks-Boltzmann-v0", domain="symbolic", regime="boltzmann",
                  goals=((0,), (1,), (2,)), params={"beta": beta}, env_params={"problem": "blocks"},
                  n_demos=40, n_train=30)


@pytest.mark.parametrize("level", [0.1, 0.3, 1.0])
def test_likelihood_equals_the_demonstrators_when_beta_matches(level):
    task = minigrid(0.6)
    train, test = task.split(task.generate_demos(seed=0))
    rec = BIPRecognizer(beta=0.6)
    rec.fit(train, task.make_env)
    # a horizon prefix observes the first k steps whatever the path (k is fixed by the horizon), so its exact
    # likelihood is the product of the steps' probabilities, the no-op on the goal after it included
    selection = Selection(horizon=True, random_subset=False, level=level)
    demonstrators = [BoltzmannDemonstrator(task, goal) for goal in task.goals]
    space = observation_space(task)
    for goal in task.goals:
        for traj in test[goal][:4]:
            k = n_observed(level, len(traj.acts))
            observed = Trajectory(obs=traj.obs[: k + 1], acts=traj.acts[:k], infos=None, terminal=False)
            pairs = tuple(zip(state_index(traj.obs[:k], space).tolist(), traj.acts[:k].tolist()))
            exact = np.array([d.likelihood(pairs, selection) for d in demonstrators])
            assert exact[task.goals.index(goal)] > 0
            ours, possible = rec.log_likelihoods(observed), exact > 0
            assert ours[possible] == pytest.approx(np.log(exact[possible]), rel=1e-9)
            assert (ours[~possible] <= LOG_ZERO).all()  # e.g. a path through another goal, which stops there
            posterior = np.exp(list(rec.score(observed).values()))
            assert posterior == pytest.approx(exact / exact.sum(), rel=1e-6, abs=1e-12)  # the Bayes posterior


def test_symbolic_likelihood_of_a_whole_demonstration_is_its_goals_demonstrators():
    task = symbolic(0.6)
    train, test = task.split(task.generate_demos(seed=0))
    rec = BIPRecognizer(beta=0.6)
    rec.fit(train, task.make_env)
    whole = Selection(horizon=False, random_subset=False, level=1.0)
    space = observation_space(task)
    for k, goal in enumerate(task.goals):
        d = BoltzmannDemonstrator(task, goal)
        for traj in test[goal]:
            pairs = tuple(zip(state_index(traj.obs[:-1], space).tolist(), traj.acts.tolist()))
            # the path ends on the goal: under its own goal's demonstrator, its probability is its steps'
            assert rec.log_likelihoods(traj)[k] == pytest.approx(np.log(d.likelihood(pairs, whole)), rel=1e-9)


@pytest.mark.parametrize("make, beta", [(minigrid, 0.4), (minigrid, 1.5), (symbolic, 1.0)])
def test_fitted_beta_recovers_the_demonstrators(make, beta):
    task = make(beta)
    train, _ = task.split(task.generate_demos(seed=1))
    rec = BIPRecognizer()
    rec.fit(train, task.make_env)
    assert rec.beta == pytest.approx(beta, rel=0.25)


def test_optimal_demonstrations_fit_the_largest_beta():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    train, _ = task.split(task.generate_demos(seed=0))
    rec = BIPRecognizer(beta_max=20.0)
    rec.fit(train, task.make_env)
    assert rec.beta == 20.0  # only optimal actions: the likelihood grows with beta


def test_online_posterior_ends_at_the_score_and_recognises_the_goal():
    task = minigrid(1.0)
    train, test = task.split(task.generate_demos(seed=2))
    rec = BIPRecognizer()
    rec.fit(train, task.make_env)
    right = 0
    for goal in task.goals:
        for traj in test[goal]:
            observed = observe(traj, 0.5)
            curves, scores = rec.score_prefixes(observed), rec.score(observed)
            assert {g: c[-1] for g, c in curves.items()} == pytest.approx(scores)
            assert np.logaddexp.reduce(list(scores.values())) == pytest.approx(0.0)  # a log posterior
            right += max(scores, key=scores.get) == goal
    assert right / (len(task.goals) * 10) > 2 / 3  # far above chance (1/3)


def test_refuses_tasks_without_exact_values_in_one_line():
    task = grail_bench.make_task(next(t for t in grail_bench.task_ids() if "PointMaze" in t))
    with pytest.raises(UserError, match="exact action values") as err:
        BIPRecognizer().check_task(task)
    assert "\n" not in str(err.value)
    BIPRecognizer().check_task(grail_bench.make_task("GRAIL/MiniGrid-Boltzmann-v0"))
    BIPRecognizer().check_task(grail_bench.make_task("GRAIL/Symbolic-Blocks-Optimal-v0"))


@pytest.mark.parametrize("settings", [{"beta": -1.0}, {"beta": BETA.high + 1}, {"beta_max": 0.0}])
def test_bad_settings_are_refused(settings):
    with pytest.raises(UserError):
        BIPRecognizer(**settings)


@pytest.mark.slow
def test_runs_end_to_end_from_the_command_line(tmp_path):
    env = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_STORE": str(tmp_path / "store.sqlite")}
    out = subprocess.run([sys.executable, "-m", "grail_bench", "run", "-r", "bip", "--task",
                          "GRAIL/MiniGrid-Boltzmann-v0", "--seeds", "1", "-o", "0.3", "--no-progress", "--json", str(tmp_path / "r.json")],
                         capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr
    rows = json.loads(Path(tmp_path / "r.json").read_text())
    assert rows and all(r["recognizer"] == "bip" for r in rows)
    assert all(r["task"] == "GRAIL/MiniGrid-Boltzmann-v0" for r in rows)
    assert {r["observability"] for r in rows} == {0.3}
