"""K goal policies evaluated in one batched numpy forward pass.

GRAIL scores an observation against every goal's policy. Calling K torch
modules costs far more in framework overhead than the arithmetic itself for
these small MLPs, so the actor weights of the K SB3 policies are stacked into
``(K, in, out)`` arrays once, and one ``matmul`` per layer serves all goals.
For discrete observations (one-hot encoded by SB3) the first layer is a
lookup: the product of a one-hot vector with the weights is the sum of the
weight rows it selects, so those rows are gathered instead of multiplying by
the mostly-zero one-hot matrix (equal up to float rounding). And when a
discrete observation space is small (MiniGrid's room has 324 states), the
outputs on every state are computed once, on first use, and scoring looks them
up: the same forward pass, paid once per fit instead of once per observation.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.sac.policies import SACPolicy
from torch import nn

from grail_bench.core.spaces import all_states, n_states, preprocess, state_index

#: Discrete observation spaces with at most this many states get a table of the outputs on every state.
TABLE_STATES = 4096

_ACTIVATIONS = {nn.Tanh: np.tanh, nn.ReLU: lambda x: np.maximum(x, 0.0), nn.Identity: lambda x: x}


def _one_hot_offsets(space: spaces.Space) -> np.ndarray | None:
    """Where each component's one-hot block starts, for discrete observation spaces (None for others)."""
    if isinstance(space, spaces.MultiDiscrete):
        return np.concatenate([[0], np.cumsum(space.nvec)[:-1]]).astype(np.int64)
    if isinstance(space, spaces.Discrete):
        return np.array([-int(space.start)], dtype=np.int64)
    return None


def _state_index(space: spaces.Space) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]] | None:
    """Every state of a small discrete space and the map from states to their rows (else None)."""
    discrete = isinstance(space, spaces.Discrete) or (isinstance(space, spaces.MultiDiscrete) and space.nvec.ndim == 1)
    if not discrete or n_states(space) > TABLE_STATES:
        return None
    return all_states(space), lambda obs: state_index(obs, space)


def _stack(modules_per_policy: list[list[nn.Module]]) -> list[tuple[np.ndarray, np.ndarray, Callable]]:
    """Stack ``Linear`` (+ activation) sequences of K policies into ``(K, in, out)`` weights."""
    layers = []
    first = modules_per_policy[0]
    i = 0
    while i < len(first):
        if not isinstance(first[i], nn.Linear):
            raise TypeError(f"unsupported actor layer {first[i]!r}")
        act = _ACTIVATIONS.get(type(first[i + 1])) if i + 1 < len(first) else None
        weights = np.stack([m[i].weight.detach().numpy().T for m in modules_per_policy]).astype(np.float32)
        biases = np.stack([m[i].bias.detach().numpy() for m in modules_per_policy])[:, None, :].astype(np.float32)
        layers.append((weights, biases, act or _ACTIVATIONS[nn.Identity]))
        i += 2 if act else 1
    return layers


def _apply(x: np.ndarray, layers: list[tuple[np.ndarray, np.ndarray, Callable]]) -> np.ndarray:
    for weights, biases, activation in layers:
        x = activation(np.matmul(x, weights) + biases)
    return x


