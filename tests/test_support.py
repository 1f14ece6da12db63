"""Recognizers that know where they have evidence: off-support rules, BC's stay augmentation, the occupancy scorer,
and the refusals of settings a domain cannot serve."""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import numpy as np
import pytest
from grail_bench.core.trajectory import Trajectory
from typer.testing import CliRunner

from grail_bench import UserError
from grail_bench.cli import app
from grail_bench.harness import sweep
from grail_bench.harness.api import evaluate
from grail_bench.harness.store import ResultsStore
from grail_bench.recognizers.contract import FitReport, settings_key
from grail_bench.recognizers.policy import PolicyRecognizer, spaces_of
from grail_bench.recognizers.registry import make_recognizer
from grail_bench.recognizers.evidence import (
    RADIUS_FLOOR,
    OffSupport,
    off_support_setting,
    support_radius,
    training_states,
)
from grail_bench.task import make_task

MINIGRID = "GRAIL/MiniGrid-Optimal-4Goals-v0"
STAY = 3
TINY = {"n_epochs": 2}


def _states(traj: Trajectory, rows: np.ndarray) -> Trajectory:
    """An observation visiting ``rows`` (each with action 0): what :meth:`policy_output` needs."""
    obs = np.concatenate([rows, rows[-1:]])
    return Trajectory(obs=obs, acts=np.zeros((len(rows), *np.asarray(traj.acts).shape[1:]), traj.acts.dtype),
                      infos=None, terminal=True)


@functools.lru_cache(maxsize=None)
def _minigrid() -> tuple[Any, dict, dict]:
    task = make_task(MINIGRID)
    train, _ = task.split(task.generate_demos(0))
    return task, train, {}


def _fitted(task: Any, train: dict, name: str = "bc", **settings: Any) -> Any:
    rec = make_recognizer(name, **{**TINY, **settings})
    rec.fit(train, task.env_factory(), seed=0, cache_key=task.env_key)
    return rec


def _on_and_off(train: dict, goal: Any) -> tuple[np.ndarray, np.ndarray]:
    """Discrete states on ``goal``'s route (its training states) and off it (other goals' states it never visits)."""
    own = np.concatenate(training_states(train[goal]))
    seen = {tuple(s) for s in own.tolist()}
    others = np.concatenate([np.concatenate(training_states(train[g])) for g in train if g != goal])
    off = np.unique(np.array([s for s in others.tolist() if tuple(s) not in seen]), axis=0)
    return np.unique(own, axis=0), off


# --- off_support on discrete and continuous observations ------------------------------------------------------------


@pytest.mark.parametrize("rule", ["stay", "uniform"])
def test_a_state_on_a_goals_route_keeps_its_policy_and_a_state_off_it_gets_the_rule_discrete(rule):
    task, train, _ = _minigrid()
    trust, ruled = _fitted(task, train), _fitted(task, train, off_support=rule)
    k, goal = 0, task.goals[0]
    on, off = _on_and_off(train, goal)
    assert len(on) and len(off)
    raw = trust.outputs_at(np.concatenate([on, off])).probs[k]
    scored, _ = ruled.policy_output(_states(train[goal][0], np.concatenate([on, off])))
    np.testing.assert_array_equal(scored.probs[k, : len(on)], raw[: len(on)])  # its route: its own policy
    expected = np.eye(4)[STAY] if rule == "stay" else np.full(4, 0.25)
    np.testing.assert_allclose(scored.probs[k, len(on):], np.broadcast_to(expected, (len(off), 4)))
    assert not np.allclose(raw[len(on):], expected)  # the policy itself said something else there
    assert ruled.bank.tabled  # the rule was applied once to the table of every state: the same as applying it here
    states = np.concatenate([on, off])
    here = ruled.evidence.replace_off_support(ruled.outputs_at(states), ruled.goals, states, rule)
    np.testing.assert_array_equal(scored.probs, here.probs)
    plain, _ = trust.policy_output(_states(train[goal][0], off))
    np.testing.assert_array_equal(plain.probs, trust.outputs_at(off).probs)  # "trust" scores the policy as it is


