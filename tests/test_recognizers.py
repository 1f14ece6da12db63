"""Every registered recognizer against the protocol; built-in specifics."""

from __future__ import annotations

import functools
import json
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import torch
from conftest import FAST
from gymnasium import spaces
from grail_bench.core.trajectory import Trajectory
from stable_baselines3.common.policies import ActorCriticPolicy

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.core.ppo_update import mirrorable
from grail_bench.core.rl import make_ppo
from grail_bench.recognizers import Recognizer, UnknownRecognizerError, available_recognizers, make_recognizer
from grail_bench.recognizers.contract import capabilities
from grail_bench.recognizers.registry import register_recognizer, unregister_recognizer
from grail_bench.task.observation import observe

TASK = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
TRAIN, TEST = TASK.split(TASK.generate_demos(seed=0))
BUILTINS = sorted(available_recognizers())


@functools.cache
def case(name: str) -> tuple[Any, dict, dict]:
    """``(task, train, test)`` a recognizer is checked on: MiniGrid-Biased, or, for a recognizer that refuses it
    where a run is planned (in one line, as planning-based ones refuse tasks without a STRIPS model), a symbolic
    task."""
    try:
        capabilities(make_recognizer(name), name).check_task(TASK)
    except UserError as exc:
        assert str(exc) and "\n" not in str(exc)
        task = grail_bench.make_task("GRAIL/Symbolic-Grid-Optimal-v0")
        return (task, *task.split(task.generate_demos(seed=0)))
    return TASK, TRAIN, TEST


def fitted(name: str, seed: int = 0):
    task, train, _ = case(name)
    rec = make_recognizer(name, **FAST.get(name, {}))
    rec.fit(train, task.make_env, seed=seed)
    return rec


@pytest.mark.parametrize("name", BUILTINS)
def test_conforms_to_protocol(name):
    task, train, test = case(name)
    rec = make_recognizer(name, **FAST.get(name, {}))
    assert isinstance(rec, Recognizer)
    assert rec.name == name
    rec.fit(train, task.make_env, seed=0)
    scores = rec.score(observe(test[task.goals[0]][0], 0.3))
    assert set(scores) == set(task.goals)
    assert all(isinstance(v, float) and np.isfinite(v) for v in scores.values())


@pytest.mark.parametrize("name", BUILTINS)
def test_same_seed_same_scores(name):
    task, _, test = case(name)
    observed = observe(test[task.goals[-1]][0], 0.4)
    assert fitted(name, seed=3).score(observed) == fitted(name, seed=3).score(observed)


@pytest.mark.parametrize("name", BUILTINS)
def test_bad_observations_are_clear_errors(name):
    task, _, test = case(name)
    rec = fitted(name)
    traj = test[task.goals[0]][0]
    cases = [
        (SimpleNamespace(obs=traj.obs[:1], acts=traj.acts[:0]), "empty"),
        (Trajectory(obs=traj.obs[:, :2], acts=traj.acts, infos=None, terminal=False), "shape"),
        ("not a trajectory", "expected a Trajectory"),
    ]
    for observed, message in cases:
        with pytest.raises(ValueError, match=message):
            rec.score(observed)


@pytest.mark.parametrize("name", BUILTINS)
def test_score_before_fit_is_an_error(name):
    with pytest.raises(RuntimeError, match="fit"):
        make_recognizer(name).score(observe(TEST[(7, 1)][0], 0.3))


def test_malformed_trajectory_lengths():
    rec = fitted("bc")

    loose = SimpleNamespace(obs=TEST[(7, 1)][0].obs[:3], acts=TEST[(7, 1)][0].acts[:5])  # not a checked Trajectory
    with pytest.raises(ValueError, match="malformed"):
        rec.score(loose)


def test_policy_bank_matches_sb3_policies():
    rec = fitted("bc")
    obs = TEST[(7, 1)][0].obs[:20]
    bank_probs = rec.bank.action_probs(obs)
    env = TASK.make_env()
    for goal in TASK.goals:
        # Re-train the same goal's policy to compare against torch directly.
        policy, _ = rec.train_policy(goal, TRAIN[goal], TASK.make_env, seed=11)
        from grail_bench.recognizers.policy_bank import PolicyBank

        single = PolicyBank([policy]).action_probs(obs)[0]
        with torch.no_grad():
            obs_t, _ = policy.obs_to_tensor(obs)
            expected = policy.get_distribution(obs_t).distribution.probs.numpy()
        np.testing.assert_allclose(single, expected, rtol=1e-5, atol=1e-6)
    assert bank_probs.shape == (2, 20, env.action_space.n)


