"""Test-time shifts: shifted dynamics and another regime for the test demonstrations only."""

from __future__ import annotations

import functools
import itertools
import math
from collections import defaultdict

import numpy as np
import pytest

import grail_bench.task  # noqa: F401 - installs the demonstration source
from grail_bench.core.errors import UserError
from grail_bench.domains.minigrid import demos as minigrid_demos
from grail_bench.domains.minigrid.env import GRMiniGridEnv
from grail_bench.domains.minigrid.grid import ACTION_NAMES, GridModel
from grail_bench.harness.ceiling import bayes_ceiling, has_ceiling
from grail_bench.harness.planning import config_hash, fitted_config, task_params
from grail_bench.task.model import GRTask
from grail_bench.task.observation import BUILTIN
from grail_bench.task.registration import make_task
from grail_bench.task.versions import fingerprint


def _same(a, b) -> bool:
    return len(a) == len(b) and all(np.array_equal(x.obs, y.obs) and np.array_equal(x.acts, y.acts)
                                    for x, y in zip(a, b))


def _tiny(**params) -> GRTask:
    """A 3x3 room, two goals, a 5-step horizon: small enough to enumerate every slipping episode."""
    task = GRTask(id="GRAIL/Tiny-v0", domain="minigrid", regime="optimal", goals=((3, 1), (3, 3)),
                  params={"route_choice": "fixed"},
                  env_params={"size": 5, "start": [1, 2], "obstacles": [], "max_steps": 5}, n_demos=4, n_train=2)
    return task.with_overrides(**params)


# -- the shifted dynamics --------------------------------------------------------------------------------------

def test_slip_replaces_the_action_by_one_of_the_three_others_uniformly():
    slip, n = 0.3, 6000
    env = GRMiniGridEnv((7, 1), slip=slip)
    model = env.model
    state = (3, 4, 0)  # every action leads elsewhere: turn left, turn right, forward, stay
    expected = model.transition(state, 2, slip)
    assert len(expected) == 4 and expected[model.step(state, 2)] == pytest.approx(1 - slip)
    counts: dict = defaultdict(int)
    env.reset(seed=0)
    for _ in range(n):
        env.agent_pos, env.agent_dir = state[:2], state[2]
        env.step(2)
        counts[env.state] += 1
    for successor, p in expected.items():
        assert abs(counts[successor] / n - p) < 4.5 * math.sqrt(p * (1 - p) / n), successor


def test_without_slip_the_transition_is_the_model_step():
    model = GridModel.of(9, [[7, 4]])
    for state in model.states()[:40]:
        for action in range(len(ACTION_NAMES)):
            assert model.transition(state, action) == {model.step(state, action): 1.0}


def test_recognizer_envs_refuse_the_tables_of_a_slipping_room():
    with pytest.raises(UserError, match="slips"):
        GRMiniGridEnv((7, 1), slip=0.1).tabular_dynamics()


@pytest.mark.parametrize("task_id, actions", [
    ("GRAIL/PointMaze-Biased-v0", ([0.8, -0.4], [1.0, 1.0], [-0.6, 0.2])),
    ("GRAIL/PandaReach-Optimal-v0", ([0.8, -0.4, 0.2], [1.0, 1.0, -1.0], [-0.6, 0.2, 0.0])),
])
def test_action_scale_executes_the_scaled_action(task_id, actions):
    task = make_task(task_id)
    scaled = task.spec.make_env(task.goals[0], **task.env_params, action_scale=0.5)
    plain = task.spec.make_env(task.goals[0], **task.env_params)
    scaled.reset(seed=0), plain.reset(seed=0)
    for action in actions:
        a = scaled.step(np.array(action, dtype=np.float32))[0]
        b = plain.step(0.5 * np.array(action, dtype=np.float32))[0]
        np.testing.assert_allclose(a, b, atol=1e-6)
    moved = plain.step(np.array(actions[0], dtype=np.float32))[0]
    assert not np.allclose(scaled.step(np.array(actions[0], dtype=np.float32))[0], moved)  # the scale matters
    scaled.close(), plain.close()


# -- training untouched, test split shifted ----------------------------------------------------------------------

@pytest.mark.parametrize("shift", [{"test_slip": 0.2}, {"test_obstacles": [[4, 4]]}, {"test_regime": "suboptimal"}])
def test_a_shift_changes_the_test_demonstrations_only(shift):
    task = make_task("GRAIL/MiniGrid-Optimal-v0")
    shifted = task.with_overrides(**shift)
    nominal, moved = task.generate_demos(3), shifted.generate_demos(3)
    for goal in task.goals:
        assert _same(nominal[goal][:task.n_train], moved[goal][:task.n_train])
        assert len(moved[goal]) == task.n_demos
    assert any(not _same(nominal[g][task.n_train:], moved[g][task.n_train:]) for g in task.goals)


