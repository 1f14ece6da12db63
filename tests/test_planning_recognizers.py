"""The planning-based recognizers (``prp``, ``landmarks``) on hand-made grid problems written here as PDDL."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from grail_bench.core.trajectory import Trajectory

import grail_bench
from grail_bench import GRTask
from grail_bench.contrib.landmarks import LandmarkRecognizer, fact_landmarks
from grail_bench.contrib.prp import LOG_ZERO, PRPRecognizer, log_likelihood
from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.generator import GRID_DOMAIN
from grail_bench.recognizers import make_recognizer
from grail_bench.task.observation import observe, project

NAMES = ("prp", "landmarks")


def grid_problem(root: Path, cells: list[str], edges: list[tuple[str, str]], start: str, goals: list[str]) -> str:
    """A grid problem in the dataset's layout, as a folder; ``edges`` are undirected."""
    root.mkdir(parents=True, exist_ok=True)
    init = [f"(robot-at {start})"] + [f"(adjacent {a} {b}) (adjacent {b} {a})" for a, b in edges]
    (root / "domain.pddl").write_text(GRID_DOMAIN)
    (root / "template.pddl").write_text(
        f"(define (problem p) (:domain grid-navigation) (:objects {' '.join(cells)} - cell)\n"
        f"  (:init {' '.join(init)})\n  (:goal (and <HYPOTHESIS>)))\n")
    (root / "hyps.dat").write_text("".join(f"(robot-at {g})\n" for g in goals))
    (root / "obs.dat").write_text("")
    (root / "real_hyp.dat").write_text(f"(robot-at {goals[0]})\n")
    return str(root)


def rows(n_rows: int, n_cols: int) -> tuple[list[str], list[tuple[str, str]]]:
    """Cells ``a0``, ``a1``, ... (row letter, column digit) of an open grid and their 4-neighbour edges."""
    cells = [f"{chr(97 + r)}{c}" for r in range(n_rows) for c in range(n_cols)]
    edges = [(f"{chr(97 + r)}{c}", f"{chr(97 + r)}{c + 1}") for r in range(n_rows) for c in range(n_cols - 1)]
    edges += [(f"{chr(97 + r)}{c}", f"{chr(98 + r)}{c}") for r in range(n_rows - 1) for c in range(n_cols)]
    return cells, edges


def task_of(problem: str, regime: str = "optimal") -> GRTask:
    return GRTask(id="GRAIL/Test-Grid-v0", domain="symbolic", regime=regime, goals=((0,), (1,)),
                  env_params={"problem": problem}, n_demos=10, n_train=4, protocol="subset")


@pytest.fixture(scope="module")
def crossroads(tmp_path_factory) -> GRTask:
    """A 3x3 open grid from the middle of its left column to its two right corners (3 moves, 3 optimal
    plans each, the first move often shared)."""
    cells, edges = rows(3, 3)
    return task_of(grid_problem(tmp_path_factory.mktemp("cross"), cells, edges, "b0", ["a2", "c2"]))


@pytest.fixture(scope="module")
def square(tmp_path_factory) -> PRPRecognizer:
    """``prp`` fitted on a 2x3 open grid from ``a0``: goal 0 ``b2`` (3 moves), goal 1 ``a2`` (2 moves)."""
    cells, edges = rows(2, 3)
    task = task_of(grid_problem(tmp_path_factory.mktemp("square"), cells, edges, "a0", ["b2", "a2"]))
    rec = make_recognizer("prp")
    rec.fit({g: [] for g in task.goals}, task.make_env)
    return rec


@pytest.fixture(scope="module")
def corridor(tmp_path_factory) -> GRTask:
    """A corridor ``A - a2 - a1 - s - b1 - b2 - B`` from ``s``: goal 0 ``A``, goal 1 ``B``."""
    cells = ["ga", "a2", "a1", "s", "b1", "b2", "gb"]
    return task_of(grid_problem(tmp_path_factory.mktemp("corridor"), cells, list(zip(cells, cells[1:])), "s",
                                ["ga", "gb"]))


def actions(rec, *texts: str) -> Trajectory:
    """An observation of these actions only (the actions channel: states NaN)."""
    acts = np.array([rec.model.operator_index(t) for t in texts])
    return Trajectory(obs=np.full((len(acts) + 1, rec.model.n_fluents), np.nan), acts=acts, infos=None,
                      terminal=False)


