"""The symbolic (PDDL/STRIPS) domain: grounding, the optimal planner, the env, the demonstrators, their
likelihood and action tables, and the goal-recognition dataset's format both ways."""

from __future__ import annotations

import io
import itertools
import math
import tarfile
import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.core.spaces import state_index
from grail_bench.domains.symbolic.dataset import file_texts, load_problem, write_problem
from grail_bench.domains.symbolic.env import SymbolicEnv
from grail_bench.domains.symbolic.generator import BLOCKS_DOMAIN, builtin_problem, write_dataset
from grail_bench.domains.symbolic.likelihood import GoalDemonstrator
from grail_bench.domains.symbolic.planner import astar, optimal_plan_graph
from grail_bench.domains.symbolic.problem import GRProblem
from grail_bench.task.observation import Selection

#: Optimal plan lengths of the built-in problems' hypotheses, worked out by hand.
OPTIMAL = {"blocks": [6, 6, 6, 6], "grid": [5, 5, 6], "logistics": [8, 12, 5, 5]}

SWAP_TEMPLATE = """(define (problem swap) (:domain blocks) (:objects a b - block)
  (:init (handempty) (on a b) (ontable b) (clear a))
  (:goal (and <HYPOTHESIS>)))"""


def _swap(hyps: tuple = ((("on", "b", "a"),), (("ontable", "a"),))) -> GRProblem:
    """Two blocks, ``a`` on ``b``: swapping them takes 4 actions, putting ``a`` down 2."""
    return GRProblem("swap", BLOCKS_DOMAIN, SWAP_TEMPLATE, hyps, hyps[0], ())


def _archive(tmp_path, texts: dict[str, str], name: str = "p.tar.bz2"):
    path = tmp_path / name
    with tarfile.open(path, "w:bz2") as tar:
        for member, text in texts.items():
            data = text.encode()
            info = tarfile.TarInfo(member)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return path


@pytest.mark.parametrize("name", sorted(OPTIMAL))
def test_env_passes_gymnasium_checker(name):
    env = SymbolicEnv((0,), problem=name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env, skip_render_check=True)  # the render check needs gym.make: test_registration makes it
        check_env(gym.make(f"GRAIL/Symbolic-{name.capitalize()}-Optimal-v0").unwrapped)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and env.model.n_fluents <= 16


def test_hand_made_problem_plans_are_optimal():
    problem = _swap()
    model = problem.model
    for goal, length in zip(problem.goal_masks, (4, 2)):
        plan = astar(model, goal)
        assert len(plan) == length == len(astar(model, goal, heuristic="blind"))  # blind A* is breadth-first
        assert model.plan_states(plan)[-1] & goal == goal
    assert [model.operators[a].text for a in astar(model, problem.goal_masks[0])] == [
        "(unstack a b)", "(put-down a)", "(pick-up b)", "(stack b a)"]


def test_pddl_keywords_and_names_in_upper_case_read_as_lower_case():
    """PDDL is case-insensitive; some of the dataset's problems write ``(:INIT`` and ``(ON A B)``."""
    upper = GRProblem("swap", BLOCKS_DOMAIN.upper(), SWAP_TEMPLATE.upper(),
                      ((("on", "b", "a"),), (("ontable", "a"),)), (("on", "b", "a"),), ())
    assert upper.model.fluents == _swap().model.fluents
    assert len(astar(upper.model, upper.goal_masks[0])) == 4


@pytest.mark.parametrize("name", sorted(OPTIMAL))
def test_planner_is_optimal_and_the_env_agrees_on_every_optimal_plan(name):
    """A*'s length is the known optimum, the plan graph holds only plans of that length, and the env ends each
    exactly at its last action, with success."""
    problem = builtin_problem(name)
    model = problem.model
    for index, (goal, length) in enumerate(zip(problem.goal_masks, OPTIMAL[name])):
        assert len(astar(model, goal)) == length == len(astar(model, goal, heuristic="blind"))
        graph = optimal_plan_graph(model, goal)
        plans = list(graph.plans())
        assert len(plans) == graph.n_plans == len({tuple(p) for p in plans})
        env = SymbolicEnv((index,), problem=name)
        for plan in plans:
            assert len(plan) == length
            env.reset(seed=0)
            for t, action in enumerate(plan):
                obs, reward, terminated, truncated, info = env.step(action)
                assert terminated == info["is_success"] == (t == length - 1) and not truncated
            assert reward == 1.0 and model.state(obs) == model.plan_states(plan)[-1]


