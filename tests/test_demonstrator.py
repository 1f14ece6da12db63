"""The ``demonstrator`` reference recognizer and the domains' ``demonstrator_policy``."""

from __future__ import annotations

import numpy as np
import pytest
from grail_bench.core.trajectory import Trajectory

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.core.spaces import state_index
from grail_bench.core.trajectory import until_success
from grail_bench.domains.minigrid.demos import fixed_path, optimal_successors, shortest_path_graph
from grail_bench.domains.minigrid.grid import FORWARD, LEFT, RIGHT, STAY
from grail_bench.domains.minigrid.likelihood import GoalDemonstrator
from grail_bench.recognizers import make_recognizer

OPTIMAL = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")


def tables(task, support: str = "everywhere") -> tuple[np.ndarray, object]:
    """The recognizer's (K, S, A) table on ``task``, fitted from the goals alone, and the task's env."""
    rec = make_recognizer("demonstrator", support=support)
    report = rec.fit({goal: [] for goal in task.goals}, task.env_factory(), seed=0)
    assert report.trained == len(task.goals) and report.train_seconds >= 0
    return rec.probs, task.make_env()


def row(table: np.ndarray, env, state) -> np.ndarray:
    return table[int(state_index(np.array([state]), env.observation_space)[0])]


def test_optimal_is_the_shortest_path_count_weights_and_stays_on_the_goal():
    probs, env = tables(OPTIMAL)
    base, k = env.unwrapped, OPTIMAL.goal_index((7, 1))
    model, start = base.model, (*base.start, base.start_dir)
    dist, count = shortest_path_graph(model, (7, 1))
    succ = optimal_successors(model, dist, start)
    expected = np.zeros(4)
    for action, nxt in succ.items():
        expected[action] = count[nxt]
    np.testing.assert_allclose(row(probs[k], env, start), expected / expected.sum())
    assert len(succ) == 2  # a real mixture: forward (east) and left (north)
    np.testing.assert_allclose(probs.sum(-1), 1.0)
    for state in model.states():
        p = row(probs[k], env, state)
        if state[:2] == (7, 1):
            assert p[STAY] == 1.0
        else:
            assert set(np.flatnonzero(p)) <= set(optimal_successors(model, dist, state))


def test_optimal_equals_the_marginal_over_the_enumerated_support():
    probs, env = tables(OPTIMAL, "demonstrated")
    demonstrator = GoalDemonstrator(OPTIMAL, (7, 7))
    counts: dict = {}
    for actions, weight in demonstrator.support():
        for *state, action in demonstrator.pairs(actions):
            counts.setdefault(tuple(state), np.zeros(4))[action] += weight
    for state, c in counts.items():
        np.testing.assert_allclose(row(probs[OPTIMAL.goal_index((7, 7))], env, state), c / c.sum())


def test_route_regimes_follow_their_route_with_probability_one():
    for task in (grail_bench.make_task("GRAIL/MiniGrid-Biased-v0"), OPTIMAL.with_overrides(route_choice="fixed")):
        probs, env = tables(task)
        for k, goal in enumerate(task.goals):
            demonstrator = GoalDemonstrator(task, goal)
            assert demonstrator.fixed
            for *state, action in demonstrator.pairs(demonstrator.paths[0]):
                assert row(probs[k], env, tuple(state))[action] == 1.0
    # off the fixed route: the fixed path from there (straight ahead first)
    model = env.unwrapped.model
    off = (1, 1, 1)  # north-west corner, facing south
    assert row(probs[0], env, off)[fixed_path(model, off, (7, 1))[0]] == 1.0


def test_suboptimal_turns_and_the_monte_carlo_marginal():
    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1")
    probs, env = tables(task)
    demonstrated, _ = tables(task, "demonstrated")
    base = env.unwrapped
    start = (*base.start, base.start_dir)
    for k in range(len(task.goals)):
        p = row(probs[k], env, start)
        assert p[LEFT] > 0 and p[RIGHT] > 0 and p[STAY] == 0
    # off the demonstrations, where forward is the only optimal move: a left-right insertion, then forward
    dist, _ = shortest_path_graph(base.model, (7, 1))
    off = [s for s in base.model.states() if s in dist and dist[s] > 0
           and set(optimal_successors(base.model, dist, s)) == {FORWARD}
           and np.allclose(row(demonstrated[0], env, s), 0.25)]
    assert off
    for state in off:
        np.testing.assert_allclose(row(probs[0], env, state), [0.25, 0.25, 0.5, 0.0])
    # the exact marginal against action frequencies in generated demonstrations (visited often enough)
    demos = task.generate_demos(seed=0, n_demos=300)
    for k, goal in enumerate(task.goals):
        counts = np.zeros_like(probs[k])
        for traj in demos[goal]:
            traj = until_success(traj)
            np.add.at(counts, (state_index(traj.obs[:-1], env.observation_space), np.asarray(traj.acts)), 1)
        visits = counts.sum(1)
        seen = visits > 0
        np.testing.assert_array_equal(seen, np.any(demonstrated[k] != 0.25, axis=1) & (demonstrated[k][:, STAY] == 0))
        estimate = counts[seen] / visits[seen, None]
        tolerance = 2.5 * 0.5 / np.sqrt(visits[seen, None])  # 2.5 binomial standard errors at p = 1/2
        assert np.all(np.abs(probs[k][seen] - estimate) <= tolerance)


