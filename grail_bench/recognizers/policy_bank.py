"""K goal policies evaluated in one batched numpy forward pass.

GRAIL scores an observation against every goal's policy. Calling K torch
modules costs far more in framework overhead than the arithmetic itself for
these small MLPs, so the actor weights of the K SB3 policies are stacked into
``(K, in, out)`` arrays once, and one ``matmul`` per layer serves all goals.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import FlattenExtractor
from torch import nn

_ACTIVATIONS = {nn.Tanh: np.tanh, nn.ReLU: lambda x: np.maximum(x, 0.0), nn.Identity: lambda x: x}


def preprocess(obs: np.ndarray, space: spaces.Space) -> np.ndarray:
    """Numpy twin of SB3's ``preprocess_obs`` for flat spaces.

    ``Discrete`` and ``MultiDiscrete`` observations become (concatenated)
    one-hot vectors; ``Box`` observations are flattened floats.
    """
    if isinstance(space, spaces.MultiDiscrete):
        offsets = np.concatenate([[0], np.cumsum(space.nvec)[:-1]])
        out = np.zeros((len(obs), int(space.nvec.sum())), dtype=np.float32)
        out[np.arange(len(obs))[:, None], obs.astype(np.int64) + offsets] = 1.0
        return out
    if isinstance(space, spaces.Discrete):
        out = np.zeros((len(obs), int(space.n)), dtype=np.float32)
        out[np.arange(len(obs)), obs.astype(np.int64).reshape(-1) - int(space.start)] = 1.0
        return out
    if isinstance(space, spaces.Box):
        return obs.reshape(len(obs), -1).astype(np.float32)
    raise TypeError(f"unsupported observation space {space}")


class PolicyBank:
    """The actors of K same-architecture SB3 ``ActorCriticPolicy`` objects, stacked.

    Args:
        policies: One trained policy per goal, all with the same architecture.
    """

    def __init__(self, policies: Sequence[ActorCriticPolicy]) -> None:
        if not policies:
            raise ValueError("a policy bank needs at least one policy")
        first = policies[0]
        if not isinstance(first.features_extractor, FlattenExtractor):
            raise TypeError("PolicyBank supports flat (FlattenExtractor) policies only")
        self.observation_space = first.observation_space
        self.action_space = first.action_space
        self.discrete = isinstance(self.action_space, spaces.Discrete)
        self.layers: list[tuple[np.ndarray, np.ndarray]] = []
        self.activations = []
        per_policy = [self._actor_layers(p) for p in policies]
        for depth, (linear, act) in enumerate(per_policy[0]):
            weights = np.stack([pl[depth][0].weight.detach().numpy().T for pl in per_policy]).astype(np.float32)
            biases = np.stack([pl[depth][0].bias.detach().numpy() for pl in per_policy])[:, None, :].astype(np.float32)
            self.layers.append((weights, biases))
            self.activations.append(act)
        self.log_std = (
            np.stack([p.log_std.detach().numpy() for p in policies]).astype(np.float32)
            if hasattr(first, "log_std") and not self.discrete else None
        )

    @staticmethod
    def _actor_layers(policy: ActorCriticPolicy) -> list[tuple[nn.Linear, object]]:
        modules = list(policy.mlp_extractor.policy_net) + [policy.action_net, nn.Identity()]
        layers, i = [], 0
        while i < len(modules) - 1:
            linear = modules[i]
            if not isinstance(linear, nn.Linear):
                raise TypeError(f"unsupported actor layer {linear!r}")
            nxt = modules[i + 1]
            if type(nxt) in _ACTIVATIONS and i + 1 < len(modules) - 1:
                layers.append((linear, _ACTIVATIONS[type(nxt)]))
                i += 2
            else:
                layers.append((linear, _ACTIVATIONS[nn.Identity]))
                i += 1
        return layers

    def __len__(self) -> int:
        return self.layers[0][0].shape[0]

    def forward(self, obs: np.ndarray) -> np.ndarray:
        """Action logits (discrete) or mean actions (continuous), ``(K, T, A)``."""
        x = preprocess(obs, self.observation_space)[None]
        for (weights, biases), activation in zip(self.layers, self.activations):
            x = activation(np.matmul(x, weights) + biases)
        return x

    def action_probs(self, obs: np.ndarray) -> np.ndarray:
        """Softmax action probabilities, ``(K, T, A)``; discrete actions only."""
        logits = self.forward(obs)
        logits -= logits.max(axis=-1, keepdims=True)
        e = np.exp(logits)
        return e / e.sum(axis=-1, keepdims=True)