def test_goal_counts_are_read_without_grounding():
    from grail_bench.domains.symbolic import goal_count

    for name, lengths in OPTIMAL.items():
        assert goal_count(name) == len(builtin_problem(name).hypotheses) == len(lengths)


def test_plan_graph_counts_the_grid_routes():
    """Round the blocked cell (2, 1): two routes to (4, 0) (up at once, or after one step east)."""
    problem = builtin_problem("grid")
    assert optimal_plan_graph(problem.model, problem.goal_masks[0]).n_plans == 2


def test_inapplicable_action_leaves_the_state_and_tables_match_the_env():
    env = SymbolicEnv((1,), problem="logistics", max_steps=3)
    model = env.model
    table = env.tabular_dynamics()
    obs, _ = env.reset(seed=0)
    blocked = next(a for a in range(model.n_operators) if not model.applicable(model.init, a))
    nxt, reward, terminated, truncated, _ = env.step(blocked)
    assert np.array_equal(nxt, obs) and reward == 0.0 and not terminated and not truncated
    rng = np.random.default_rng(0)
    for _ in range(200):  # random states, random actions: the tables are the env's dynamics
        s, a = int(rng.integers(len(table.next_state))), int(rng.integers(model.n_operators))
        env.state = s
        obs, _, terminated, _, _ = env.step(a)
        assert int(state_index(obs[None], env.observation_space)[0]) == table.next_state[s, a] == model.step(s, a)
    env.reset()
    for _ in range(3):
        *_, truncated, _ = env.step(blocked)
    assert truncated


#: Every symbolic task (blocks' towers have one optimal plan each: it has no biased task).
TASKS = [(problem, regime) for problem in ("Blocks", "Grid", "Logistics") for regime in ("Optimal", "Biased", "Suboptimal")
         if (problem, regime) != ("Blocks", "Biased")]


def test_the_cards_are_every_symbolic_task():
    boltzmann = [f"GRAIL/Symbolic-{p}-Boltzmann-v0" for p in ("Blocks", "Grid", "Logistics")]  # tests/test_boltzmann.py
    assert sorted(t for t in gym.registry if t.startswith("GRAIL/Symbolic-")) == sorted(
        [f"GRAIL/Symbolic-{p}-{r}-v0" for p, r in TASKS] + boltzmann)


@pytest.mark.parametrize("problem, regime", TASKS)
def test_demonstrations_are_seeded_and_reach_their_goals(problem, regime):
    task = grail_bench.make_task(f"GRAIL/Symbolic-{problem}-{regime}-v0")
    demos, again, other = task.generate_demos(seed=3), task.generate_demos(seed=3), task.generate_demos(seed=4)
    lengths = OPTIMAL[problem.lower()]
    differs = False
    for goal, trajs in demos.items():
        optimum = lengths[int(goal[0])]
        for traj, same, diff in zip(trajs, again[goal], other[goal]):
            assert np.array_equal(traj.acts, same.acts) and np.array_equal(traj.obs, same.obs)
            differs |= not np.array_equal(traj.acts, diff.acts)
            assert traj.infos[-1]["is_success"] and not any(i["is_success"] for i in traj.infos[:-1])
            if regime == "Suboptimal":
                assert len(traj.acts) >= optimum and (len(traj.acts) - optimum) % 2 == 0
            else:
                assert len(traj.acts) == optimum
        if regime == "Biased":  # one preferred plan
            assert len({tuple(t.acts) for t in trajs}) == 1
    if regime == "Suboptimal" or problem != "Blocks":  # blocks' towers have one optimal plan each
        assert differs == (regime != "Biased")
    else:
        assert not differs