def test_demonstrated_is_uniform_off_the_demonstrations_and_equal_on_them():
    everywhere, env = tables(OPTIMAL)
    demonstrated, _ = tables(OPTIMAL, "demonstrated")
    k = OPTIMAL.goal_index((7, 1))
    corner = (1, 7, 1)  # south-west corner, facing the wall: no demonstration of (7, 1) goes there
    np.testing.assert_allclose(row(demonstrated[k], env, corner), 0.25)
    assert row(everywhere[k], env, corner).max() > 0.25
    train, _ = OPTIMAL.split(OPTIMAL.generate_demos(seed=0))
    visited = np.unique(np.concatenate([state_index(until_success(t).obs, env.observation_space)
                                        for t in train[(7, 1)]]))
    np.testing.assert_array_equal(demonstrated[k][visited], everywhere[k][visited])


@pytest.mark.parametrize("support", ["everywhere", "demonstrated"])
def test_evaluates_end_to_end_without_training(support):
    records = grail_bench.evaluate("GRAIL/MiniGrid-Optimal-4Goals-v0", [("demonstrator", {"support": support})],
                                   seeds=2)
    assert records and {r.scorer for r in records} == {"mse"}
    assert all(0.0 <= r.f1.mean <= 1.0 for r in records)


def test_point_maze_biased_is_its_route_on_the_rollout_and_no_preference_elsewhere():
    from grail_bench.domains.point_maze.likelihood import RouteDemonstrator
    from grail_bench.domains.point_maze.policy import STD_FLOOR, UNIFORM_STD

    task = grail_bench.make_task("GRAIL/PointMaze-Biased-v0")
    goal = task.goals[0]
    demonstrator = RouteDemonstrator(task, goal)
    pairs = np.array(demonstrator.pairs(demonstrator.routes[0]), dtype=np.float32)
    off = np.array([[0.3, 0.2, 0.5, -0.4]], dtype=np.float32)
    for support in ("everywhere", "demonstrated"):
        policy = task.spec.demonstrator_policy(task, goal, support)
        mean, std = policy(pairs[:, :4])
        np.testing.assert_allclose(mean, pairs[:, 4:], atol=1e-7)
        np.testing.assert_allclose(std, STD_FLOOR)
        mean, std = policy(off)
        if support == "demonstrated":
            np.testing.assert_allclose(mean, 0.0)
            np.testing.assert_allclose(std, UNIFORM_STD)
        else:
            assert np.abs(mean).max() > 0 and np.all(np.abs(mean) <= 1.0)
    rec = make_recognizer("demonstrator")
    assert rec.exposes(task.make_env().action_space) == {"mean", "std"}
    rec.fit({g: [] for g in task.goals}, task.env_factory(), seed=0)
    observed = Trajectory(obs=np.concatenate([pairs[:30, :4], pairs[30:31, :4]]), acts=pairs[:30, 4:], infos=None,
                          terminal=False)
    scores = rec.score(observed, "loglik")
    assert max(scores, key=scores.get) == goal


@pytest.mark.parametrize("task_id, message", [
    ("GRAIL/PandaReach-Aligned-Optimal-v0", "minigrid, point_maze"),
    ("GRAIL/PointMaze-Noisy-0.1-v0", "optimal and biased"),
])
def test_refuses_domains_and_regimes_without_a_stated_distribution_in_one_line(task_id, message):
    task = grail_bench.make_task(task_id)
    for attempt in (lambda rec: rec.check_task(task),  # where a run is planned, before any demonstration
                    lambda rec: rec.fit({goal: [] for goal in task.goals}, task.env_factory(), seed=0)):
        with pytest.raises(UserError) as err:
            attempt(make_recognizer("demonstrator"))
        assert message in str(err.value) and "\n" not in str(err.value)
    make_recognizer("demonstrator").check_task(OPTIMAL)  # served: no error


def test_settings():
    rec = make_recognizer("demonstrator")
    assert rec.config.support == "everywhere" and rec.default_scorer == "mse"
    assert rec.paper_name == "Demonstrator (perfect imitation)"
    with pytest.raises(UserError, match="support") as err:
        make_recognizer("demonstrator", support="nowhere")
    assert "\n" not in str(err.value)
