"""The Bayes ceiling: hand-computed cases, exact against Monte Carlo, the likelihood against brute force."""

from __future__ import annotations

import itertools
import json
from collections import defaultdict

import numpy as np
import pytest

import grail_bench
from grail_bench.domains import get_domain
from grail_bench.domains.minigrid.grid import TURN_PATTERNS
from grail_bench.domains.minigrid.likelihood import GoalDemonstrator
from grail_bench.harness.ceiling import bayes_ceiling, ceilings_for, normalised
from grail_bench.task.model import GRTask
from grail_bench.task.observation import Selection


def tiny(regime: str = "optimal", **params) -> GRTask:
    """A 3x3 room, start (1, 2) facing east, goals (3, 1) and (3, 3): the only shortest paths are
    F F L F and F F R F, so the first two pairs are shared and the last two tell the goals apart."""
    defaults = get_domain("minigrid").regimes[regime]
    env = {**get_domain("minigrid").env_defaults, "size": 5, "start": [1, 2], "obstacles": [], "max_steps": 8}
    return GRTask(id="GRAIL/Tiny-v0", domain="minigrid", regime=regime, goals=((3, 1), (3, 3)),
                  params={**defaults, **params}, env_params=env)


@pytest.mark.parametrize("protocol, level, expected", [
    ("prefix", 0.5, 0.5),          # k = 2: F F for both goals
    ("prefix", 0.75, 1.0),         # k = 3: the turn tells them apart
    ("subset", 0.25, 0.75),        # k = 1 of 4 pairs: 2 shared (1/2 right), 2 telling
    ("horizon-subset", 0.125, 0.875),  # k = 1 of 8 pairs: 2 shared, 2 telling, 4 on the goal (telling)
    ("horizon-prefix", 0.25, 0.5),  # k = 2 of 8: still F F
])
def test_hand_computed_ceilings(protocol, level, expected):
    c = bayes_ceiling(tiny(), protocol, level)
    assert c.method == "exact" and c.stderr == 0.0 and c.chance == 0.5
    assert c.accuracy == pytest.approx(expected)


@pytest.mark.parametrize("task_id, protocol", [("GRAIL/MiniGrid-Optimal-4Goals-v0", "prefix"),
                                               ("GRAIL/MiniGrid-Optimal-v0", "subset"),
                                               ("GRAIL/MiniGrid-Biased-v0", "subset")])
def test_monte_carlo_agrees_with_the_exact_value(task_id, protocol):
    task = grail_bench.make_task(task_id)
    exact = bayes_ceiling(task, protocol, 0.2, method="exact")
    mc = bayes_ceiling(task, protocol, 0.2, method="monte-carlo", samples=200, seed=1)
    assert mc.method == "monte-carlo" and mc.samples == 200
    assert abs(mc.accuracy - exact.accuracy) <= 4 * mc.stderr + 1e-9


@pytest.mark.parametrize("route_choice, prefix_ceiling, subset_ceiling", [
    # Known values (docs/results/boards.md): the prefix caps any recognizer far below the paper's 0.87-0.92.
    ("uniform", [0.44, 0.53, 0.61], [0.80, 0.92, 0.97]),
    # One route per goal, straight ahead (east) first: the first 30 % of every path is the same eastward run.
    ("fixed", [1 / 3, 1 / 3, 1 / 3], [0.72, 0.88, 0.96]),
])
def test_the_paper_protocols_ceilings_on_six_goals(route_choice, prefix_ceiling, subset_ceiling):
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0", route_choice=route_choice)
    prefix = [bayes_ceiling(task, "prefix", p, rounding="ceil").accuracy for p in (0.1, 0.2, 0.3)]
    subset = [bayes_ceiling(task, "subset", p, rounding="ceil").accuracy for p in (0.1, 0.2, 0.3)]
    assert np.round(prefix, 2).tolist() == np.round(prefix_ceiling, 2).tolist()
    assert np.round(subset, 2).tolist() == subset_ceiling