def test_suboptimal_demonstrations_take_detours():
    task = grail_bench.make_task("GRAIL/Symbolic-Grid-Suboptimal-v0", detour_prob=1.0)
    for goal, trajs in task.generate_demos(seed=0).items():
        for traj in trajs:  # a detour before every action
            assert len(traj.acts) == 3 * OPTIMAL["grid"][int(goal[0])]


def test_gym_make_carries_the_task():
    env = gym.make("GRAIL/Symbolic-Logistics-Optimal-v0")
    assert env.unwrapped.task.goals == ((0,), (1,), (2,), (3,))
    assert env.unwrapped.problem.name == "logistics"


def _selections():
    return [Selection(horizon=False, random_subset=subset, level=level) for subset in (True, False)
            for level in (0.1, 0.3, 0.7)]


@pytest.mark.parametrize("regime", ["Optimal", "Biased"])
def test_likelihood_sums_to_one_and_matches_enumeration(regime):
    task = grail_bench.make_task(f"GRAIL/Symbolic-Logistics-{regime}-v0")
    model = GoalDemonstrator(task, (1,))  # 45 optimal plans of 12 actions
    assert len(model.plans) == (45 if regime == "Optimal" else 1)
    for selection in _selections():
        joint: dict[tuple, float] = {}
        for plan, p_plan in model.support():
            for obs, p_obs in model.observations(plan, selection):
                joint[obs] = joint.get(obs, 0.0) + p_plan * p_obs
        assert math.isclose(math.fsum(joint.values()), 1.0)
        for obs, p in itertools.islice(joint.items(), 200):
            assert math.isclose(model.likelihood(obs, selection), p, rel_tol=1e-9)
    rng = np.random.default_rng(0)
    other = GoalDemonstrator(task, (0,))
    observation = model.sample_observation(rng, _selections()[0])
    assert model.likelihood(observation, _selections()[0]) > 0.0
    assert other.likelihood(observation, _selections()[0]) == 0.0 or regime == "Optimal"


def test_suboptimal_has_no_stated_likelihood():
    task = grail_bench.make_task("GRAIL/Symbolic-Grid-Suboptimal-v0")
    with pytest.raises(UserError, match="likelihood is stated"):
        GoalDemonstrator(task, (0,))
    with pytest.raises(UserError, match="action distribution"):
        task.spec.check_demonstrator_policy(task, "everywhere")


@pytest.mark.parametrize("regime", ["Optimal", "Biased"])
def test_demonstrator_policy_is_the_demonstrators_action_distribution(regime):
    task = grail_bench.make_task(f"GRAIL/Symbolic-Logistics-{regime}-v0")
    env = task.make_env((1,)).unwrapped
    graph = optimal_plan_graph(env.model, env.goal_mask)
    for support in ("everywhere", "demonstrated"):
        probs = task.spec.demonstrator_policy(task, (1,), support)
        assert probs.shape == (2 ** env.model.n_fluents, env.model.n_operators)
        assert np.allclose(probs.sum(axis=1), 1.0)
        for state in graph.edges:  # the states the demonstrator visits
            expected = graph.step_probs(state)
            if regime == "Biased":
                first = min(expected)
                expected = {first: 1.0}
            row = {a: p for a, p in enumerate(probs[state]) if p > 0}
            if regime == "Optimal" or state in env.model.plan_states(graph.first()):
                assert row.keys() == expected.keys()
                assert all(math.isclose(row[a], expected[a]) for a in row)


def test_archive_round_trip(tmp_path):
    """The generator's archives load, write back byte for byte, and load equal."""
    paths = write_dataset(tmp_path / "gen", names=("logistics",), levels=(30,), seed=0)
    assert [p.name for p in paths] == [f"logistics_hyp-{g}_30.tar.bz2" for g in range(4)]
    for path in paths:
        problem = load_problem(path)
        assert problem.real_index == int(path.name.split("hyp-")[1][0])
        observed = problem.observed_operators()
        assert len(observed) == math.ceil(0.3 * OPTIMAL["logistics"][problem.real_index])
        copy = write_problem(problem, tmp_path / "copy" / path.name)
        assert copy.read_bytes() == path.read_bytes()
        assert load_problem(copy) == problem
        folder = write_problem(problem, tmp_path / "folder" / "p")
        assert load_problem(folder) == replace(problem, name="p")