@functools.lru_cache(maxsize=None)
def _panda() -> tuple[Any, dict]:
    task = make_task("GRAIL/PandaReach-Gaussian-0.3-v0", expert="scripted", n_demos=4, n_train=3)
    train, _ = task.split(task.generate_demos(0))
    return task, train


@pytest.mark.parametrize("rule", ["stay", "uniform"])
def test_a_state_on_a_goals_route_keeps_its_policy_and_a_state_off_it_gets_the_rule_continuous(rule):
    task, train = _panda()
    trust, ruled = _fitted(task, train, n_epochs=1), _fitted(task, train, n_epochs=1, off_support=rule)
    k, goal = 1, task.goals[1]
    on = np.concatenate(training_states(train[goal]))
    far = on[:2] + np.array([0.0, 0.0, 0.0, 5.0, 5.0, 5.0], dtype=on.dtype)  # fast, wherever the arm is: off
    states = np.concatenate([on, far])
    raw = trust.outputs_at(states)
    scored, _ = ruled.policy_output(_states(train[goal][0], states))
    mean, std = scored.mean[k], np.broadcast_to(scored.std, scored.mean.shape)[k]
    raw_std = np.broadcast_to(raw.std, raw.mean.shape)[k]
    np.testing.assert_array_equal(mean[: len(on)], raw.mean[k, : len(on)])
    np.testing.assert_array_equal(std[: len(on)], raw_std[: len(on)])
    box = trust.action_space
    if rule == "stay":
        np.testing.assert_array_equal(mean[len(on):], 0.0)  # PandaReach's no-op: the zero action
        np.testing.assert_array_equal(std[len(on):], raw_std[len(on):])  # std kept
    else:
        np.testing.assert_allclose(mean[len(on):], np.broadcast_to((box.low + box.high) / 2, (2, 3)))
        np.testing.assert_allclose(std[len(on):], np.broadcast_to((box.high - box.low) / math.sqrt(12), (2, 3)),
                                   rtol=1e-6)
    radius = ruled.evidence.radius[goal]
    assert radius > 0 and ruled.evidence.off_support([goal], states)[0].tolist() == [False] * len(on) + [True] * 2


def test_the_support_radius_rule():
    line = np.array([[0.0], [1.0], [2.0], [3.0], [10.0]])  # leave-one-out neighbours at 1, 1, 1, 1, 7
    assert support_radius(line) == pytest.approx(np.percentile([1, 1, 1, 1, 7], 95))
    assert support_radius(np.array([[2.0, -4.0]])) == pytest.approx(RADIUS_FLOOR * 4)  # a single distinct state
    # identical demonstrations count once: their distinct states give the radius
    assert support_radius(np.unique(np.concatenate([line, line]), axis=0)) == support_radius(line)


@dataclasses.dataclass(frozen=True)
class _MineConfig:
    """A third-party recognizer's settings: only the off-support rule."""

    off_support: OffSupport = off_support_setting()


class _Mine(PolicyRecognizer):
    """A third-party policy recognizer: untrained BC policies, the off-support rule through the same field."""

    name = "mine"
    Config = _MineConfig

    def new_policy(self, goal: Any, env_factory: Any) -> Any:
        from grail_bench.core.bc_update import bc_policy

        observation_space, action_space = spaces_of(env_factory, goal)
        return bc_policy(observation_space, action_space, 1e-3)

    def train_policy(self, goal: Any, demos: Any, env_factory: Any, seed: int) -> Any:
        return self.new_policy(goal, env_factory), {}


def test_a_third_party_policy_recognizer_gets_the_rule_through_the_same_field(no_noop):
    task, train, _ = _minigrid()
    goal = task.goals[0]
    _, off = _on_and_off(train, goal)
    rec = _Mine(off_support="uniform")
    rec.fit(train, task.env_factory(), seed=0)
    scored, _ = rec.policy_output(_states(train[goal][0], off))
    np.testing.assert_allclose(scored.probs[0], 0.25)
    with pytest.raises(UserError, match=r"^mine: off_support='stay' needs the domain's no-op action; domain "
                                        r"'minigrid' declares no noop_action$"):
        _Mine(off_support="stay").check_task(task)
    assert settings_key(_Mine().config) == {} and settings_key(rec.config, models=True) == {}


