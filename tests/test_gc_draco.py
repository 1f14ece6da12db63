"""GC-DRACO (grail_bench.contrib.gc_draco): one goal-conditioned RL agent, DRACO's Wasserstein scoring."""

from __future__ import annotations

import ast
import inspect

import numpy as np
import pytest
import scipy.stats
import torch

import grail_bench
from grail_bench.contrib import gc_draco
from grail_bench.contrib.gc_draco import GCDRACORecognizer
from grail_bench.core.rl import empty_policy
from grail_bench.core.spaces import all_states, preprocess
from grail_bench.harness.api import evaluate
from grail_bench.harness.store import ResultsStore, ZeroShotRow
from grail_bench.recognizers import make_recognizer
from grail_bench.recognizers.draco import DRACORecognizer
from grail_bench.recognizers.policy_bank import PolicyBank
from grail_bench.task.observation import observe

TASK = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
TRAIN, TEST = TASK.split(TASK.generate_demos(seed=0))
TINY = {"ppo_steps": 1024}
BUDGET = {"ppo_steps": 60_000}


def fitted(seed: int = 0, **settings) -> GCDRACORecognizer:
    rec = GCDRACORecognizer(**(settings or TINY))
    rec.fit(TRAIN, TASK.env_factory(), seed=seed)
    return rec


def observations(level: float) -> list[tuple[int, object]]:
    return [(i, observe(t, level, "prefix")) for i, g in enumerate(TASK.goals) for t in TEST[g]]


def test_registered_and_written_against_public_names_only():
    assert isinstance(make_recognizer("gc-draco", **TINY), GCDRACORecognizer)
    allowed = ("grail_bench.core.", "grail_bench.recognizers.contract", "grail_bench.recognizers.scoring",
               "grail_bench.recognizers.policy_bank", "grail_bench.recognizers.gcbc")
    tree = ast.parse(inspect.getsource(gc_draco))
    imported = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module.startswith("grail_b")]
    assert imported and all(m.startswith(allowed) for m in imported), imported


def test_settings_are_checked_and_sac_needs_continuous_actions():
    with pytest.raises(grail_bench.UserError, match=r"ppo_steps=0 is out of range \(allowed 1\.\."):
        GCDRACORecognizer(ppo_steps=0)
    with pytest.raises(grail_bench.UserError, match="algorithm"):
        GCDRACORecognizer(algorithm="dqn")
    with pytest.raises(grail_bench.UserError, match="SAC needs continuous actions"):
        GCDRACORecognizer(algorithm="sac").exposes(TASK.make_env().action_space)
    assert make_recognizer("gc-draco").default_scorer == "wasserstein"


@pytest.mark.slow
def test_recognises_above_chance_at_full_observability():
    """Trained by RL alone on the env's reward (never on the demonstrations), the agent tells the two goals apart
    from whole paths: above chance (0.5) over 3 seeds, though not on every seed. At this budget some seeds' agents
    head for one goal whatever they are given; which ones differs between CPUs (their floating-point kernels
    steer the RL runs apart), so no seed is named."""
    accuracy = {}
    for seed in (0, 1, 2):
        rec = fitted(seed, **BUDGET)
        accuracy[seed] = np.mean([max((s := rec.score(o)), key=s.get) == TASK.goals[i] for i, o in observations(1.0)])
    assert np.mean(list(accuracy.values())) > 0.6, accuracy


def test_same_seed_same_scores_and_the_cache_returns_the_same_agent():
    observed = observe(TEST[(7, 7)][0], 0.4, "prefix")
    first = fitted(3).score(observed)
    assert first != fitted(4).score(observed)
    cached = [GCDRACORecognizer(**TINY) for _ in range(2)]
    reports = [rec.fit(TRAIN, TASK.env_factory(), seed=3, cache_key="minigrid-test") for rec in cached]
    assert [(r.trained, r.reused) for r in reports] == [(1, 0), (0, 1)]
    assert reports[0].train_seconds == reports[1].train_seconds > 0  # what the cached agent cost to train
    # Trained again with the same seed (the first cached fit), then read back: the same scores each time.
    assert cached[0].score(observed) == cached[1].score(observed) == first


def test_set_goals_scores_goals_it_never_trained_on():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0")
    train, test = task.split(task.generate_demos(0))
    rec = GCDRACORecognizer(**TINY)
    with pytest.raises(RuntimeError, match="fit"):
        rec.set_goals(task.goals)
    rec.fit({g: train[g] for g in [(7, 1), (7, 7)]}, task.env_factory(), seed=0)
    rec.set_goals(task.goals)
    scores = rec.score(observe(test[(7, 3)][0], 0.5, "prefix"))
    assert list(scores) == list(task.goals) and all(np.isfinite(list(scores.values())))
    assert len(set(scores.values())) == 4  # each goal conditions the agent: no goal copies another's scores
    with pytest.raises(grail_bench.UserError, match="2 coordinates"):
        rec.set_goals([(1, 2, 3)])


