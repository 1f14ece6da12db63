"""GAIL and AIRL training: the suite's speed-ups change no trained weight, and their settings are checked."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.recognizers import adversarial, make_recognizer

TASK = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
TRAIN, _ = TASK.split(TASK.generate_demos(seed=0))


def fit(name: str) -> dict[str, torch.Tensor]:
    goal = TASK.goals[0]
    torch.manual_seed(3)
    return make_recognizer(name, total_timesteps=2048).train_policy(goal, TRAIN[goal], TASK.make_env, seed=3)[0].state_dict()


class PerStepRewards(adversarial._RolloutRewards):
    """imitation's own way: the learned reward of every step as it is taken."""

    def __call__(self, *transitions: np.ndarray) -> np.ndarray:
        return self.reward_fn(*transitions)

    def collect(self) -> np.ndarray:
        return np.float32(0.0)


@pytest.mark.parametrize("name", ["gail", "airl"])
def test_rollout_rewards_in_one_call_train_the_same_weights(name, monkeypatch):
    batched = fit(name)
    monkeypatch.setattr(adversarial, "_RolloutRewards", PerStepRewards)
    per_step = fit(name)
    for key in per_step:
        torch.testing.assert_close(batched[key], per_step[key], rtol=0, atol=0)


def test_update_is_validated():
    with pytest.raises(UserError, match="update expects one of 'numpy', 'torch', got 'jax'"):
        make_recognizer("gail", update="jax")


@pytest.mark.parametrize("name", ["gail", "airl"])
def test_continuous_generators_update_in_numpy_and_are_keyed_apart(name):
    """On continuous actions the generator's update runs in numpy too (SB3's once ran it); those generators carry
    it in their cache key, discrete ones and ``update=torch`` keep theirs."""
    from grail_bench.core.ppo_update import mirrorable

    maze = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    train, _ = maze.split(maze.generate_demos(seed=0))
    rec = make_recognizer(name, total_timesteps=1024)
    rec.learn_evidence(train, maze.env_factory())
    assert mirrorable(rec._generator(maze.goals[0], maze.env_factory(), 2))
    assert rec.model_key(maze.goals[0]) == {"update": "numpy"}
    policy, curves = rec.train_policy(maze.goals[0], train[maze.goals[0]], maze.make_env, seed=0)
    assert all(torch.isfinite(v).all() for v in policy.state_dict().values()) and curves
    torch_update = make_recognizer(name, update="torch")
    torch_update.learn_evidence(train, maze.env_factory())
    assert torch_update.model_key(maze.goals[0]) == {}
    discrete = make_recognizer(name)
    discrete.learn_evidence(TRAIN, TASK.env_factory())
    assert discrete.model_key(TASK.goals[0]) == {}