# --- BC's stay augmentation ---------------------------------------------------------------------------------------


def test_augment_adds_exactly_the_other_goals_off_support_states_once_each(monkeypatch):
    from grail_bench.recognizers import bc

    seen: list[tuple[np.ndarray, np.ndarray]] = []
    original = bc.train_bc

    def spy(policy: Any, obs: np.ndarray, acts: np.ndarray, **kwargs: Any) -> Any:
        seen.append((np.asarray(obs), np.asarray(acts)))
        return original(policy, obs, acts, **kwargs)

    monkeypatch.setattr(bc, "train_bc", spy)
    task, train, _ = _minigrid()
    rec = make_recognizer("bc", n_epochs=1, augment="stay")
    rec.stacked = False  # each goal through train_bc (stacking trains the same pairs: tests/test_bc_stacked.py)
    rec.fit(train, task.env_factory(), seed=0)  # no cache: all train
    assert len(seen) == len(train)
    for goal, (obs, acts) in zip(train, seen):
        own = sum(len(states) for states in training_states(train[goal]))
        _, off = _on_and_off(train, goal)
        assert len(off) > 0 and len(obs) == own + len(off)  # its own pairs, then each off-support state once
        np.testing.assert_array_equal(obs[own:], off)
        assert (acts[own:] == STAY).all()
    default, augmented = make_recognizer("bc"), make_recognizer("bc", augment="stay")
    assert settings_key(augmented.config, models=True) == {**settings_key(default.config), "augment": "stay"}


# --- the occupancy scorer -----------------------------------------------------------------------------------------


def test_occupancy_decides_where_the_policies_tie():
    from grail_bench.recognizers.scoring import PolicyOutput, check_scorer, get_scorer

    scorer = get_scorer("occupancy")
    probs = np.broadcast_to(np.array([0.1, 0.2, 0.3, 0.4]), (2, 3, 4)).copy()  # two goals, the same policy
    actions = np.array([3, 0, 2])
    occupancy = np.log(np.array([[0.5, 0.05, 0.2], [0.1, 0.1, 0.1]]))  # goal 0 visits these states more, overall
    out = PolicyOutput(probs=probs, log_occupancy=occupancy)
    scores = scorer.fn(out, actions)
    policy = np.log([0.4, 0.1, 0.3]).mean()
    np.testing.assert_allclose(scores, policy + occupancy.mean(axis=1))
    assert scores[0] > scores[1]
    assert scorer.fn(PolicyOutput(probs=probs, log_occupancy=occupancy[::-1]), actions).argmax() == 1
    prefixes = scorer.prefix_scores(out, actions)  # online mode: every prefix from one pass
    for k in range(1, 4):
        np.testing.assert_allclose(prefixes[:, k - 1], scorer.fn(out.head(k), actions[:k]))
    mean = np.zeros((2, 3, 2))  # continuous actions: the same Gaussian policy for both goals
    gaussian = PolicyOutput(mean=mean, std=np.ones((2, 1, 2)), log_occupancy=occupancy)
    assert scorer.fn(gaussian, np.ones((3, 2))).argmax() == 0 and scorer.posterior
    needs = "needs action probabilities and state occupancy or mean actions and action std and state occupancy"
    with pytest.raises(UserError, match=needs):
        check_scorer("occupancy", frozenset({"probs"}), "toy")


def _toy(space: Any, demos_states: list[list[Any]]) -> Any:
    from grail_bench.recognizers.evidence import Evidence

    def demo(states: list[Any]) -> Trajectory:
        obs = np.asarray([*states, states[-1]])
        return Trajectory(obs=obs, acts=np.zeros(len(states), dtype=np.int64), infos=None, terminal=True)

    goals = {(float(i),): [demo(d) for d in demos] for i, demos in enumerate(demos_states)}
    return goals, Evidence(goals, space, __import__("gymnasium").spaces.Discrete(2))


