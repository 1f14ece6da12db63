"""The vectorised MiniGrid env: the same transitions as copies of the single env, and the same trained models."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv

import grail_bench
from grail_bench.core.rl import vec_env
from grail_bench.domains.minigrid.env import GRMiniGridEnv
from grail_bench.domains.minigrid.vector import MiniGridVecEnv
from grail_bench.recognizers import make_recognizer


@pytest.mark.parametrize("fixed_horizon", [True, False])
def test_steps_equal_the_single_env_copies(fixed_horizon):
    n, kwargs = 6, {"goal": (3, 2), "max_steps": 15, "fixed_horizon": fixed_horizon}
    vector = MiniGridVecEnv(GRMiniGridEnv(**kwargs), n)
    single = DummyVecEnv([lambda: GRMiniGridEnv(**kwargs) for _ in range(n)])
    np.testing.assert_array_equal(vector.reset(), single.reset())
    rng = np.random.default_rng(0)
    reached = 0
    for _ in range(400):
        actions = rng.choice(4, size=n, p=[0.2, 0.2, 0.5, 0.1])  # forward-heavy, so goals get reached
        got, want = vector.step(actions), single.step(actions)
        for a, b in zip(got[:3], want[:3]):
            np.testing.assert_array_equal(a, b)
        assert got[1].dtype == want[1].dtype and got[0].dtype == want[0].dtype
        for info, expected in zip(got[3], want[3]):
            assert info.keys() == expected.keys()
            for key, value in expected.items():
                np.testing.assert_array_equal(info[key], value)
        reached += int((got[1] > 0).sum())
    assert reached > 10  # the comparison covered rewards, absorption and resets, not only wandering


def test_vec_env_uses_the_vectorised_twin_only_for_unwrapped_minigrid_envs():
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    assert isinstance(vec_env(lambda: task.make_env(), 4).venv, MiniGridVecEnv)
    from gymnasium.wrappers import TimeLimit

    wrapped = vec_env(lambda: TimeLimit(task.make_env(), 5), 4).venv
    assert isinstance(wrapped, DummyVecEnv) and wrapped.num_envs == 4


def test_invalid_actions_are_rejected():
    vector = MiniGridVecEnv(GRMiniGridEnv((3, 2)), 2)
    vector.reset()
    with pytest.raises(ValueError, match="invalid actions"):
        vector.step(np.array([0, 4]))


@pytest.mark.parametrize("name", ["gail", "airl"])
def test_adversarial_fit_is_identical_with_the_vectorised_env(name, monkeypatch):
    """Same seed, same generator weights whether rollouts come from the vectorised env or env copies."""
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    train, _ = task.split(task.generate_demos(seed=0))
    goal = task.goals[0]

    def fit() -> dict[str, torch.Tensor]:
        torch.manual_seed(3)
        rec = make_recognizer(name, total_timesteps=1024)
        return rec.train_policy(goal, train[goal], task.make_env, seed=3)[0].state_dict()

    vectorised = fit()
    monkeypatch.setattr(GRMiniGridEnv, "vector_copies", None)
    copies = fit()
    assert vectorised.keys() == copies.keys()
    for key in copies:
        torch.testing.assert_close(vectorised[key], copies[key], rtol=0, atol=0)