def test_the_test_obstacles_are_walls_of_the_test_room():
    task = make_task("GRAIL/MiniGrid-Optimal-v0").with_overrides(test_obstacles=[[2, 4], [2, 3], [2, 5]])
    _, test = task.split(task.generate_demos(0))
    cells = {tuple(o[:2]) for trajs in test.values() for t in trajs for o in t.obs.tolist()}
    assert not cells & {(2, 4), (2, 3), (2, 5)}  # every test demonstration walks round the moved wall


def test_cross_regime_test_demonstrations_are_the_named_regimes():
    optimal, suboptimal = make_task("GRAIL/MiniGrid-Optimal-v0"), make_task("GRAIL/MiniGrid-Suboptimal-v1")
    cross = optimal.with_overrides(test_regime="suboptimal")
    assert cross.test_task().regime == "suboptimal" and cross.regime == "optimal"
    train, test = cross.split(cross.generate_demos(1))
    own_train, _ = optimal.split(optimal.generate_demos(1))
    _, their_test = suboptimal.split(suboptimal.generate_demos(1))
    for goal in cross.goals:
        assert _same(train[goal], own_train[goal])
        assert _same(test[goal], their_test[goal])


def test_cross_regime_on_the_symbolic_domain():
    optimal, suboptimal = make_task("GRAIL/Symbolic-Blocks-Optimal-v0"), make_task("GRAIL/Symbolic-Blocks-Suboptimal-v0")
    cross = optimal.with_overrides(test_regime="suboptimal")
    train, test = cross.split(cross.generate_demos(0))
    own_train, _ = optimal.split(optimal.generate_demos(0))
    _, their_test = suboptimal.split(suboptimal.generate_demos(0))
    for goal in cross.goals:
        assert _same(train[goal], own_train[goal])
        assert _same(test[goal], their_test[goal])
    assert has_ceiling(optimal.with_overrides(test_regime="biased"))
    assert not has_ceiling(cross)  # the symbolic suboptimal demonstrator has no stated likelihood


def test_the_cross_regime_needs_its_regimes_parameters():
    task = make_task("GRAIL/MiniGrid-Optimal-v0")
    with pytest.raises(UserError, match="test_regime_params"):
        task.with_overrides(test_regime="biased")
    biased = task.with_overrides(test_regime="biased", test_regime_params={"routes": ["NE", "ES"]})
    assert biased.test_task().params == {"routes": ["NE", "ES"]}
    overrides = biased.overrides_against(task)  # as a stored run records it, and reads it back
    assert overrides.label() == 'test_regime="biased" test_regime_params={"routes": ["NE", "ES"]}'
    assert task.with_overrides(**overrides.as_dict()) == biased
    from grail_bench.task.overrides import TaskOverrides

    assert TaskOverrides.from_json(overrides.to_json()) == overrides


def test_cached_training_demonstrations_are_shared_with_the_unshifted_task(monkeypatch):
    from grail_bench.task import demo_cache

    keys = []
    real = demo_cache.cached

    def spy(kind, key, *args, **kwargs):
        keys.append(key)
        return real(kind, key, *args, **kwargs)

    monkeypatch.setattr(demo_cache, "cached", spy)
    task = make_task("GRAIL/PointMaze-Biased-v0").with_overrides(n_demos=3, n_train=2)
    task.generate_demos(0)
    nominal_keys, keys[:] = list(keys), []
    demos = task.with_overrides(test_action_scale=0.5).generate_demos(0)
    assert [k for k in keys if "test" not in k] == nominal_keys
    tests = [k for k in keys if "test" in k]
    assert len(tests) == len(task.goals) and all(k["test"] == {"test_action_scale": 0.5} and k["from"] == 2
                                                 for k in tests)
    assert all(len(d) == 3 for d in demos.values())


# -- what the shift leaves alone -----------------------------------------------------------------------------------

def test_no_shift_is_the_task_itself():
    task = make_task("GRAIL/MiniGrid-Optimal-v0")
    same = task.with_overrides(test_slip=0.0, test_obstacles=None, test_regime="optimal")
    assert same == task and not same.shifted and fingerprint(same) == fingerprint(task)
    own_walls = task.with_overrides(test_obstacles=task.env_params["obstacles"])  # the room's own walls
    assert own_walls == task and fingerprint(own_walls) == fingerprint(task)
    assert task.with_overrides(test_obstacles=[[7, 4], [6, 1]]).shifted
    assert config_hash(fitted_config(same, "bc", {})) == config_hash(fitted_config(task, "bc", {}))
    shifted = task.with_overrides(test_slip=0.1)
    assert fingerprint(shifted) != fingerprint(task)
    config = fitted_config(shifted, "bc", {})
    assert config_hash(config) != config_hash(fitted_config(task, "bc", {}))
    import json

    assert task_params(json.dumps(config))["test_slip"] == 0.1
    assert shifted.overrides_against(task).label() == "test_slip=0.1"


