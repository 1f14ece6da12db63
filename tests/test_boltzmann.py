"""The Boltzmann demonstrator: its action values, its samples against its stated probabilities, and its exact
likelihood against enumeration."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest
from scipy.stats import chisquare

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.core.spaces import state_index
from grail_bench.core.trajectory import until_success
from grail_bench.domains.boltzmann import BoltzmannDemonstrator, action_values, fit_beta
from grail_bench.domains.minigrid.demos import shortest_path_graph
from grail_bench.task.domain import get_domain
from grail_bench.task.model import GRTask
from grail_bench.task.observation import Selection


def tiny(beta: float = 0.7, max_steps: int = 5) -> GRTask:
    """A 2x2 room, start (1, 1) facing east, goals (2, 2) and (2, 1): short enough to enumerate every path."""
    env = {**get_domain("minigrid").env_defaults, "size": 4, "start": [1, 1], "obstacles": [], "max_steps": max_steps}
    return GRTask(id="GRAIL/Tiny-v0", domain="minigrid", regime="boltzmann", goals=((2, 2), (2, 1)),
                  params={"beta": beta}, env_params=env)


def observation_space(task: GRTask):
    env = task.make_env(task.goals[0])
    env.close()
    return env.observation_space


def paper_room(beta: float, goals=((7, 1), (7, 7))) -> GRTask:
    return GRTask(id="GRAIL/MiniGrid-Boltzmann-v0", domain="minigrid", regime="boltzmann", goals=goals,
                  params={"beta": beta})


def test_action_values_are_the_shortest_path_costs():
    task = paper_room(1.0)
    env = task.make_env(task.goals[0])
    base = env.unwrapped
    dyn = base.tabular_dynamics()
    env.close()
    q = action_values(dyn)
    dist, _ = shortest_path_graph(base.model, (7, 1))
    for state, d in dist.items():
        if d == 0:
            continue
        i = int(state_index(np.array([state]), base.observation_space)[0])
        assert -q[i].max() == d  # the best action's cost is the distance
        for a in range(4):
            succ = base.model.step(state, a)
            assert q[i, a] == -(1 + dist[succ])  # every other action's: one step, then the rest


def test_lava_is_never_entered():
    env = {**get_domain("minigrid").env_defaults, "obstacles": [[2, 4, "lava"]]}
    task = GRTask(id="GRAIL/Lava-v0", domain="minigrid", regime="boltzmann", goals=((7, 1), (7, 7)), params={"beta": 0.0},
                  env_params=env)
    d = BoltzmannDemonstrator(task, task.goals[0])
    start = d.chain.dyn.start
    assert d.chain.policy[start, 2] == 0.0  # forward from (1, 4) facing east steps into the lava
    assert d.chain.policy[start, [0, 1, 3]] == pytest.approx([1 / 3] * 3)  # beta 0: uniform over the rest


def test_empirical_action_frequencies_match_the_stated_probabilities():
    task = paper_room(1.0)
    goal = task.goals[0]
    demos = task.spec.generate_demos(task, goal, 300, np.random.default_rng(0))
    policy = task.spec.demonstrator_policy(task, goal)
    space = observation_space(task)
    counts: dict[int, np.ndarray] = defaultdict(lambda: np.zeros(4))
    for traj in demos:
        cut = until_success(traj)
        for s, a in zip(state_index(cut.obs[: len(cut.acts)], space), cut.acts):
            counts[int(s)][int(a)] += 1
    busiest = sorted(counts, key=lambda s: -counts[s].sum())[:5]
    for s in busiest:
        observed, p = counts[s], policy[s]
        support = p > 0
        assert observed[~support].sum() == 0  # never an action it gives no probability
        result = chisquare(observed[support], observed.sum() * p[support])
        assert result.pvalue > 1e-3, (s, observed, p)


def _enumerate(d: BoltzmannDemonstrator) -> list[tuple[list[int], float]]:
    """Every demonstration (action sequence up to the goal or the horizon) with its probability."""
    chain, out = d.chain, []

    def walk(s: int, prefix: list[int], p: float) -> None:
        if len(prefix) == chain.horizon:
            out.append((prefix, p))
            return
        for a in np.flatnonzero(chain.policy[s] > 0):
            q = p * chain.policy[s, a]
            if chain.dyn.success[s, a]:
                out.append(([*prefix, int(a)], q))
            else:
                walk(int(chain.dyn.next_state[s, a]), [*prefix, int(a)], q)

    walk(chain.dyn.start, [], 1.0)
    return out


@pytest.mark.parametrize("selection", [
    Selection(horizon=False, random_subset=True, level=0.4),
    Selection(horizon=True, random_subset=True, level=0.4),
    Selection(horizon=False, random_subset=False, level=0.5),
    Selection(horizon=True, random_subset=False, level=0.6),
    Selection(horizon=False, random_subset=True, level=1.0, rounding="floor"),
], ids=["subset", "horizon-subset", "prefix", "horizon-prefix", "whole-floor"])
def test_likelihood_equals_the_enumerated_probability_of_every_observation(selection):
    d = BoltzmannDemonstrator(tiny(), (2, 2))
    support = _enumerate(d)
    assert sum(p for _, p in support) == pytest.approx(1.0)
    joint: dict[tuple, float] = defaultdict(float)
    for actions, p in support:
        for obs, w in d.observations(actions, selection):
            joint[obs] += p * w
    assert sum(joint.values()) == pytest.approx(1.0)
    for obs, p in joint.items():
        assert d.likelihood(obs, selection) == pytest.approx(p, rel=1e-9, abs=1e-15)
    assert d.likelihood(((0, 0),), selection) == 0.0  # a wall state: never visited


def test_the_ceiling_lies_between_chance_and_certainty_and_rises_with_beta():
    from grail_bench.harness.ceiling import bayes_ceiling

    low, high = (bayes_ceiling(tiny(beta, max_steps=8), "subset", 0.3, samples=400) for beta in (0.0, 5.0))
    assert low.method == "monte-carlo" and 0.5 <= low.accuracy < high.accuracy <= 1.0


def test_fit_beta_recovers_the_demonstrators():
    task = paper_room(0.8)
    qs, states, actions = [], [], []
    for goal in task.goals:
        d = BoltzmannDemonstrator(task, goal)
        rng = np.random.default_rng(1)
        acts = [d.chain.sample(rng) for _ in range(100)]
        qs += [d.chain.q] * len(acts)
        states += [np.array(d.chain.path(a)[0]) for a in acts]
        actions += [np.array(a) for a in acts]
    assert fit_beta(qs, states, actions) == pytest.approx(0.8, rel=0.1)


def test_symbolic_boltzmann_demos_follow_their_likelihood():
    task = GRTask(id="GRAIL/Symbolic-Blocks-Boltzmann-v0", domain="symbolic", regime="boltzmann",
                  goals=((0,), (1,)), params={"beta": 2.0}, env_params={"problem": "blocks"})
    d = BoltzmannDemonstrator(task, (0,))
    demos = task.spec.generate_demos(task, (0,), 5, np.random.default_rng(0))
    whole = Selection(horizon=False, random_subset=False, level=1.0)
    for traj in demos:
        cut = until_success(traj)
        pairs = tuple(zip(state_index(cut.obs[: len(cut.acts)], observation_space(task)).tolist(),
                          cut.acts.tolist()))
        assert pairs == tuple(d.span(cut.acts.tolist(), whole))  # the env and the chain agree step by step
        expected = np.prod([d.chain.policy[s, a] for s, a in pairs])
        assert d.likelihood(pairs, whole) == pytest.approx(expected)  # the whole path: its own probability


@pytest.mark.parametrize("beta", [-0.5, 51, "1", True])
def test_a_bad_beta_is_refused_in_one_line(beta):
    with pytest.raises(UserError, match="beta") as err:
        paper_room(beta)
    assert "\n" not in str(err.value)


def test_the_boltzmann_tasks_are_listed():
    ids = grail_bench.task_ids()
    assert {"GRAIL/MiniGrid-Boltzmann-v0", "GRAIL/MiniGrid-Boltzmann-4Goals-v0", "GRAIL/MiniGrid-Boltzmann-6Goals-v0",
            "GRAIL/Symbolic-Blocks-Boltzmann-v0", "GRAIL/Symbolic-Grid-Boltzmann-v0",
            "GRAIL/Symbolic-Logistics-Boltzmann-v0"} <= set(ids)
    task = grail_bench.make_task("GRAIL/MiniGrid-Boltzmann-v0")
    assert task.regime == "boltzmann" and task.params["beta"] == get_domain("minigrid").regimes["boltzmann"]["beta"]