def test_the_prior_weight_and_the_bandwidth_follow_leave_one_demonstration_out_likelihood():
    from gymnasium import spaces

    from grail_bench.recognizers.evidence import ALPHAS, BANDWIDTHS

    same = [[[0, 1, 2]] * 3, [[5, 6, 7]] * 3]  # identical demonstrations: the held-out one is predicted exactly
    goals, evidence = _toy(spaces.Discrete(10), same)
    assert evidence.alpha == min(ALPHAS)
    a, n = evidence.alpha, 9
    expected = np.log([(3 + a) / (n + 10 * a), a / (n + 10 * a)])
    np.testing.assert_allclose(evidence.log_occupancy([(0.0,)], np.array([1, 6]))[0], expected)
    np.testing.assert_allclose(evidence.log_occupancy([(9.0,)], np.array([1])), [[-np.log(10)]])  # no demos: prior
    apart = [[[0, 1], [2, 3], [4, 5]], [[6], [7], [8]]]  # every demonstration elsewhere: the prior matters most
    assert _toy(spaces.Discrete(10), apart)[1].alpha == max(ALPHAS)
    box = spaces.Box(-5.0, 5.0, shape=(2,))
    line = [[[0.0, 0.0], [0.5, 0.2], [1.0, 0.4]]] * 3
    assert _toy(box, [line, [[[3.0, 3.0], [3.0, 2.0]]] * 3])[1].bandwidth == min(BANDWIDTHS)  # the floor
    noisy = np.random.default_rng(0).normal(size=(2, 4, 20, 2)).tolist()
    assert min(BANDWIDTHS) < _toy(box, noisy)[1].bandwidth


def test_policy_recognizers_score_occupancy_in_one_pass_and_online():
    task, train, _ = _minigrid()
    rec = _fitted(task, train)
    observed = train[task.goals[2]][0]
    states = np.asarray(observed.obs)[: len(observed.acts)]
    scores = rec.score(observed, "occupancy")
    loglik = rec.score(observed, "loglik")
    occupancy = rec.evidence.log_occupancy(rec.goals, states).mean(axis=1)
    np.testing.assert_allclose([scores[g] for g in rec.goals], [loglik[g] for g in rec.goals] + occupancy, rtol=1e-6)
    prefixes = rec.score_prefixes(observed, "occupancy")
    for k in (1, 5, len(states)):
        head = Trajectory(obs=observed.obs[: k + 1], acts=observed.acts[:k], infos=None, terminal=False)
        np.testing.assert_allclose([prefixes[g][k - 1] for g in rec.goals], list(rec.score(head, "occupancy").values()),
                                   rtol=1e-6)
    assert max(scores, key=scores.get) == task.goals[2]
    assert "occupancy" in make_recognizer("gc-bc").exposes(rec.action_space)
    assert "occupancy" in make_recognizer("draco").exposes(rec.action_space)


def test_a_recognizer_without_occupancy_refuses_the_scorer_at_planning():
    from grail_bench.harness.planning import RecognizerSpec, plan

    task = make_task(MINIGRID)
    env = task.make_env()
    with pytest.raises(UserError, match="scorer 'occupancy' needs"):
        plan(task, RecognizerSpec("graql", {}, ("occupancy",)), env.action_space)
    assert plan(task, RecognizerSpec("gail", {}, ("occupancy",)), env.action_space).labels == ("occupancy",)
    env.close()


# --- keys: scoring settings share models, not stored results --------------------------------------------------------