@pytest.mark.parametrize("params, why", [
    ({"test_slip": 1.5}, "out of range"),
    ({"test_slip": "x"}, "probability"),
    ({"test_obstacles": [[7, 1]]}, "not a free cell"),
    ({"test_regime": "greedy"}, "unknown regime"),
    ({"test_regime_params": {"turn_prob": 0.5}}, "no parameter of the optimal regime"),
    ({"test_action_scale": 0.5}, "cannot apply parameter"),
])
def test_bad_shifts_are_refused_in_one_line(params, why):
    with pytest.raises(UserError, match=why) as info:
        make_task("GRAIL/MiniGrid-Optimal-v0").with_overrides(**params)
    assert "\n" not in str(info.value)


def test_gym_make_takes_the_test_parameters():
    import gymnasium as gym

    env = gym.make("GRAIL/MiniGrid-Optimal-v0", test_slip=0.1)
    assert env.unwrapped.task.test_params == {"test_slip": 0.1}
    assert env.unwrapped.slip == 0.0  # the env a recognizer (or a user) builds keeps the task's dynamics
    env.close()


def test_a_dataset_task_refuses_a_shift():
    import dataclasses

    task = dataclasses.replace(make_task("GRAIL/MiniGrid-Optimal-v0"), test_params={"test_slip": 0.1})
    with pytest.raises(UserError, match="generated ones only"):
        dataclasses.replace(task, demos="some/dataset-v0")


# -- Bayes ceilings under the shift ----------------------------------------------------------------------------------

class _Outcomes:
    """Stands for an env's ``np_random``: plays one given sequence of slip outcomes (None: no slip, else the
    index among the three other actions) and records how many it used."""

    def __init__(self, outcomes) -> None:
        self.outcomes, self.used = outcomes, 0

    def random(self) -> float:
        return 0.0 if self.outcomes[self.used] is not None else 1.0

    def integers(self, n: int) -> int:
        out = self.outcomes[self.used]
        self.used += 1
        return out


@functools.lru_cache(maxsize=8)
def _brute_force_episodes(task: GRTask, goal, slip: float) -> dict:
    """Every episode of the real env and closed-loop player, over every sequence of slip outcomes."""
    out: dict = defaultdict(float)
    seen = set()
    horizon = task.env_params["max_steps"]
    for outcomes in itertools.product([None, 0, 1, 2], repeat=horizon):
        env = minigrid_demos.test_env(task, goal)
        base = env.unwrapped
        fake = _Outcomes(list(outcomes))
        real_reset = base.reset

        def reset(*, seed=None, options=None, _real=real_reset, _fake=fake, _base=base):
            result = _real(seed=seed, options=options)
            _base._np_random = _fake
            return result

        base.reset = reset
        plan = minigrid_demos.plan_from(task, goal, base.model, (*base.start, base.start_dir), np.random.default_rng(0))
        traj = _play_counting(env, task, goal, plan, fake)
        used = tuple(outcomes[:fake.used])
        if used in seen:
            continue
        seen.add(used)
        prob = math.prod(1 - slip if o is None else slip / 3 for o in used)
        pairs = tuple((*map(int, o), int(a)) for o, a in zip(traj.obs[:-1], traj.acts))
        reached = next((t + 1 for t, info in enumerate(traj.infos) if info["is_success"]), horizon)
        out[(pairs, reached)] += prob
        env.close()
    return dict(out)


def _play_counting(env, task, goal, plan, fake):
    """The closed-loop player, counting each step's draw (the env draws ``random()`` once per live step and
    ``integers`` once more when it slips)."""
    base = env.unwrapped
    original = base.step

    def step(action):
        no_slip = not base._absorbed and fake.outcomes[fake.used] is None
        result = original(action)
        fake.used += no_slip  # a draw that did not slip (a slip's index advanced it already)
        return result

    base.step = step
    return minigrid_demos.play_closed_loop(env, task, goal, plan, np.random.default_rng(0))


