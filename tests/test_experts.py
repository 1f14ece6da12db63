"""The RL experts' deterministic actor: SB3's ``predict`` bit for bit."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from grail_bench.core.experts import deterministic_actor
from grail_bench.core.rl import empty_policy


@pytest.mark.parametrize("low, high", [(-1.0, 1.0), (np.array([-2.0, 0.0, -0.5]), np.array([1.0, 3.0, 0.5]))])
def test_deterministic_actor_equals_predict_bit_for_bit(low, high):
    torch.manual_seed(0)
    obs_space = gym.spaces.Box(-10.0, 10.0, shape=(9,), dtype=np.float32)
    act_space = gym.spaces.Box(low, high, shape=(3,), dtype=np.float32)
    policy = empty_policy("sac", obs_space, act_space, [64, 64])
    with torch.no_grad():  # away from initialisation, so tanh saturates on some observations
        for p in policy.actor.parameters():
            p.mul_(4.0)
    policy.set_training_mode(False)
    act = deterministic_actor(policy)
    rng = np.random.default_rng(0)
    for obs in rng.uniform(-10, 10, size=(200, 9)).astype(np.float32):
        expected = policy.predict(obs, deterministic=True)[0]
        got = act(obs)
        assert got.dtype == expected.dtype and got.shape == expected.shape == (3,)
        assert np.array_equal(got, expected)
    obs64 = np.linspace(-1, 1, 9)  # float64 input is cast as predict casts it
    assert np.array_equal(act(obs64), policy.predict(obs64, deterministic=True)[0])