def test_off_support_stores_apart_but_reuses_the_cached_models(monkeypatch, tmp_path):
    reports: list[FitReport] = []
    original = PolicyRecognizer.fit

    @functools.wraps(original)
    def counted(self, *args: Any, **kwargs: Any) -> FitReport:
        reports.append(original(self, *args, **kwargs))
        return reports[-1]

    monkeypatch.setattr(PolicyRecognizer, "fit", counted)
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))
    with ResultsStore(tmp_path / "s.sqlite") as store:
        records = evaluate(MINIGRID, [("bc", TINY), ("bc", {**TINY, "off_support": "stay"}),
                                      ("bc", {**TINY, "off_support": "uniform"})],
                           seeds=1, observability=[0.3], store=store)
        hashes = {r.config_hash for r in records}
    goals = len(make_task(MINIGRID).goals)
    assert len(hashes) == 3
    assert [(r.trained, r.reused) for r in reports] == [(goals, 0), (0, goals), (0, goals)]
    default, stay = make_recognizer("bc"), make_recognizer("bc", off_support="stay")
    assert settings_key(stay.config, models=True) == settings_key(default.config, models=True) \
        == settings_key(default.config)
    assert "off_support" not in settings_key(default.config) and settings_key(stay.config)["off_support"] == "stay"


# --- refusals before any training ----------------------------------------------------------------------------------


class _WithoutNoop:
    """A domain stub: the real domain, less its ``noop_action``."""

    def __init__(self, domain: Any) -> None:
        self._domain = domain

    def __getattr__(self, name: str) -> Any:
        if name == "noop_action":
            raise AttributeError(name)
        return getattr(self._domain, name)


@pytest.fixture
def no_noop(monkeypatch):
    """Every task's domain declares no ``noop_action``, and any unit that would run fails loudly."""
    from grail_bench.task import model

    real = model.get_domain
    monkeypatch.setattr(model, "get_domain", lambda name: _WithoutNoop(real(name)))

    def trained(unit: Any) -> Any:
        raise AssertionError(f"a unit ran: {unit.describe()}")

    monkeypatch.setattr(sweep, "run_unit", trained)


REFUSED = [
    ("bc", {"off_support": "stay"}, ["bc.off_support=stay"], "bc: off_support='stay' needs the domain's no-op"),
    ("gail", {"off_support": "stay"}, ["gail.off_support=stay"], "gail: off_support='stay' needs the domain's no-op"),
    ("gc-bc", {"off_support": "stay"}, ["gc-bc.off_support=stay"], "gc-bc: off_support='stay' needs"),
    ("bc", {"augment": "stay"}, ["bc.augment=stay"], "bc: augment='stay' needs the domain's no-op"),
]


@pytest.mark.parametrize("name, settings, items, message", REFUSED, ids=[r[2][0] for r in REFUSED])
def test_a_domain_without_a_noop_refuses_stay_in_one_line_before_training(no_noop, name, settings, items, message):
    with pytest.raises(UserError) as err:
        evaluate(MINIGRID, [("bc", TINY), (name, settings)], seeds=1, observability=[0.3])
    assert message in str(err.value) and "declares no noop_action" in str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name, settings, items, message", REFUSED, ids=[r[2][0] for r in REFUSED])
def test_the_cli_refuses_stay_without_a_noop_in_one_line(no_noop, tmp_path, name, settings, items, message):
    store = tmp_path / "s.sqlite"
    args = ["run", "-t", MINIGRID, "-r", name, "--seeds", "1", "-o", "0.3", "--store", str(store), "--no-progress"]
    for item in items:
        args += ["--set", item]
    result = CliRunner().invoke(app, args, env={"COLUMNS": "200"})
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], result.stderr


def test_fit_itself_refuses_stay_without_a_noop_before_training(no_noop, monkeypatch):
    from grail_bench.recognizers.bc import BCRecognizer

    def trained(*_: Any, **__: Any) -> Any:
        raise AssertionError("a policy trained")

    monkeypatch.setattr(BCRecognizer, "train_policy", trained)
    task, train, _ = _minigrid()
    with pytest.raises(UserError, match=r"^bc: off_support='stay' needs the domain's no-op action; the env's domain "
                                        r"declares no noop_action$"):
        make_recognizer("bc", off_support="stay").fit(train, make_task(MINIGRID).env_factory(), seed=0)


# --- the packed evidence against its per-goal definitions ------------------------------------------------------------