def test_slipping_demonstrator_enumerates_what_the_env_plays():
    from grail_bench.domains.minigrid.slip import SlipDemonstrator

    task = _tiny(test_slip=0.2).test_task()
    for goal in task.goals:
        exact = SlipDemonstrator(task, goal).episodes
        brute = _brute_force_episodes(task, goal, 0.2)
        assert set(exact) == set(brute)
        for episode, p in brute.items():
            assert exact[episode] == pytest.approx(p, abs=1e-12)


@pytest.mark.parametrize("protocol", sorted(BUILTIN))
def test_ceiling_under_slip_is_the_brute_force_one(protocol):
    from grail_bench.domains.minigrid.slip import SlipDemonstrator

    task = _tiny(test_slip=0.2)
    assert has_ceiling(task)
    test = task.test_task()
    selection_level = 0.5
    ceiling = bayes_ceiling(task, protocol, selection_level, method="exact")
    from grail_bench.harness.ceiling import _selection

    selection = _selection(protocol, selection_level, "ceil")
    joint: dict = defaultdict(lambda: np.zeros(len(task.goals)))
    for g, goal in enumerate(task.goals):
        d = SlipDemonstrator(test, goal)
        for episode, p in _brute_force_episodes(test, goal, 0.2).items():
            for obs, q in selection.observations(d.span(episode, selection)):
                joint[obs][g] += p * q
    brute = sum(v.max() for v in joint.values()) / len(task.goals)
    assert ceiling.accuracy == pytest.approx(brute, abs=1e-9)
    nominal = bayes_ceiling(_tiny(), protocol, selection_level, method="exact")
    assert ceiling.accuracy != pytest.approx(nominal.accuracy)  # the slip moves the ceiling


def test_slipping_likelihood_is_its_enumerated_observation_probability():
    from grail_bench.domains.minigrid.slip import SlipDemonstrator
    from grail_bench.harness.ceiling import _selection

    test = _tiny(test_slip=0.3).test_task()
    d = SlipDemonstrator(test, test.goals[0])
    selection = _selection("subset", 0.5, "ceil")
    totals: dict = defaultdict(float)
    for episode, p in d.support():
        for obs, q in d.observations(episode, selection):
            totals[obs] += p * q
    for obs, p in list(totals.items())[:50]:
        assert d.likelihood(obs, selection) == pytest.approx(p, abs=1e-12)


def test_ceiling_with_moved_obstacles_uses_the_test_room():
    task = _tiny()
    moved = task.with_overrides(test_obstacles=[[2, 2]])  # a wall right ahead of the start
    assert has_ceiling(moved)
    a, b = (bayes_ceiling(t, "prefix", 0.3, method="exact").accuracy for t in (task, moved))
    assert a != b


def test_large_slipping_rooms_of_other_regimes_have_no_ceiling_but_say_why(monkeypatch):
    from grail_bench.domains.minigrid import slip

    monkeypatch.setattr(slip, "MAX_BRANCHES", 20_000)  # the same refusal, sooner
    task = make_task("GRAIL/MiniGrid-Suboptimal-v1").with_overrides(test_slip=0.1)  # not Markov: no DP either
    with pytest.raises(UserError, match="small rooms"):
        bayes_ceiling(task, "prefix", 0.1)


@pytest.mark.parametrize("regime, params", [("optimal", {"route_choice": "uniform"}),
                                            ("suboptimal", {"turn_prob": 0.5})])
def test_slipping_demonstrator_probabilities_match_the_generator(regime, params):
    from grail_bench.domains.minigrid.slip import SlipDemonstrator

    tiny = _tiny()
    task = GRTask(id="GRAIL/Tiny-v0", domain="minigrid", regime=regime, goals=tiny.goals, params=params,
                  env_params={**tiny.env_params, "max_steps": 4}, n_demos=4, n_train=2,
                  test_params={"test_slip": 0.25}).test_task()
    goal, n = task.goals[1], 3000
    exact = SlipDemonstrator(task, goal).episodes
    assert sum(exact.values()) == pytest.approx(1.0)
    demos = task.spec.generate_demos(task, goal, n, np.random.default_rng(7))
    counts: dict = defaultdict(int)
    for traj in demos:
        pairs = tuple((*map(int, o), int(a)) for o, a in zip(traj.obs[:-1], traj.acts))
        reached = next((t + 1 for t, info in enumerate(traj.infos) if info["is_success"]), len(traj.acts))
        counts[(pairs, reached)] += 1
    assert set(counts) <= set(exact)  # the generator plays nothing the enumeration misses
    likely = sorted(exact, key=exact.get, reverse=True)[:30]  # each on its own, the rare rest together
    groups = [([e], exact[e]) for e in likely] + [([e for e in exact if e not in likely],
                                                   1.0 - sum(exact[e] for e in likely))]
    for episodes, p in groups:
        freq = sum(counts[e] for e in episodes) / n
        assert abs(freq - p) <= 5 * math.sqrt(p * (1 - p) / n) + 1 / n