def _draco_twin(rec: GCDRACORecognizer) -> DRACORecognizer:
    """A DRACO recognizer whose policy of each goal is GC-DRACO's agent conditioned on that goal.

    On MiniGrid the agent's input for a fixed goal is affine in the state's one-hot code (DRACO's policies'
    input), so each goal's first layer folds the goal encoding in: the same network on the same states.
    """
    space = rec.observation_space
    states = all_states(space)
    codes = preprocess(states, space).astype(np.float64)  # (S, P)
    agent = rec.agent.state_dict()
    policies = []
    for goal in rec.goals:
        features = rec.encoder.encode(states, [goal])[0].astype(np.float64)  # (S, F)
        fold, *_ = np.linalg.lstsq(codes, features, rcond=None)  # (P, F): codes @ fold = features
        assert np.abs(codes @ fold - features).max() < 1e-5
        policy = empty_policy("ppo", space, rec.action_space, list(rec.config.net_arch))
        state = dict(agent)
        for net in ("policy_net", "value_net"):
            name = f"mlp_extractor.{net}.0.weight"
            state[name] = torch.as_tensor(agent[name].double().numpy() @ fold.T, dtype=torch.float32)
        policy.load_state_dict(state)
        policies.append(policy)
    draco = DRACORecognizer()
    draco.goals, draco.bank = list(rec.goals), PolicyBank(policies)
    draco.observation_space, draco.action_space = space, rec.action_space
    return draco


def test_wasserstein_scoring_is_dracos_and_a_true_wasserstein_distance():
    rec = fitted(0)
    draco = _draco_twin(rec)
    for _, observed in observations(0.5):
        ours, theirs = rec.score(observed), draco.score(observed)
        assert ours == pytest.approx(theirs, abs=1e-5)
        # Each step's distance is scipy's W1 between the action distribution and the observed action.
        acts = np.asarray(observed.acts)
        for goal in rec.goals:
            features = torch.as_tensor(rec.encoder.encode(np.asarray(observed.obs[:-1]), [goal])[0])
            with torch.no_grad():
                probs = rec.agent.get_distribution(features).distribution.probs.numpy()
            w1 = [scipy.stats.wasserstein_distance(np.arange(probs.shape[1]), [a], u_weights=p)
                  for p, a in zip(probs, acts)]
            assert ours[goal] == pytest.approx(-np.mean(w1), abs=1e-5)


def test_a_zero_shot_run_stores_its_adaptation_time(tmp_path):
    task = "GRAIL/MiniGrid-Optimal-4Goals-v0"
    with ResultsStore(tmp_path / "r.sqlite") as store:
        (record,) = evaluate(task, [("gc-draco", TINY)], seeds=1, mode="zero-shot", observability=[1.0], store=store)
        (row,) = store.select(ZeroShotRow)
    assert row.recognizer == "gc-draco" and row.scorer == "wasserstein"
    assert row.adapt_seconds_per_goal > 0 and row.score_us_per_observation > 0 and row.fit_seconds_per_goal > 0
    assert record.adapt_seconds_per_goal == row.adapt_seconds_per_goal


def test_continuous_actions_train_one_sac_agent():
    """PointMaze's force actions: SAC (as DRACO's continuous choice), scored by the Gaussian Wasserstein distance."""
    from stable_baselines3.sac.policies import SACPolicy

    task = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    train, test = task.split(task.generate_demos(0))
    rec = GCDRACORecognizer(sac_steps=550)
    rec.fit({g: train[g] for g in task.goals[:3]}, task.env_factory(), seed=0)
    assert isinstance(rec.agent, SACPolicy) and rec.exposes(rec.action_space) == {"mean", "std", "occupancy"}
    rec.set_goals(task.goals)
    scores = rec.score(observe(test[task.goals[4]][0], 0.3, "prefix"))
    assert list(scores) == list(task.goals) and all(np.isfinite(v) and v < 0 for v in scores.values())


def test_ppo_agents_on_continuous_actions_are_keyed_apart_from_sb3_trained_ones(monkeypatch, tmp_path):
    """PPO's update runs in numpy on continuous actions too; those agents carry it in their cache key, discrete
    ones keep the key they always had."""
    import json

    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    task = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    train, _ = task.split(task.generate_demos(0))
    GCDRACORecognizer(algorithm="ppo", ppo_steps=1024).fit({g: train[g] for g in task.goals[:2]},
                                                          task.env_factory(), seed=0, cache_key="maze-test")
    GCDRACORecognizer(**TINY).fit(TRAIN, TASK.env_factory(), seed=0, cache_key="minigrid-test")
    keys = {(k := json.loads(p.read_text())["key"])["env"]: k for p in (tmp_path / "policy-gc-draco").glob("*.json")}
    assert keys["maze-test"]["update"] == "numpy" and "update" not in keys["minigrid-test"]