def test_pairs_only_leaves_out_how_many_pairs_there_are():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0", route_choice="fixed")
    # Prefix at 10 %: the first 2 pairs of the 11-action paths ((7,1), (7,7)) or the first 1 of the 9-action
    # ones ((7,3), (7,5)), all "forward" from the start: the count tells long from short, the pairs nothing.
    assert bayes_ceiling(task, "prefix", 0.1).accuracy == pytest.approx(0.5)
    c = bayes_ceiling(task, "prefix", 0.1, pairs_only=True)
    assert c.pairs_only and c.method == "exact" and c.accuracy == pytest.approx(0.25)


@pytest.mark.parametrize("route_choice, expected", [
    # One east-first route per goal: (7,1) and (7,3), like (7,7) and (7,5), act alike for 7 actions.
    ("fixed", [0.62, 0.76, 0.85]),
    ("uniform", [0.79, 0.90, 0.95]),
])
def test_pairs_only_ceilings_on_four_goals_are_below_the_bayes_ceiling(route_choice, expected):
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0", route_choice=route_choice)
    pairs = [bayes_ceiling(task, "subset", p, pairs_only=True) for p in (0.1, 0.2, 0.3)]
    assert [round(c.accuracy, 2) for c in pairs] == expected
    assert all(c.accuracy < bayes_ceiling(task, "subset", c.observability).accuracy for c in pairs)


def test_the_ceiling_follows_the_tasks_rounding_and_fewer_pairs_tell_less():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
    assert task.rounding == "ceil"
    for p in (0.1, 0.2, 0.3):
        default, ceil = bayes_ceiling(task, "subset", p), bayes_ceiling(task, "subset", p, rounding="ceil")
        assert default == ceil and default.protocol == "subset"
        assert bayes_ceiling(task, "subset", p, rounding="floor").accuracy <= ceil.accuracy
    assert bayes_ceiling(task, "subset", 0.1, rounding="floor").accuracy < bayes_ceiling(task, "subset", 0.1).accuracy


def _brute_force_likelihoods(d: GoalDemonstrator, selection: Selection) -> dict:
    """Enumerate every path and every insertion choice of the tiny task."""
    out: dict = defaultdict(float)
    options = [()] + list(d.patterns)
    for path in d.paths:
        for choice in itertools.product(range(len(options)), repeat=len(path)):
            p = 1.0 / len(d.paths)
            actions = []
            for a, c in zip(path, choice):
                p *= (1 - d.turn_prob) if c == 0 else d.turn_prob / len(d.patterns)
                actions += [*options[c], a]
            for obs, w in d.observations(actions, selection):
                out[obs] += p * w
    return out


@pytest.mark.parametrize("turn_prob", [0.4, 1.0])  # 1.0: turns before every action, the default
@pytest.mark.parametrize("pattern", sorted(TURN_PATTERNS))
@pytest.mark.parametrize("protocol, level", [("subset", 0.15), ("prefix", 0.5), ("horizon-subset", 0.1),
                                             ("horizon-prefix", 0.6)])
def test_likelihood_with_turn_insertions_matches_brute_force(pattern, protocol, level, turn_prob):
    task = tiny("suboptimal", turn_prob=turn_prob, turn_pattern=pattern)
    task = GRTask(**{**task.__dict__, "env_params": {**task.env_params, "max_steps": 20}})
    chosen = grail_bench.task.observation.BUILTIN[protocol]
    selection = Selection(horizon=chosen.span == "horizon", random_subset=chosen.random_subset, level=level)
    d = GoalDemonstrator(task, (3, 1))
    brute = _brute_force_likelihoods(d, selection)
    assert sum(brute.values()) == pytest.approx(1.0)
    observations = list(brute)
    picked = np.random.default_rng(0).choice(len(observations), size=min(150, len(observations)), replace=False)
    for i in picked:
        assert d.likelihood(observations[i], selection) == pytest.approx(brute[observations[i]], rel=1e-9, abs=1e-12)
    unseen = ((9, 9, 0, 0),) * len(observations[0])  # an observation no demonstration yields
    assert d.likelihood(unseen, selection) == 0.0