def fitted(name: str, task: GRTask, **settings):
    rec = make_recognizer(name, **settings)
    rec.fit(task.split(task.generate_demos(seed=0))[0], task.make_env, seed=0)
    return rec


def true_rank(scores: dict, goal) -> float:
    """The true goal's rank, 1 = best, ties shared (a tie of two at the top ranks 1.5)."""
    others = [v for g, v in scores.items() if g != goal]
    return 1 + sum(v > scores[goal] for v in others) + 0.5 * sum(v == scores[goal] for v in others)


def posterior(name: str, scores: dict, goal) -> float:
    """The true goal's posterior: the softmax of prp's log-likelihoods; landmarks' heuristic values normalised
    (the paper gives no posterior; a share of the summed values, uniform when every value is 0)."""
    values = np.array(list(scores.values()), dtype=float)
    index = list(scores).index(goal)
    if name == "prp":
        p = np.exp(values - values.max())
        return float(p[index] / p.sum())
    return float(values[index] / values.sum()) if values.sum() > 0 else 1 / len(values)


@pytest.mark.parametrize("name", NAMES)
def test_full_observability_recovers_the_true_goal(name, crossroads):
    rec = fitted(name, crossroads)
    for seed in range(3):
        _, test = crossroads.split(crossroads.generate_demos(seed=seed))
        for goal, trajs in test.items():
            for traj in trajs:
                scores = rec.score(observe(traj, 1.0))
                assert true_rank(scores, goal) == 1, (goal, scores)


@pytest.mark.parametrize("name", NAMES)
def test_fewer_observations_rank_and_sharpen_no_better(name, crossroads):
    rec = fitted(name, crossroads)
    ranks, sharp = {}, {}
    for level in (0.1, 0.5, 1.0):
        r, p = [], []
        for seed in range(5):
            rng = np.random.default_rng(seed)
            _, test = crossroads.split(crossroads.generate_demos(seed=seed))
            for goal, trajs in test.items():
                for traj in trajs:
                    scores = rec.score(observe(traj, level, "subset", rng))
                    r.append(true_rank(scores, goal))
                    p.append(posterior(name, scores, goal))
        ranks[level], sharp[level] = np.mean(r), np.mean(p)
    assert ranks[0.1] >= ranks[0.5] >= ranks[1.0] == 1.0
    assert ranks[0.1] > 1.0  # one observed move of three is often shared by both goals' plans
    assert sharp[1.0] > sharp[0.1]


def test_prp_costs_by_hand(square):
    """2x3 grid from a0: b2 takes 3 moves (3 optimal plans), a2 takes 2 (one plan)."""
    b2, a2 = (0,), (1,)
    cases = {
        # a0->a1 lies on an optimal plan of both; a2 without it: a0 b0 b1 (a1|b2) a2.
        ("(move a0 a1)",): {b2: (3, 3), a2: (2, 4)},
        # a0->b0 lies on an optimal plan of b2 only; a2 through it: a0 b0 b1 (a1|b2) a2.
        ("(move a0 b0)",): {b2: (3, 3), a2: (4, 2)},
        # a gap between the two observed moves: a0 b0 [b1] a1, then a2 (and b2 one move further).
        ("(move a0 b0)", "(move b1 a1)"): {b2: (5, 3), a2: (4, 2)},
    }
    for texts, expected in cases.items():
        observed = actions(square, *texts)
        assert square.costs(observed) == expected
        scores = square.score(observed)
        for goal, (c_with, c_without) in expected.items():
            assert scores[goal] == pytest.approx(-math.log(1 + math.exp(c_with - c_without)) - math.log(2))
    assert square.score(actions(square, "(move a0 b0)"))[b2] > square.score(actions(square, "(move a0 b0)"))[a2]


def test_prp_infinite_costs_as_the_paper_treats_them(corridor):
    rec = fitted("prp", corridor)
    observed = actions(rec, "(move s a1)")
    # Every plan to ga takes s->a1: no plan avoids O, so P(O | ga) = 1; gb goes there and back.
    assert rec.costs(observed) == {(0,): (3, math.inf), (1,): (5, 3)}
    assert rec.score(observed)[(0,)] == pytest.approx(math.log(0.5))
    assert log_likelihood(math.inf, 3) == LOG_ZERO and log_likelihood(math.inf, math.inf) == LOG_ZERO
    assert log_likelihood(3, math.inf) == 0.0
    assert LOG_ZERO < log_likelihood(1000, 0) < log_likelihood(1, 0)


