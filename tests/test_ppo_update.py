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


def one_round(cls: type[PPO], **kwargs) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """Weights before and after one rollout of 8 x 64 steps and one update (10 epochs of 32-sample minibatches)."""
    venv = vec_env(lambda: TASK.make_env(TASK.goals[1]), 8, seed=0)
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
    assert expected.keys() == got.keys()
    for key, value in expected.items():
        torch.testing.assert_close(got[key], value, rtol=0, atol=1e-6)
    # The update moved the weights, so this compares two trained networks, not two untouched ones.
    assert max(float((expected[k] - before[k]).abs().max()) for k in before) > 1e-3


def test_what_numpy_cannot_mirror_runs_sb3_update():
    continuous = PPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64, batch_size=32, device="cpu")
    assert not mirrorable(continuous)
    clipped_values = NumpyPPO("MlpPolicy", vec_env(lambda: TASK.make_env(), 2), n_steps=64, batch_size=32,
                              clip_range_vf=0.2, device="cpu")
    assert not mirrorable(clipped_values)
    clipped_values.set_logger(Logger(folder=None, output_formats=[]))
    clipped_values.learn(128)  # trains through SB3's own update