def test_suboptimal_ceiling_is_monte_carlo_with_a_standard_error():
    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", route_choice="uniform", turn_prob=0.3)
    c = bayes_ceiling(task, "prefix", 0.3, samples=60, seed=0)
    assert c.method == "monte-carlo" and c.samples == 60 and 0 < c.stderr < 0.1
    assert 0.5 <= c.accuracy <= 1.0
    assert bayes_ceiling(task, "prefix", 0.3, samples=60, seed=0) == c  # seeded
    pairs = bayes_ceiling(task, "prefix", 0.3, samples=60, seed=0, pairs_only=True)
    assert pairs.method == "monte-carlo" and pairs.pairs_only and 0.5 <= pairs.accuracy <= 1.0
    assert bayes_ceiling(task, "prefix", 0.3, samples=60, seed=0, pairs_only=True) == pairs
    with pytest.raises(ValueError, match="cannot enumerate"):
        bayes_ceiling(task, "prefix", 0.3, method="exact")


def test_ceilings_are_cached_and_other_domains_have_none(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    cell = ("GRAIL/MiniGrid-Optimal-v0", {}, "subset+floor", 0.2)
    first = ceilings_for([cell])
    (only,) = first.values()
    files = list((tmp_path / "ceilings").glob("*.json"))
    assert len(files) == 1 and only.protocol == "subset+floor"
    assert ceilings_for([cell], executor=_Refuses()) == first  # read back, nothing computed
    files[0].write_text("{not json")  # a corrupt entry is computed again
    assert ceilings_for([cell]) == first
    assert json.loads(files[0].read_text())["ceiling"]["accuracy"] == only.accuracy
    assert ceilings_for([("GRAIL/PandaReach-Optimal-v0", {}, "subset", 0.02)]) == {}
    assert ceilings_for([(cell[0], {}, "random", 0.2)]) == {}  # legacy rows have no ceiling


class _Refuses:
    """An executor that must not be given work: every cell is already cached."""

    def map_unordered(self, fn, items):
        assert not items, f"{len(items)} ceilings computed again"
        return iter(())


def test_ceilings_on_a_process_pool_equal_the_serial_ones_and_are_cached(tmp_path, monkeypatch):
    from grail_bench.harness.executors import LocalExecutor

    cells = [("GRAIL/MiniGrid-Optimal-v0", {}, "subset+floor", 0.1), ("GRAIL/MiniGrid-Optimal-v0", {}, "prefix", 0.5),
             ("GRAIL/MiniGrid-Suboptimal-v1", {"turn_prob": 0.3}, "prefix", 0.3),
             ("GRAIL/PandaReach-Optimal-v0", {}, "subset", 0.1)]  # no ceiling: left out
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "serial"))
    serial = ceilings_for(cells, samples=60)
    assert len(serial) == 3
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "pool"))
    pool = LocalExecutor(2)
    try:
        ticks = []
        repeated = cells + cells[:2]  # an offline level that is also an online fraction: computed once
        assert ceilings_for(repeated, samples=60, on_cell=lambda: ticks.append(1), executor=pool) == serial
    finally:
        pool.close()
    assert len(ticks) == len(cells)
    assert len(list((tmp_path / "pool" / "ceilings").glob("*.json"))) == 3
    assert ceilings_for(cells, samples=60, executor=_Refuses()) == serial


def test_normalised_f1():
    assert normalised(0.5, 1.0, 0.5) == 0.0
    assert normalised(1.0, 1.0, 0.5) == 1.0
    assert normalised(0.75, 0.75, 0.25) == 1.0
    assert normalised(0.5, 0.5, 0.5) is None
