"""BC's goals trained together: the stacked loop gives each goal bit for bit what the per-goal numpy loop gives it
alone, and a fit that stacks its goals stores, reuses and reports what the goal-by-goal fit does."""

from __future__ import annotations

import json

import pytest
import torch
from test_bc_update import SPACES, pairs

import grail_bench
from grail_bench.core import bc_update
from grail_bench.recognizers import make_recognizer
from grail_bench.recognizers import policy as policy_module
from grail_bench.recognizers.bc import BCRecognizer
from grail_bench.recognizers.policy_bank import PolicyBank

TASK = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
TRAIN, _ = TASK.split(TASK.generate_demos(seed=0))
SIZES = [203, 77, 150, 9]  # unequal: the goals stop after 150, 54, 108 and 6 steps (6 epochs, batch 8)


def fresh(kind: str, seed: int):
    torch.manual_seed(seed)
    return bc_update.bc_policy(*SPACES[kind], 1e-3)


@pytest.mark.parametrize("kind", SPACES)
def test_stacked_loop_equals_per_goal_loop_bit_for_bit(kind):
    obs, acts = pairs(kind)
    data = [(obs[:n], acts[:n]) for n in SIZES]
    settings = {"learning_rate": 1e-3, "ent_weight": 1e-2}
    alone = []
    for i, (o, a) in enumerate(data):
        policy = fresh(kind, 10 + i)
        losses = bc_update.train_bc(policy, o, a, batch_size=8, n_epochs=6, log_interval=3, **settings)
        alone.append((policy.state_dict(), losses))
    policies, orders = [], []
    for i, (o, _) in enumerate(data):  # each goal's policy and batches under its own seed, as it trains alone
        policies.append(fresh(kind, 10 + i))
        orders.append(bc_update.batch_order(len(o), 8, 6, None))
    assert sorted({len(order) for order in orders}) == [6, 54, 108, 150]
    run = bc_update.train_bc_stacked(policies, data, orders, log_intervals=[3] * len(data), **settings)
    for policy, losses, seconds, (expected, expected_losses) in zip(policies, run.losses, run.seconds, alone):
        assert losses == expected_losses and seconds > 0
        for key, value in policy.state_dict().items():
            assert torch.equal(value, expected[key]), key
    assert not torch.equal(alone[0][0]["action_net.weight"], fresh(kind, 10).state_dict()["action_net.weight"])


@pytest.fixture(autouse=True)
def banked(monkeypatch) -> list:
    """The policies of every fit's bank, as the fits hand them to it."""
    policies = []
    monkeypatch.setattr(policy_module, "PolicyBank", lambda given: policies.append(given) or PolicyBank(given))
    return policies


def fit(rec: BCRecognizer, banked: list, **kwargs) -> tuple[dict, dict, torch.Tensor]:
    """A fit's policies (state_dicts), curves and the next draws of torch's global generator."""
    rec.fit(TRAIN, TASK.make_env, seed=5, **kwargs)
    states = {g: {k: v.clone() for k, v in p.state_dict().items()} for g, p in zip(rec.goals, banked[-1])}
    return states, rec.curves, torch.rand(3)


@pytest.mark.parametrize("augment", ["none", "stay"])
def test_fit_stacked_equals_fit_goal_by_goal(augment, monkeypatch, banked):
    by_goal = make_recognizer("bc", n_epochs=3, augment=augment)
    by_goal.stacked = False
    stacked = make_recognizer("bc", n_epochs=3, augment=augment)
    together = []
    original = bc_update.train_bc_stacked
    monkeypatch.setattr(bc_update, "train_bc_stacked",
                        lambda policies, *a, **k: together.append(len(policies)) or original(policies, *a, **k))
    expected, expected_curves, expected_next = fit(by_goal, banked)
    assert together == []
    got, curves, got_next = fit(stacked, banked)
    assert together == [len(TRAIN)]  # every goal in one stacked run
    assert torch.equal(got_next, expected_next)  # torch's generator is left where the goal-by-goal fit leaves it
    assert curves == expected_curves
    for goal, state in expected.items():
        assert all(torch.equal(got[goal][k], v) for k, v in state.items()), goal


def test_goals_the_stacked_loop_cannot_run_train_alone(monkeypatch, banked):
    expected, _, _ = fit(make_recognizer("bc", n_epochs=2), banked)  # stacked
    keys = iter([None])
    original = bc_update.stack_key
    monkeypatch.setattr(bc_update, "stack_key", lambda policy: next(keys, original(policy)))  # the first goal: no key
    alone = []
    train_policy = BCRecognizer.train_policy

    def spy(self: BCRecognizer, goal, *args):
        alone.append(goal)
        return train_policy(self, goal, *args)

    monkeypatch.setattr(BCRecognizer, "train_policy", spy)
    got, _, _ = fit(make_recognizer("bc", n_epochs=2), banked)
    assert alone == [next(iter(TRAIN))]
    for goal, state in expected.items():
        assert all(torch.equal(got[goal][k], v) for k, v in state.items()), goal


def spy_on_jobs(rec: BCRecognizer, asked: list, monkeypatch) -> None:
    """Record the goals each call of ``rec.train_policies`` is asked to train."""
    original = rec.train_policies
    monkeypatch.setattr(rec, "train_policies",
                        lambda jobs, factory: asked.append(list(jobs)) or original(jobs, factory))


def test_stacked_fit_caches_per_goal_and_reuses_every_goal(monkeypatch, tmp_path, banked):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    first = make_recognizer("bc", n_epochs=2)
    report = first.fit(TRAIN, TASK.make_env, seed=5, cache_key=TASK.env_key)
    assert (report.trained, report.reused) == (len(TRAIN), 0)
    sidecars = [json.loads(p.read_text()) for p in (tmp_path / "policy-bc").glob("*.json")]
    assert len(sidecars) == len(TRAIN)
    # Each goal's share of the stacked run is what its entry records, and they add up to the fit's.
    assert sum(s["train_seconds"] for s in sidecars) == pytest.approx(report.train_seconds)
    assert all(s["train_seconds"] > 0 and s["extra"]["curves"]["loss"] for s in sidecars)

    second = make_recognizer("bc", n_epochs=2)
    asked = []
    spy_on_jobs(second, asked, monkeypatch)
    monkeypatch.setattr(second, "train_policy", lambda *_: pytest.fail("a cached goal retrained"))
    again = second.fit(TRAIN, TASK.make_env, seed=5, cache_key=TASK.env_key)
    assert (again.trained, again.reused) == (0, len(TRAIN)) and asked == []
    assert again.train_seconds == pytest.approx(report.train_seconds)
    for p, q in zip(banked[0], banked[1]):
        assert all(torch.equal(v, q.state_dict()[k]) for k, v in p.state_dict().items())

    # One entry missing: only that goal trains, and to the same weights.
    victim = sorted((tmp_path / "policy-bc").glob("*.pt"))[0]
    victim.unlink()
    victim.with_suffix(".json").unlink()
    third = make_recognizer("bc", n_epochs=2)
    spy_on_jobs(third, asked, monkeypatch)
    assert third.fit(TRAIN, TASK.make_env, seed=5, cache_key=TASK.env_key).trained == 1
    assert len(asked) == 1 and len(asked[0]) == 1
    for p, q in zip(banked[0], banked[2]):
        assert all(torch.equal(v, q.state_dict()[k]) for k, v in p.state_dict().items())