def test_landmarks_by_hand(corridor):
    rec = fitted("landmarks", corridor)
    m = rec.model
    index = {c: m.fluent_index(("robot-at", c)) for c in ("ga", "a2", "a1", "s", "b1", "b2", "gb")}
    graph = fact_landmarks(m, index["ga"])
    assert graph.landmarks == {index[c] for c in ("ga", "a2", "a1", "s")}  # the corridor's cells, start included
    assert graph.closure({index["a2"]}) == {index["a2"], index["a1"], index["s"]}  # a2 implies the way there
    observed = actions(rec, "(move s a1)")  # achieves s (precondition, and initially) and a1
    assert rec.score(observed) == {(0,): 0.5, (1,): 0.25}
    uniq = make_recognizer("landmarks", heuristic="uniqueness")
    uniq.fit({g: [] for g in corridor.goals}, corridor.make_env)
    # s is a landmark of both goals (uniqueness 1/2), every other landmark of one.
    assert uniq.score(observed) == pytest.approx({(0,): 1.5 / 3.5, (1,): 0.5 / 3.5})


@pytest.mark.parametrize("name", NAMES)
def test_refuses_a_minigrid_task_in_one_line(name):
    task = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
    rec = make_recognizer(name)
    for attempt in (lambda: rec.check_task(task), lambda: rec.fit({g: [] for g in task.goals}, task.make_env)):
        with pytest.raises(UserError, match="symbolic") as err:
            attempt()
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", NAMES)
def test_same_inputs_same_scores_on_either_channel(name, crossroads):
    _, test = crossroads.split(crossroads.generate_demos(seed=1))
    observed = observe(test[(1,)][0], 0.5, "subset", np.random.default_rng(0))
    first, second = fitted(name, crossroads), fitted(name, crossroads)
    assert first.score(observed) == second.score(observed) == first.score(project(observed, "actions"))
    with pytest.raises(UserError, match="states only"):
        first.score(project(observed, "states"))
    crossroads_check = make_recognizer(name)
    crossroads_check.check_task(crossroads)  # a symbolic task: accepted


@pytest.mark.parametrize("name", NAMES)
def test_goals_it_was_not_fitted_on_score_as_if_fitted(name, crossroads):
    """Nothing is learnt per goal: fitted on one goal and told both, it scores as when fitted on both."""
    _, test = crossroads.split(crossroads.generate_demos(seed=2))
    observed = observe(test[(0,)][1], 0.5, "subset", np.random.default_rng(1))
    zero_shot = make_recognizer(name)
    with pytest.raises(RuntimeError, match="fit"):
        zero_shot.set_goals(list(crossroads.goals))
    zero_shot.fit({(1,): []}, crossroads.make_env)
    zero_shot.set_goals(list(crossroads.goals))
    assert zero_shot.score(observed) == fitted(name, crossroads).score(observed)


@pytest.mark.parametrize("name", NAMES)
def test_bad_input_is_one_line(name, crossroads):
    rec = fitted(name, crossroads)
    traj = crossroads.generate_demos(seed=0)[(0,)][0]
    with pytest.raises(UserError, match="empty"):
        rec.score(SimpleNamespace(obs=traj.obs[:1], acts=traj.acts[:0]))
    with pytest.raises(UserError, match="expected a Trajectory"):
        rec.score("not a trajectory")
    with pytest.raises(UserError, match="outside"):
        rec.score(Trajectory(obs=traj.obs[:2], acts=np.array([rec.model.n_operators]), infos=None, terminal=False))
    with pytest.raises(RuntimeError, match="fit"):
        make_recognizer(name).score(traj)
    with pytest.raises(UserError, match="unexpected keyword"):
        make_recognizer(name, nope=1)


def test_settings_are_checked_and_the_node_limit_stops_prp(crossroads):
    with pytest.raises(UserError, match="beta"):
        make_recognizer("prp", beta=0.0)
    with pytest.raises(UserError, match="heuristic"):
        make_recognizer("landmarks", heuristic="nope")
    rec = fitted("prp", crossroads, node_limit=2)
    traj = crossroads.generate_demos(seed=0)[(0,)][0]
    with pytest.raises(UserError, match="node limit of 2") as err:
        rec.score(observe(traj, 1.0))
    assert "\n" not in str(err.value)
    assert isinstance(rec, PRPRecognizer) and isinstance(fitted("landmarks", crossroads), LandmarkRecognizer)