def _continuous_evidence() -> tuple[Any, Any, np.ndarray]:
    """PandaReach's evidence, and states on, near, at the radius of and far from its goals' training states."""
    from grail_bench.recognizers.evidence import Evidence, domain_noop

    task, train = _panda()
    env = task.make_env(task.goals[0])
    evidence = Evidence(train, env.observation_space, env.action_space, domain_noop(env))
    env.close()
    rng = np.random.default_rng(0)
    own = np.concatenate([np.concatenate(training_states(train[g])) for g in task.goals]).astype(np.float64)
    direction = rng.normal(size=own.shape)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    goal = task.goals[1]
    at_radius = own[:40] + evidence.radius[goal] * direction[:40]  # as far as the radius from a training state
    states = np.concatenate([own, own + 0.01 * direction, at_radius, own[:20] + 3.0 * direction[:20]])
    return task, evidence, states


def test_continuous_support_is_the_kd_trees_nearest_distance_against_the_radius():
    task, evidence, states = _continuous_evidence()
    off = evidence.off_support(task.goals, states)
    flat = states.reshape(len(states), -1)
    for k, goal in enumerate(task.goals):
        expected = evidence._trees[goal].query(flat, k=1)[0] > evidence.radius[goal]  # the definition, per goal
        np.testing.assert_array_equal(off[k], expected)
        assert 0 < expected.sum() < len(states)  # both sides are tested
    unknown = (9.0, 9.0, 9.0)  # a goal without demonstrations has no support; the order asked is kept
    reordered = evidence.off_support([task.goals[2], unknown, task.goals[0]], states)
    np.testing.assert_array_equal(reordered, np.stack([off[2], np.ones(len(states), bool), off[0]]))


def test_continuous_occupancy_is_each_goals_kernel_density():
    from grail_bench.recognizers.evidence import _log_kde, _squared_distances

    task, evidence, states = _continuous_evidence()
    scaled = (states - evidence._centre) / evidence._scale
    jacobian = np.sum(np.log(evidence._scale))
    got = evidence.log_occupancy(task.goals, states)
    for k, goal in enumerate(task.goals):
        points = evidence._scaled(np.concatenate(evidence.states[goal]))  # every visit, repeated states included
        expected = _log_kde(_squared_distances(scaled, points), evidence.bandwidth, len(points), points.shape[1])
        np.testing.assert_allclose(got[k], expected - jacobian, rtol=0, atol=1e-9)
    assert got.min() < -1000  # far states too, where unshifted kernel terms would all underflow
    unknown = (9.0, 9.0, 9.0)
    reordered = evidence.log_occupancy([unknown, task.goals[3]], states)
    box = evidence.observation_space
    np.testing.assert_allclose(reordered[0], -np.sum(np.log(box.high.astype(float) - box.low)))  # the prior
    np.testing.assert_array_equal(reordered[1], got[3])


def test_continuous_evidence_takes_many_states_in_blocks(monkeypatch):
    from grail_bench.recognizers import evidence as module

    task, evidence, states = _continuous_evidence()
    whole = evidence.off_support(task.goals, states), evidence.log_occupancy(task.goals, states)
    monkeypatch.setattr(module, "_BLOCK_ENTRIES", 7 * evidence._packed.support.shape[1])  # 7 states a block
    np.testing.assert_array_equal(evidence.off_support(task.goals, states), whole[0])
    np.testing.assert_allclose(evidence.log_occupancy(task.goals, states), whole[1], rtol=0, atol=1e-12)


def test_discrete_evidence_in_any_goal_order():
    task, train, _ = _minigrid()
    evidence = _fitted(task, train).evidence
    states = np.concatenate([np.concatenate(training_states(train[g])) for g in task.goals])
    off, occupancy = evidence.off_support(task.goals, states), evidence.log_occupancy(task.goals, states)
    unknown = (99, 99)
    asked = [task.goals[3], unknown, task.goals[0]]
    np.testing.assert_array_equal(evidence.off_support(asked, states), np.stack([off[3], np.ones(len(states), bool),
                                                                                  off[0]]))
    prior = np.full(len(states), -np.log(9 * 9 * 4))  # MiniGrid's observation: x, y and direction
    np.testing.assert_array_equal(evidence.log_occupancy(asked, states), np.stack([occupancy[3], prior, occupancy[0]]))
    own = np.concatenate(training_states(train[task.goals[0]]))
    assert not off[0][: len(own)].any() and off[0][len(own):].any()