class PolicyBank:
    """The actors of K same-architecture SB3 policies, stacked.

    Supports ``ActorCriticPolicy`` (PPO, BC, GAIL, AIRL generators: a trunk, an
    action head, a state-independent log-std for continuous actions) and SAC
    policies (a trunk, a mean head, a state-dependent log-std head, tanh
    squashing).

    Args:
        policies: One trained policy per goal, all with the same architecture.
    """

    def __init__(self, policies: Sequence[BasePolicy]) -> None:
        if not policies:
            raise ValueError("a policy bank needs at least one policy")
        first = policies[0]
        self.observation_space = first.observation_space
        self.action_space = first.action_space
        self.discrete = isinstance(self.action_space, spaces.Discrete)
        self.squash = isinstance(first, SACPolicy)
        if self.squash:
            actors = [p.actor for p in policies]
            extractor = first.actor.features_extractor
            self.trunk = _stack([list(a.latent_pi) for a in actors])
            self.head = _stack([[a.mu] for a in actors])
            self.log_std_head = _stack([[a.log_std] for a in actors])
            self.log_std = None
        elif isinstance(first, ActorCriticPolicy):
            extractor = first.features_extractor
            self.trunk = _stack([list(p.mlp_extractor.policy_net) for p in policies])
            self.head = _stack([[p.action_net] for p in policies])
            self.log_std_head = None
            self.log_std = (np.stack([p.log_std.detach().numpy() for p in policies]).astype(np.float32)
                            if not self.discrete else None)
        else:
            raise TypeError(f"unsupported policy type {type(first).__name__}")
        if not isinstance(extractor, FlattenExtractor):
            raise TypeError("PolicyBank supports flat (FlattenExtractor) policies only")

        self._offsets = _one_hot_offsets(self.observation_space)
        if self._offsets is not None and self.trunk:
            weights, biases, activation = self.trunk[0]
            self._rows = np.ascontiguousarray(weights.transpose(1, 0, 2))  # (in, K, out): one row per code
            self._first = (biases, activation)
        self._index = _state_index(self.observation_space)
        self._tables: dict[str, np.ndarray | tuple[np.ndarray, ...]] = {}

    @property
    def tabled(self) -> bool:
        """Whether the observation space is small enough for the outputs to be tabled over every state."""
        return self._index is not None

    def lookup(self, name: str, compute: Callable[[np.ndarray], Any], obs: np.ndarray) -> Any:
        """``compute(obs)``, looked up in a table of ``compute`` on every state (built at first use under
        ``name``) when the space is small (:attr:`tabled`); ``compute`` maps ``(N, ...)`` states to arrays, or
        tuples of arrays, of ``(K, N, ...)``."""
        if self._index is None:
            return compute(obs)
        states, rows_of = self._index
        if name not in self._tables:
            self._tables[name] = compute(states)
        table, rows = self._tables[name], rows_of(obs)
        return tuple(t[:, rows] for t in table) if isinstance(table, tuple) else table[:, rows]

    def __len__(self) -> int:
        return self.head[0][0].shape[0]

    def _latent(self, obs: np.ndarray) -> np.ndarray:
        if self._offsets is None or not self.trunk:
            return _apply(preprocess(obs, self.observation_space)[None], self.trunk)
        codes = np.asarray(obs, dtype=np.int64).reshape(len(obs), -1) + self._offsets  # (T, D)
        summed = self._rows[codes].sum(axis=1)  # (T, K, out): the rows the one-hot vector selects, summed
        biases, activation = self._first
        return _apply(activation(summed.transpose(1, 0, 2) + biases), self.trunk[1:])

    def forward(self, obs: np.ndarray) -> np.ndarray:
        """Action logits (discrete) or deterministic actions (continuous), ``(K, T, A)``."""
        return self.lookup("forward", self._forward, obs)

    def _forward(self, obs: np.ndarray) -> np.ndarray:
        out = _apply(self._latent(obs), self.head)
        return np.tanh(out) if self.squash else out

    def action_probs(self, obs: np.ndarray) -> np.ndarray:
        """Softmax action probabilities, ``(K, T, A)``; discrete actions only."""
        return self.lookup("probs", lambda x: _softmax(self._forward(x)), obs)

    def mean_std(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean action and its standard deviation per dimension, ``(K, T, D)`` each.

        For squashed (SAC) policies the mean is ``tanh(mu)`` and the std is
        carried through the tanh to first order: ``(1 - tanh(mu)^2) * std``.
        """
        return self.lookup("mean_std", lambda x: self._mean_std(self._latent(x)), obs)

    def outputs_of(self, inputs: np.ndarray) -> tuple[np.ndarray, ...]:
        """The policies on already encoded inputs ``(K or 1, T, F)``: ``(probs,)`` for discrete actions, else
        ``(mean, std)`` (a goal-conditioned policy is one policy fed each goal's inputs)."""
        latent = _apply(inputs, self.trunk)
        if self.discrete:
            return (_softmax(_apply(latent, self.head)),)
        return self._mean_std(latent)

    def _mean_std(self, latent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mu = _apply(latent, self.head)
        if self.log_std_head is not None:
            std = np.exp(np.clip(_apply(latent, self.log_std_head), -20.0, 2.0))  # SB3's clamp
        else:
            std = np.broadcast_to(np.exp(self.log_std)[:, None, :], mu.shape)
        if self.squash:
            mean = np.tanh(mu)
            return mean, (1.0 - mean * mean) * std
        return mu, std


def _softmax(logits: np.ndarray) -> np.ndarray:
    e = np.exp(logits - logits.max(axis=-1, keepdims=True))
    return e / e.sum(axis=-1, keepdims=True)
