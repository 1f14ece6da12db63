"""BC's loops: the torch loop trains what imitation 1.0.1's ``bc.BC`` trained (weights it recorded), and the numpy
loop equals the torch loop to float32 rounding; the torch loop runs what numpy cannot mirror."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.policies import ActorCriticPolicy

from grail_bench.core import bc_update
from grail_bench.recognizers.bc import train_bc

FIXTURES = Path(__file__).parent / "fixtures" / "bc"
SPACES = {
    "minigrid": (gym.spaces.MultiDiscrete([9, 9, 4]), gym.spaces.Discrete(4)),
    "reaching": (gym.spaces.Box(-10, 10, (6,), np.float32), gym.spaces.Box(-1, 1, (3,), np.float32)),
}
BUDGETS = {"epochs": {"n_epochs": 6}, "batches": {"n_batches": 130}}


def pairs(kind: str, n: int = 203) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random (observation, action) pairs (203: the loader drops an incomplete last batch of 8)."""
    obs_space, act_space = SPACES[kind]
    obs_space.seed(1), act_space.seed(2)
    obs = (np.random.default_rng(0).normal(size=(n, *obs_space.shape)).astype(np.float32) if kind == "reaching"
           else np.stack([obs_space.sample() for _ in range(n)]))
    return obs, np.stack([act_space.sample() for _ in range(n)])


def policy(kind: str, **kwargs) -> ActorCriticPolicy:
    torch.manual_seed(3)
    obs_space, act_space = SPACES[kind]
    if kwargs:
        return ActorCriticPolicy(obs_space, act_space, lambda _: 1e-3, **kwargs)
    return bc_update.bc_policy(obs_space, act_space, 1e-3)


def train(loop, kind: str, budget: str) -> tuple[ActorCriticPolicy, list[float], torch.Tensor]:
    """A fresh policy trained by ``loop``, its losses, and the next draws of torch's global generator."""
    pol = policy(kind)
    losses = loop(pol, *pairs(kind), batch_size=8, learning_rate=1e-3, ent_weight=1e-2, log_interval=5,
                  **BUDGETS[budget])
    return pol, losses, torch.rand(3)


@pytest.mark.parametrize("kind", SPACES)
@pytest.mark.parametrize("budget", BUDGETS)
def test_torch_loop_trains_what_imitation_trained(kind, budget):
    recorded = np.load(FIXTURES / f"{kind}-{budget}.npz")
    untrained = policy(kind).state_dict()
    got, losses, next_draws = train(bc_update.train_bc_torch, kind, budget)
    np.testing.assert_array_equal(next_draws.numpy(), recorded["next_draws"])  # later fits are seeded alike
    np.testing.assert_allclose(losses, recorded["losses"], rtol=1e-6)
    for key, value in got.state_dict().items():
        np.testing.assert_allclose(value.numpy(), recorded[f"weight/{key}"], rtol=0, atol=1e-6)
    # Training moved the actor's weights, so this compares two trained networks, not two untouched ones.
    assert max(float(np.abs(recorded[f"weight/{k}"] - untrained[k].numpy()).max())
               for k in untrained if "action_net" in k) > 1e-2


@pytest.mark.parametrize("kind", SPACES)
@pytest.mark.parametrize("budget", BUDGETS)
def test_numpy_loop_equals_torch_loop(kind, budget):
    expected, expected_losses, expected_next = train(bc_update.train_bc_torch, kind, budget)
    assert bc_update.mirrorable(policy(kind))
    got, got_losses, got_next = train(bc_update.train_bc, kind, budget)
    torch.testing.assert_close(got_next, expected_next, rtol=0, atol=0)
    np.testing.assert_allclose(got_losses, expected_losses, rtol=1e-5)
    for key, value in expected.state_dict().items():
        torch.testing.assert_close(got.state_dict()[key], value, rtol=0, atol=1e-5)


def test_what_numpy_cannot_mirror_runs_the_torch_loop():
    obs, acts = pairs("reaching")
    state_dependent_noise = policy("reaching", use_sde=True)
    assert not bc_update.mirrorable(state_dependent_noise)
    image = ActorCriticPolicy(gym.spaces.Box(0, 255, (8, 8, 3), np.uint8), gym.spaces.Discrete(2), lambda _: 1e-3)
    assert not bc_update.mirrorable(image)
    before = {k: v.clone() for k, v in state_dependent_noise.state_dict().items()}
    trained, curves = train_bc(state_dependent_noise, obs, acts, batch_size=8, learning_rate=1e-3, ent_weight=1e-3,
                               n_epochs=2)
    assert len(curves["loss"]) == 2  # one point per epoch
    assert any(not torch.equal(before[k], v) for k, v in trained.state_dict().items())


@pytest.mark.parametrize("loop", [bc_update.train_bc, bc_update.train_bc_torch])
def test_budget_is_exactly_one_of_epochs_and_batches(loop):
    obs, acts = pairs("minigrid")
    with pytest.raises(ValueError, match="exactly one"):
        loop(policy("minigrid"), obs, acts, batch_size=8, learning_rate=1e-3, ent_weight=0.0)