def test_the_other_goals_off_support_states_are_found_once_and_kept_read_only():
    task, train, _ = _minigrid()
    evidence = _fitted(task, train).evidence
    first = evidence.others_off_support(task.goals[0])
    assert evidence.others_off_support(task.goals[0]) is first and not first.flags.writeable
    _, off = _on_and_off(train, task.goals[0])
    np.testing.assert_array_equal(first, off)


def test_a_space_of_more_states_than_an_integer_holds_is_refused_by_the_evidence_in_one_line():
    """81 binary fluents (a blocks-world problem of Pereira et al.'s dataset) are 2**81 states: counted exactly,
    not wrapped round by a fixed-width product, and refused as a table of supports (the policy's own output is
    then scored, as with ``off_support="trust"``)."""
    from gymnasium import spaces

    from grail_bench.core.spaces import n_states
    from grail_bench.recognizers.evidence import Evidence

    space = spaces.MultiDiscrete([2] * 81)
    assert n_states(space) == 2 ** 81
    obs = np.zeros((3, 81), dtype=np.int64)
    demos = {(0.0,): [Trajectory(obs=obs, acts=np.zeros(2, dtype=np.int64), infos=None, terminal=True)]}
    with pytest.raises(UserError, match=r"^off-support rules need discrete observation spaces of fewer than 2\*\*62"):
        Evidence(demos, space, spaces.Discrete(2))


# --- action_box: continuous means clipped to the env's action box ----------------------------------------------------


def _loud(rec: Any) -> Any:
    """``rec`` with every policy's mean 200 times larger, so that it leaves the action box, as a PPO agent's does."""
    quiet = rec.outputs_at
    rec.outputs_at = lambda states: dataclasses.replace(quiet(states), mean=quiet(states).mean * 200)
    return rec


def test_action_box_clip_scores_the_mean_clipped_to_the_box_from_the_same_models():
    task, train = _panda()
    plain = _loud(_fitted(task, train, n_epochs=1))
    clipped = _loud(_fitted(task, train, n_epochs=1, action_box="clip"))
    goal = task.goals[0]
    states = np.concatenate(training_states(train[goal]))
    box, raw = plain.action_space, plain.outputs_at(states)
    assert np.any(raw.mean > box.high) and np.any(raw.mean < box.low)
    observed = _states(train[goal][0], states)
    scored, _ = clipped.policy_output(observed)
    np.testing.assert_array_equal(scored.mean, np.clip(raw.mean, box.low, box.high))
    np.testing.assert_array_equal(np.broadcast_to(scored.std, scored.mean.shape),
                                  np.broadcast_to(raw.std, raw.mean.shape))  # the spread is kept
    as_is, _ = plain.policy_output(observed)
    np.testing.assert_array_equal(as_is.mean, raw.mean)  # "ignore", the default, scores the mean as it is
    assert clipped.score(observed, "mse") != plain.score(observed, "mse")
    assert "action_box" not in settings_key(plain.config) and settings_key(clipped.config)["action_box"] == "clip"
    assert settings_key(clipped.config, models=True) == settings_key(plain.config, models=True)


def test_action_box_clip_on_discrete_actions_is_one_line_before_training(monkeypatch):
    from grail_bench.recognizers.bc import BCRecognizer

    def trained(*_: Any, **__: Any) -> Any:
        raise AssertionError("a policy trained")

    monkeypatch.setattr(BCRecognizer, "train_policy", trained)
    message = "bc: action_box='clip' needs a bounded continuous action box, got Discrete(4)"
    with pytest.raises(UserError) as err:
        evaluate(MINIGRID, [("bc", TINY), ("bc", {**TINY, "action_box": "clip"})], seeds=1, observability=[0.3])
    assert str(err.value) == message
    task, train, _ = _minigrid()
    with pytest.raises(UserError, match=r"^bc: action_box='clip' needs"):
        make_recognizer("bc", action_box="clip").fit(train, task.env_factory(), seed=0)
