"""PPO's update in numpy: equal to SB3's ``train()`` to float32 rounding, and SB3's wherever it cannot mirror it."""

from __future__ import annotations

import gymnasium as gym
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from torch import nn

import grail_bench
from grail_bench.core.ppo_update import NumpyPPO, mirrorable
from grail_bench.core.rl import vec_env

TASK = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
MAZE = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")  # continuous: two action dimensions


def one_round(cls: type[PPO], task=TASK, **kwargs) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """Weights before and after one rollout of 8 x 64 steps and one update (10 epochs of 32-sample minibatches)."""
    venv = vec_env(lambda: task.make_env(task.goals[1]), 8, seed=0)
    model = cls("MlpPolicy", venv, batch_size=32, n_steps=64, seed=0, device="cpu", **kwargs)
    model.set_logger(Logger(folder=None, output_formats=[]))
    before = {k: v.clone() for k, v in model.policy.state_dict().items()}
    model.learn(512)
    return before, model.policy.state_dict()


@pytest.mark.parametrize("kwargs", [
    {"gamma": 0.95},
    {"ent_coef": 0.05, "policy_kwargs": {"activation_fn": nn.ReLU, "net_arch": [32]}},
    {"policy_kwargs": {"optimizer_kwargs": {"eps": 1e-8, "betas": (0.8, 0.99)}}},
], ids=["paper", "entropy-relu", "adam-settings"])
def test_numpy_update_equals_sb3_train(kwargs):
    before, expected = one_round(PPO, **kwargs)
    _, got = one_round(NumpyPPO, **kwargs)
    assert_same_update(before, expected, got)


@pytest.mark.parametrize("kwargs", [{}, {"ent_coef": 0.05, "policy_kwargs": {"log_std_init": -0.5}}],
                         ids=["default", "entropy-log-std"])
def test_numpy_update_equals_sb3_train_on_continuous_actions(kwargs):
    before, expected = one_round(PPO, MAZE, **kwargs)
    _, got = one_round(NumpyPPO, MAZE, gaussian=True, **kwargs)
    assert_same_update(before, expected, got)
    assert float((got["log_std"] - before["log_std"]).abs().max()) > 1e-4  # log_std is trained, not left alone


def assert_same_update(before: dict[str, torch.Tensor], expected: dict[str, torch.Tensor],
                       got: dict[str, torch.Tensor]) -> None:
    assert expected.keys() == got.keys()
    for key, value in expected.items():
        torch.testing.assert_close(got[key], value, rtol=0, atol=1e-6)
    # The update moved the weights, so this compares two trained networks, not two untouched ones.
    assert max(float((expected[k] - before[k]).abs().max()) for k in before) > 1e-3


def test_what_numpy_cannot_mirror_runs_sb3_update():
    continuous = PPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64, batch_size=32, device="cpu")
    assert not mirrorable(continuous)
    assert not mirrorable(NumpyPPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64, batch_size=32, device="cpu"))
    assert mirrorable(NumpyPPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64, batch_size=32, device="cpu",
                               gaussian=True))
    assert not mirrorable(NumpyPPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64, batch_size=32, device="cpu",
                                   gaussian=True, use_sde=True))
    clipped_values = NumpyPPO("MlpPolicy", vec_env(lambda: TASK.make_env(), 2), n_steps=64, batch_size=32,
                              clip_range_vf=0.2, device="cpu")
    assert not mirrorable(clipped_values)
    clipped_values.set_logger(Logger(folder=None, output_formats=[]))
    clipped_values.learn(128)  # trains through SB3's own update