def test_policy_bank_looks_up_discrete_observations_as_the_one_hot_product():
    from grail_bench.recognizers.policy_bank import _apply, preprocess

    bank = fitted("bc").bank
    obs = np.concatenate([t.obs for t in TEST[(7, 7)]])
    one_hot_product = _apply(preprocess(obs, bank.observation_space)[None], bank.trunk)
    np.testing.assert_allclose(bank._latent(obs), one_hot_product, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize(("space", "n_states"), [(spaces.MultiDiscrete([9, 9, 4]), 324), (spaces.Discrete(7, start=2), 7)])
def test_policy_bank_table_of_every_state_equals_the_forward_pass(space, n_states, monkeypatch):
    from grail_bench.recognizers import policy_bank

    torch.manual_seed(0)
    policies = [ActorCriticPolicy(space, spaces.Discrete(4), lambda _: 1e-3) for _ in range(3)]
    obs = np.stack([space.sample() for _ in range(50)])
    tabled = policy_bank.PolicyBank(policies)
    looked_up = tabled.action_probs(obs)
    assert tabled._tables["probs"].shape == (3, n_states, 4)
    monkeypatch.setattr(policy_bank, "TABLE_STATES", 0)
    direct = policy_bank.PolicyBank(policies)
    np.testing.assert_allclose(looked_up, direct.action_probs(obs), rtol=1e-6, atol=1e-7)
    assert not direct._tables  # above the size limit, nothing is tabled


def test_bc_separates_biased_routes():
    rec = make_recognizer("bc")
    rec.fit(TRAIN, TASK.make_env, seed=0)
    for goal, trajs in TEST.items():
        for traj in trajs:
            scores = rec.score(observe(traj, 0.2))
            assert max(scores, key=scores.get) == goal


def test_graql_learns_to_reach_goals():
    rec = make_recognizer("graql")
    rec.fit(TRAIN, TASK.make_env, seed=0)
    from grail_bench.core.spaces import state_index

    for k, goal in enumerate(TASK.goals):
        env = TASK.make_env(goal)
        obs, _ = env.reset(seed=0)
        for _ in range(env.unwrapped.max_steps):
            obs, _, _, _, info = env.step(int(rec.q[k, state_index(obs[None], env.observation_space)[0]].argmax()))
            if info["is_success"]:
                break
        assert info["is_success"], f"greedy Q policy never reaches {goal}"


@pytest.mark.parametrize("env_params", [{}, {"fixed_horizon": False}, {"max_steps": 40}])
@pytest.mark.parametrize("config", [{}, {"max_episode_steps": 30}])
def test_graql_on_the_rooms_tables_learns_what_stepping_the_env_learns(env_params, config):
    """MiniGrid offers its dynamics as tables; Q-learning on them gives the stepped env's Q-table bit for bit."""
    rec = make_recognizer("graql", episodes=1000, **config)
    for goal in TASK.goals:
        from_tables = rec._q_learning(TASK.make_env(goal, **env_params), seed=5)
        stepped = TASK.make_env(goal, **env_params)
        stepped.tabular_dynamics = None  # hides the tables: the env is stepped
        from_env = rec._q_learning(stepped, seed=5)
        assert np.array_equal(from_tables[0], from_env[0]) and np.array_equal(from_tables[1], from_env[1])
        assert from_tables[2] == from_env[2] and max(from_env[2]) > 0  # returns; the goal was reached


def test_graql_unvisited_states_get_uniform_policy():
    rec = fitted("graql")
    np.testing.assert_allclose(rec._softmax_policy(rec.q, np.zeros_like(rec.visited)), 0.25)
    visited_probs = rec.outputs_at(TEST[(7, 1)][0].obs[:4]).probs  # states its training walked through
    assert not np.allclose(visited_probs, 0.25)


def test_registry_errors():
    with pytest.raises(UnknownRecognizerError, match="unknown recognizer 'nope'; available: .*bc"):
        make_recognizer("nope")
    with pytest.raises(ValueError, match="already registered"):
        register_recognizer("bc", lambda: None)
    with pytest.raises(ValueError, match="does not satisfy the recognizer contract: it lacks fit and score"):
        register_recognizer("broken", lambda: object())
        try:
            make_recognizer("broken")
        finally:
            unregister_recognizer("broken")
    with pytest.raises(ValueError, match="recognizer 'bc': got an unexpected keyword argument 'n_epochz'"):
        make_recognizer("bc", n_epochz=3)
    with pytest.raises(ValueError, match="epsilon_start and epsilon_end must be in"):
        make_recognizer("graql", epsilon_end=-0.1)


def test_plugin_found_through_entry_point(toy_plugin):
    assert "toy" in available_recognizers()
    rec = make_recognizer("toy")
    rec.fit(TRAIN, TASK.make_env, seed=0)
    scores = rec.score(observe(TEST[(7, 7)][0], 0.3))
    assert max(scores, key=scores.get) == (7, 7)


def test_duplicate_entry_point_names_are_withheld(toy_plugin, tmp_path, monkeypatch):
    """Two plugins claiming one name: neither is used, the others still list, and asking for it names both."""
    from conftest import install_plugin

    other = install_plugin(tmp_path / "other", name="toy", target="toy_recognizer:Other")
    monkeypatch.syspath_prepend(str(other))
    assert "toy" not in available_recognizers() and "bc" in available_recognizers()
    with pytest.raises(ValueError, match="registered twice"):
        make_recognizer("toy")


def test_policy_bank_matches_sac_actor():
    from stable_baselines3 import SAC

    from grail_bench.domains.panda_reach.env import GRPandaReachEnv
    from grail_bench.recognizers.policy_bank import PolicyBank

    env = GRPandaReachEnv()
    models = [SAC("MlpPolicy", env, policy_kwargs={"net_arch": [16, 16]}, seed=s, device="cpu") for s in (0, 1)]
    obs = np.random.default_rng(0).normal(size=(5, 6)).astype(np.float32) * 0.1
    bank = PolicyBank([m.policy for m in models])
    mean, std = bank.mean_std(obs)
    for k, model in enumerate(models):
        with torch.no_grad():
            expected = model.policy.actor(torch.as_tensor(obs), deterministic=True).numpy()
            _, log_std, _ = model.policy.actor.get_action_dist_params(torch.as_tensor(obs))
        np.testing.assert_allclose(mean[k], expected, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(std[k], (1 - expected ** 2) * np.exp(log_std.numpy()), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", ["bc", "gail", "draco"])
def test_trained_policies_are_cached_and_reloaded(name, monkeypatch, tmp_path):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))  # counts from an empty cache, in any test order
    factory = TASK.env_factory()
    first = make_recognizer(name, **FAST[name])
    first_report = first.fit(TRAIN, factory, seed=4, cache_key=TASK.env_key)
    assert (first_report.trained, first_report.reused) == (2, 0)
    observed = observe(TEST[(7, 1)][0], 0.3)
    expected = first.score(observed)

    calls = []  # one per goal trained, alone or with others
    second = make_recognizer(name, **FAST[name])
    original, together = second.train_policy, second.train_policies
    monkeypatch.setattr(second, "train_policy", lambda *a, **k: calls.append(1) or original(*a, **k))

    def train_together(*args):
        got = together(*args)
        calls.extend([1] * len(got))
        return got

    monkeypatch.setattr(second, "train_policies", train_together)
    report = second.fit(TRAIN, factory, seed=4, cache_key=TASK.env_key)
    assert calls == [] and second.score(observed) == expected
    assert (report.trained, report.reused) == (0, 2)
    assert report.train_seconds == pytest.approx(first_report.train_seconds)  # what training cost, not loading

    other_task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0", route_choice="uniform")
    other_train, _ = other_task.split(other_task.generate_demos(seed=0))
    second.fit(other_train, other_task.env_factory(), seed=4, cache_key=other_task.env_key)
    # Imitation learners retrain on other demonstrations; DRACO ignores them and reuses its policies.
    assert calls == ([] if name == "draco" else [1, 1])


def test_draco_updates_ppo_in_numpy_and_keys_those_models_apart(monkeypatch, tmp_path):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    factory = TASK.env_factory()
    assert mirrorable(make_ppo(lambda: factory(TASK.goals[0]), [64, 64]))  # DRACO's PPO on MiniGrid: numpy update
    make_recognizer("draco", **FAST["draco"]).fit(TRAIN, factory, seed=0, cache_key=TASK.env_key)
    keys = [json.loads(p.read_text())["key"] for p in (tmp_path / "policy-draco").glob("*.json")]
    assert len(keys) == 2 and all(k["update"] == "numpy" for k in keys)
    # Continuous actions too (PandaReach, PointMaze): SB3-trained models there had no such entry.
    maze = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    assert mirrorable(make_ppo(lambda: maze.make_env(maze.goals[0]), [64, 64]))
    assert make_recognizer("draco").model_key(maze.goals[0]) == {"update": "numpy"}
    assert make_recognizer("draco", algorithm="sac").model_key(maze.goals[0]) == {}


def test_draco_identity_holds_only_the_chosen_algorithms_budget(monkeypatch):
    """PPO and SAC fits key results and models apart, and a new default for one algorithm leaves the other's
    stored results and cached models valid."""
    from grail_bench.harness.planning import RecognizerSpec, plan
    from grail_bench.recognizers import draco
    from grail_bench.recognizers.contract import settings_key

    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", expert="scripted")
    action_space = task.make_env().action_space

    def identity(**config):
        return plan(task, RecognizerSpec("draco", config, ()), action_space).config_hash

    sac = make_recognizer("draco", algorithm="sac")
    assert settings_key(sac.config) == {"algorithm": "sac", "sac_steps": draco.STEPS["sac"], "net_arch": [64, 64]}
    assert identity() != identity(algorithm="sac")
    before = identity(algorithm="sac"), identity(algorithm="sac", sac_steps=5000)
    monkeypatch.setitem(draco.STEPS, "ppo", draco.STEPS["ppo"] + 1)
    assert (identity(algorithm="sac"), identity(algorithm="sac", sac_steps=5000)) == before


def test_graql_refuses_a_space_too_large_for_its_table_before_learning():
    """A symbolic problem of 30 fluents has 2**30 states: a one-line refusal, not a table that exhausts memory."""
    import gymnasium as gym

    class Fluents(gym.Env):
        observation_space = spaces.MultiDiscrete([2] * 30)
        action_space = spaces.Discrete(4)

    with pytest.raises(UserError, match=r"^graql keeps a Q-table row for every state: .* 1\.07e\+09 states, more than"):
        make_recognizer("graql")._q_learning(Fluents(), seed=0)
