"""BC's loop in numpy: equal to imitation's ``bc.BC`` to float32 rounding; imitation's where it cannot mirror."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch
from imitation.algorithms import bc
from imitation.data.types import Transitions
from imitation.policies.base import FeedForward32Policy
from stable_baselines3.common.policies import ActorCriticPolicy

from grail_bench.core import bc_update
from grail_bench.core.torchutil import recording_logger
from grail_bench.recognizers.bc import train_bc

SPACES = {
    "minigrid": (gym.spaces.MultiDiscrete([9, 9, 4]), gym.spaces.Discrete(4)),
    "reaching": (gym.spaces.Box(-10, 10, (6,), np.float32), gym.spaces.Box(-1, 1, (3,), np.float32)),
}


def transitions(kind: str, n: int = 203) -> Transitions:
    """``n`` random pairs (203: the loader drops an incomplete last batch of 8)."""
    obs_space, act_space = SPACES[kind]
    obs_space.seed(1), act_space.seed(2)
    obs = (np.random.default_rng(0).normal(size=(n, *obs_space.shape)).astype(np.float32) if kind == "reaching"
           else np.stack([obs_space.sample() for _ in range(n)]))
    acts = np.stack([act_space.sample() for _ in range(n)])
    return Transitions(obs=obs, acts=acts, infos=np.array([{}] * n), next_obs=obs, dones=np.zeros(n, bool))


def policy(kind: str, **kwargs) -> ActorCriticPolicy:
    torch.manual_seed(3)
    obs_space, act_space = SPACES[kind]
    if kwargs:
        return ActorCriticPolicy(obs_space, act_space, lambda _: 1e-3, **kwargs)
    return FeedForward32Policy(observation_space=obs_space, action_space=act_space, lr_schedule=lambda _: 1e-3)


def imitation_bc(pol: ActorCriticPolicy, data: Transitions, **budget) -> list[float]:
    """imitation's own loop, as grail-bench ran it before (one loss logged per 5 steps)."""
    logger, logged = recording_logger()
    trainer = bc.BC(observation_space=pol.observation_space, action_space=pol.action_space, demonstrations=data,
                    rng=np.random.default_rng(0), policy=pol, batch_size=8, optimizer_kwargs={"lr": 1e-3},
                    ent_weight=1e-2, device="cpu", custom_logger=logger)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        trainer.train(progress_bar=False, log_interval=5, **budget)
    return logged["bc/loss"]


@pytest.mark.parametrize("kind", SPACES)
@pytest.mark.parametrize("budget", [{"n_epochs": 6}, {"n_batches": 130}], ids=["epochs", "batches"])
def test_numpy_loop_equals_imitation_bc(kind, budget):
    data = transitions(kind)
    expected_policy, got_policy = policy(kind), policy(kind)
    before = {k: v.clone() for k, v in expected_policy.state_dict().items()}
    expected_losses = imitation_bc(expected_policy, data, **budget)
    expected_next = torch.rand(3)  # the global generator after training: later fits are seeded alike
    torch.manual_seed(3), policy(kind)  # the same generator state as before the first fit
    assert bc_update.mirrorable(got_policy)
    got_losses = bc_update.train_bc(got_policy, data.obs, data.acts, batch_size=8, learning_rate=1e-3,
                                    ent_weight=1e-2, log_interval=5, **budget)
    torch.testing.assert_close(torch.rand(3), expected_next, rtol=0, atol=0)
    np.testing.assert_allclose(got_losses, expected_losses, rtol=1e-5)
    expected, got = expected_policy.state_dict(), got_policy.state_dict()
    for key, value in expected.items():
        torch.testing.assert_close(got[key], value, rtol=0, atol=1e-5)
    # Training moved the actor's weights, so this compares two trained networks, not two untouched ones.
    assert max(float((expected[k] - before[k]).abs().max()) for k in before if "action_net" in k) > 1e-2


def test_what_numpy_cannot_mirror_runs_imitation_loop():
    data = transitions("reaching")
    state_dependent_noise = policy("reaching", use_sde=True)
    assert not bc_update.mirrorable(state_dependent_noise)
    image = ActorCriticPolicy(gym.spaces.Box(0, 255, (8, 8, 3), np.uint8), gym.spaces.Discrete(2), lambda _: 1e-3)
    assert not bc_update.mirrorable(image)
    before = {k: v.clone() for k, v in state_dependent_noise.state_dict().items()}
    trained, curves = train_bc(state_dependent_noise, data, seed=0, batch_size=8, learning_rate=1e-3,
                               ent_weight=1e-3, n_epochs=2)
    assert len(curves["loss"]) == 2  # one point per epoch, from imitation's logger
    assert any(not torch.equal(before[k], v) for k, v in trained.state_dict().items())


def test_budget_is_exactly_one_of_epochs_and_batches():
    data = transitions("minigrid")
    with pytest.raises(ValueError, match="exactly one"):
        bc_update.train_bc(policy("minigrid"), data.obs, data.acts, batch_size=8, learning_rate=1e-3,
                           ent_weight=0.0)