def test_cli_ceiling_names_the_shift_and_refuses_a_bad_one_in_one_line():
    from typer.testing import CliRunner

    from grail_bench.cli import app

    env = {"COLUMNS": "200"}
    ok = CliRunner().invoke(app, ["ceiling", "-t", "GRAIL/MiniGrid-Optimal-v0", "-p", "prefix", "-o", "0.3",
                                  "--param", "test_obstacles=[[4, 4]]"], env=env)
    assert ok.exit_code == 0, ok.output
    assert "test_obstacles=[[4, 4]]" in ok.output
    bad = CliRunner().invoke(app, ["ceiling", "-t", "GRAIL/MiniGrid-Optimal-v0", "--param", "test_slip=2"], env=env)
    assert bad.exit_code == 2 and bad.output.count("\n") == 1 and "test_slip: 2 is out of range" in bad.output


def test_a_card_sets_test_parameters_in_its_test_table():
    from grail_bench.task.cards import parse_card

    text = ('domain = "minigrid"\n[[task]]\nid = "GRAIL/Mine-v0"\nregime = "optimal"\ngoals = [[7, 1], [7, 7]]\n'
            'test = { test_slip = 0.1, test_regime = "suboptimal" }\n')
    (task,) = parse_card(text, "mine.toml")
    assert task.test_params == {"test_slip": 0.1, "test_regime": "suboptimal"}
    with pytest.raises(UserError, match=r"mine.toml: .*test.test_slip"):
        parse_card(text.replace("0.1", "7"), "mine.toml")


@pytest.mark.parametrize("params", [{"route_choice": "uniform"}, {"routes": ["NE", "ES"]}])
@pytest.mark.parametrize("protocol", sorted(BUILTIN))
def test_markov_slipping_likelihood_is_the_enumerated_one(params, protocol):
    from grail_bench.domains.minigrid.slip import MarkovSlipDemonstrator, SlipDemonstrator
    from grail_bench.harness.ceiling import _selection

    tiny = _tiny()
    regime = "biased" if "routes" in params else "optimal"
    task = GRTask(id="GRAIL/Tiny-v0", domain="minigrid", regime=regime, goals=tiny.goals, params=params,
                  env_params=tiny.env_params, n_demos=4, n_train=2, test_params={"test_slip": 0.2}).test_task()
    selection = _selection(protocol, 0.4, "ceil")
    for goal in task.goals:
        exact, markov = SlipDemonstrator(task, goal), MarkovSlipDemonstrator(task, goal)
        seen: dict = defaultdict(float)
        for episode, p in exact.support():
            for obs, q in exact.observations(episode, selection):
                seen[obs] += p * q
        for obs, p in seen.items():
            assert markov.likelihood(obs, selection) == pytest.approx(p, abs=1e-12)
        rng = np.random.default_rng(0)
        drawn = [markov.sample_observation(rng, selection) for _ in range(200)]
        assert all(obs in seen for obs in drawn)


def test_large_slipping_rooms_get_a_monte_carlo_ceiling(monkeypatch):
    from grail_bench.domains.minigrid import slip

    tiny = _tiny(route_choice="uniform", test_slip=0.2)
    exact = bayes_ceiling(tiny, "subset", 0.4, method="exact")
    monkeypatch.setattr(slip, "MAX_BRANCHES", 50)  # too large to enumerate: the dynamic programme's likelihood
    estimate = bayes_ceiling(tiny, "subset", 0.4, samples=4000)
    assert estimate.method == "monte-carlo" and exact.method == "exact"
    assert abs(estimate.accuracy - exact.accuracy) < 4 * estimate.stderr + 1e-9
    room = make_task("GRAIL/MiniGrid-Optimal-v0").with_overrides(test_slip=0.2)
    assert bayes_ceiling(room, "prefix", 0.3, samples=100).method == "monte-carlo"


@pytest.mark.parametrize("overrides", [{"test_slip": 0.1}, {"test_regime": "boltzmann", "test_slip": 0.1}])
def test_a_demonstrator_drawn_from_the_nominal_dynamics_refuses_a_shift_of_them(overrides):
    task_id = "GRAIL/MiniGrid-Boltzmann-v0" if "test_regime" not in overrides else "GRAIL/MiniGrid-Optimal-v0"
    with pytest.raises(UserError, match="boltzmann demonstrator is generated under the nominal dynamics only"):
        make_task(task_id, **overrides)