def test_dataset_style_archive_loads(tmp_path):
    """The dataset's spelling: upper-case atoms, commas with or without spaces, a problem with the hypothesis slot."""
    texts = file_texts(_swap())
    texts["hyps.dat"] = "(ON B A)\n(ONTABLE A), (HANDEMPTY)\n"
    texts["real_hyp.dat"] = "(ONTABLE A),(HANDEMPTY)\n"
    texts["obs.dat"] = "(UNSTACK A B)\n"
    problem = load_problem(_archive(tmp_path, texts))
    assert problem.hypotheses[1] == (("ontable", "a"), ("handempty",)) and problem.real_index == 1
    assert problem.observed_operators() == [problem.model.operator_index("(unstack a b)")]


def test_env_runs_a_dataset_archive(tmp_path):
    path = write_problem(_swap(), tmp_path / "swap.tar.bz2")
    env = SymbolicEnv((0,), problem=str(path))
    env.reset(seed=0)
    for action in astar(env.model, env.goal_mask):
        *_, terminated, _, _ = env.step(action)
    assert terminated


def _one_line(err: pytest.ExceptionInfo) -> str:
    text = str(err.value)
    assert "\n" not in text
    return text


def test_bad_input_gets_one_line_errors(tmp_path):
    with pytest.raises(UserError) as err:
        GRProblem("bad", "(define (domain blocks) (:action", SWAP_TEMPLATE, ((("ontable", "a"),),), (), ()).model
    assert "domain.pddl does not parse" in _one_line(err)
    with pytest.raises(UserError) as err:
        _swap(((("on", "b", "zed"),),)).model
    assert "unknown object 'zed'" in _one_line(err)
    texts = file_texts(_swap())
    del texts["obs.dat"]
    with pytest.raises(UserError) as err:
        load_problem(_archive(tmp_path, texts))
    assert "lacks obs.dat" in _one_line(err)
    texts = file_texts(_swap())
    texts["hyps.dat"] = "on b a\n"
    with pytest.raises(UserError) as err:
        load_problem(_archive(tmp_path, texts, "atoms.tar.bz2"))
    assert "hyps.dat line 1" in _one_line(err)
    problem = builtin_problem("logistics")
    with pytest.raises(UserError) as err:
        astar(problem.model, problem.goal_masks[1], node_limit=5)
    assert "node limit of 5" in _one_line(err)
    with pytest.raises(UserError) as err:
        grail_bench.make_task("GRAIL/Symbolic-Grid-Optimal-v0", problem="nowhere.tar.bz2")
    assert "nowhere.tar.bz2" in _one_line(err)


def test_bc_graql_and_the_demonstrator_run_on_a_symbolic_task():
    """End to end on the grid with tiny budgets: every recognizer scores every level, and perfect imitation
    of the optimal demonstrator recognises every full plan."""
    records = grail_bench.evaluate("GRAIL/Symbolic-Grid-Optimal-v0",
                                   [("bc", {"n_epochs": 2}), ("graql", {"episodes": 300}), "demonstrator"], seeds=1)
    assert {r.recognizer for r in records} == {"bc", "graql", "demonstrator"}
    assert {r.observability for r in records} == {0.1, 0.3, 0.5, 0.7, 1.0}
    assert all(0.0 <= r.f1.mean <= 1.0 for r in records)
    full = next(r for r in records if r.recognizer == "demonstrator" and r.observability == 1.0)
    assert full.f1.mean == 1.0


def test_batched_and_single_hmax_agree_and_are_admissible():
    from grail_bench.domains.symbolic.planner import hmax, hmax_many

    problem = builtin_problem("logistics")
    model = problem.model
    for goal in problem.goal_masks:
        graph = optimal_plan_graph(model, goal)
        states = sorted({s for s in graph.edges} | {model.init})
        batch = hmax_many(model, states, goal)
        assert [hmax(model, s, goal) for s in states] == batch.tolist()
        for s, h in zip(states, batch):  # on an optimal plan, the remaining length is the true cost
            remaining = next(len(p) for p in optimal_plan_graph(model, goal, s).plans())
            assert h <= remaining
