"""Behavioural cloning as imitation 1.0.1's ``bc.BC`` trains (the paper's BC-GRAIL), in torch and in numpy.

The loop: the batches in the order imitation's data loader draws them (the
same torch generator calls), its loss (negative log-likelihood of the
demonstrated action, minus ``ent_weight`` times the policy's entropy) and
torch's Adam with its settings, on its default policy (:func:`bc_policy`).
:func:`train_bc_torch` is that loop in torch, for any SB3 actor-critic
policy; it reproduces ``bc.BC``'s trained weights (tested against weights
imitation trained, recorded in ``tests/fixtures/bc``).

BC-GRAIL takes one Adam step per 8 demonstrated pairs (the paper's batch), so
a PandaReach goal with 150 demonstrations is ~100 000 steps, and torch spends
~1.5 ms on each (forward, backward and Adam on a ~2 500-weight network),
nearly all of it framework overhead. :func:`train_bc` runs the same loop on
one flat float32 vector and agrees with the torch loop to float32 rounding
(tested on discrete and continuous actions). :func:`mirrorable` says which
policies it can run; others go through the torch loop.

:func:`train_bc_stacked` trains several goals' policies of one architecture
together: one batched forward, backward and Adam step over the goals per
step, each goal on its own data and batch order (:func:`batch_order`, drawn
under its own seed). Each goal's weights and losses are bit for bit those
:func:`train_bc` gives it alone (tested).
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass
from typing import Hashable, Iterator, Sequence

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.distributions import CategoricalDistribution, DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import FlattenExtractor

from grail_bench.core.flat_mlp import Adam, FlatMLPs, StackedMLPs
from grail_bench.core.spaces import preprocess

_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)


def bc_policy(observation_space: spaces.Space, action_space: spaces.Space, learning_rate: float) -> ActorCriticPolicy:
    """imitation's default BC policy (its ``FeedForward32Policy``): SB3's actor-critic MLP with two hidden layers
    of 32 tanh units, built in the same order, so the same torch seed gives the same initial weights."""
    return ActorCriticPolicy(observation_space, action_space, lambda _: learning_rate, net_arch=[32, 32])


def mirrorable(policy: ActorCriticPolicy) -> bool:
    """Whether :func:`train_bc` can clone into ``policy``: a flat-input MLP with a categorical or Gaussian head."""
    if not isinstance(policy, ActorCriticPolicy):
        return False
    discrete = isinstance(policy.action_space, spaces.Discrete) and isinstance(policy.action_dist,
                                                                               CategoricalDistribution)
    gaussian = (isinstance(policy.action_space, spaces.Box) and type(policy.action_dist) is DiagGaussianDistribution
                and not policy.squash_output)
    obs = policy.observation_space
    flat_obs = isinstance(obs, (spaces.Discrete, spaces.MultiDiscrete)) or (
        isinstance(obs, spaces.Box) and not is_image_space(obs, check_channels=False))
    return ((discrete or gaussian) and flat_obs and isinstance(policy.features_extractor, FlattenExtractor)
            and FlatMLPs.mirrors([*policy.mlp_extractor.policy_net, policy.action_net]))


def batch_indices(n: int, batch_size: int, n_epochs: int | None, n_batches: int | None) -> Iterator[np.ndarray]:
    """The index batches imitation's ``bc.BC`` trains on, in its order.

    Its data loader (torch's, shuffled, incomplete last batch dropped) is
    iterated afresh every epoch. Each time it draws two seeds from torch's
    global generator, its iterator's base seed and then its sampler's, and the
    sampler permutes the indices with a generator seeded by the second; the
    same draws here leave the global generator where the loader leaves it.
    Exactly one of ``n_epochs`` and ``n_batches`` is given.
    """
    def batches() -> Iterator[np.ndarray]:
        for _ in itertools.count() if n_epochs is None else range(n_epochs):
            torch.empty((), dtype=torch.int64).random_()  # the loader iterator's base seed (unused here)
            seed = int(torch.empty((), dtype=torch.int64).random_().item())
            order = torch.randperm(n, generator=torch.Generator().manual_seed(seed)).numpy()
            for start in range(0, n - batch_size + 1, batch_size):
                yield order[start:start + batch_size]

    return itertools.islice(batches(), n_batches)


def train_bc(policy: ActorCriticPolicy, obs: np.ndarray, acts: np.ndarray, *, batch_size: int,
             learning_rate: float, ent_weight: float, n_epochs: int | None = None, n_batches: int | None = None,
             log_interval: int = 1) -> list[float]:
    """Clone ``(obs, acts)`` into ``policy`` (in place) as imitation's ``bc.BC`` would.

    Args:
        policy: A policy :func:`mirrorable` accepts; its weights are the starting point.
        obs: Demonstrated observations, ``(N, *observation_space.shape)``.
        acts: Demonstrated actions, ``(N, *action_space.shape)``.
        batch_size: Pairs per Adam step (at most ``N``).
        learning_rate: Adam's (imitation's other Adam settings are torch's defaults).
        ent_weight: Weight of the entropy bonus.
        n_epochs, n_batches: The budget: passes over the data, or steps (exactly one of them).
        log_interval: Record the loss of every ``log_interval``-th step, from the first.

    Returns:
        The recorded losses (each before its step).
    """
    if (n_epochs is None) == (n_batches is None):
        raise ValueError("train_bc needs exactly one of n_epochs and n_batches")
    x_all = preprocess(np.asarray(obs), policy.observation_space)
    gaussian = isinstance(policy.action_space, spaces.Box)
    acts = np.asarray(acts, dtype=np.float32 if gaussian else np.int64)
    acts = acts.reshape(len(acts), -1) if gaussian else acts.reshape(-1)
    net = FlatMLPs([[*policy.mlp_extractor.policy_net, policy.action_net]], extra=[policy.log_std] if gaussian else [])
    net.read()
    (layers,) = net.chains
    adam = Adam(net.flat.size)
    losses = []
    for step, idx in enumerate(batch_indices(len(x_all), batch_size, n_epochs, n_batches)):
        out, inputs = net.forward(layers, x_all[idx])
        loss, d_out = (_gaussian if gaussian else _categorical)(net, out, acts[idx], ent_weight)
        if step % log_interval == 0:
            losses.append(loss)
        net.backward(layers, inputs, d_out)
        adam.step(net.flat, net.grad, learning_rate)
    net.write_back()
    return losses


def batch_order(n: int, batch_size: int, n_epochs: int | None, n_batches: int | None) -> np.ndarray:
    """:func:`batch_indices` drawn all at once: ``(steps, batch_size)`` indices, the same draws from torch's
    global generator, which is left where training would leave it."""
    return np.array(list(batch_indices(n, batch_size, n_epochs, n_batches)), dtype=np.int64).reshape(-1, batch_size)


def stack_key(policy: ActorCriticPolicy) -> Hashable | None:
    """Policies with equal keys can train together in :func:`train_bc_stacked`; None for one it cannot train."""
    if not mirrorable(policy):
        return None
    chain = [*policy.mlp_extractor.policy_net, policy.action_net]
    return (type(policy.action_space).__name__, tuple(type(m).__name__ for m in chain),
            tuple(tuple(p.shape) for m in chain for p in m.parameters()),
            tuple(policy.log_std.shape) if isinstance(policy.action_space, spaces.Box) else None)


@dataclass(frozen=True)
class StackedRun:
    """What :func:`train_bc_stacked` reports per policy, in the order given.

    Attributes:
        losses: Each policy's recorded losses, as :func:`train_bc` returns them.
        seconds: Each policy's share of the wall time: every step's time split equally among the policies
            it stepped, the rest (reading, writing back, gathering data) equally among all.
    """

    losses: list[list[float]]
    seconds: list[float]


def train_bc_stacked(policies: Sequence[ActorCriticPolicy], data: Sequence[tuple[np.ndarray, np.ndarray]],
                     orders: Sequence[np.ndarray], *, learning_rate: float, ent_weight: float,
                     log_intervals: Sequence[int]) -> StackedRun:
    """Clone each ``data[i]`` into ``policies[i]`` (in place), all at once, as :func:`train_bc` would one by one.

    Args:
        policies: Policies with one :func:`stack_key`; their weights are the starting points.
        data: Per policy, its ``(obs, acts)`` as :func:`train_bc` takes them.
        orders: Per policy, its batches (:func:`batch_order`), all of one batch size; their counts may differ
            (a policy stops after its last batch).
        learning_rate, ent_weight: As :func:`train_bc`'s.
        log_intervals: Per policy, :func:`train_bc`'s ``log_interval``.
    """
    start = time.perf_counter()
    if not policies:
        return StackedRun([], [])
    keys = {stack_key(p) for p in policies}
    if None in keys or len(keys) != 1:
        raise ValueError("train_bc_stacked needs mirrorable policies of one architecture")
    if len({order.shape[1] for order in orders}) != 1:
        raise ValueError("train_bc_stacked needs one batch size")
    count = len(policies)
    # The goals by decreasing number of steps, so the ones still training are always the first k rows.
    rank = sorted(range(count), key=lambda i: -len(orders[i]))
    steps = np.array([len(orders[i]) for i in rank])
    gaussian = isinstance(policies[0].action_space, spaces.Box)
    xs = [preprocess(np.asarray(data[i][0]), policies[i].observation_space) for i in rank]
    acts = [np.asarray(data[i][1], dtype=np.float32 if gaussian else np.int64) for i in rank]
    acts = [a.reshape(len(a), -1) if gaussian else a.reshape(-1) for a in acts]
    x_all, a_all = np.concatenate(xs), np.concatenate(acts)
    offsets = np.cumsum([0] + [len(x) for x in xs[:-1]])
    # Every step's rows of x_all, per goal (a goal's rows past its last step are never read).
    rows = np.zeros((int(steps[0]), count, orders[0].shape[1]), dtype=np.int64)
    for j, i in enumerate(rank):
        rows[:steps[j], j] = orders[i] + offsets[j]
    net = StackedMLPs([[*policies[i].mlp_extractor.policy_net, policies[i].action_net] for i in rank],
                      [[policies[i].log_std] if gaussian else [] for i in rank])
    net.read()
    adam = Adam(net.flat.shape)
    losses = np.zeros(rows.shape[:2])
    seconds = np.zeros(count)
    loss_fn = _gaussian_stacked if gaussian else _categorical_stacked
    t = 0
    for k in range(count, 0, -1):  # phases: the first k goals step until the k-th one's batches run out
        if t >= steps[k - 1]:
            continue
        phase = time.perf_counter()
        flat, grad = net.flat[:k], net.grad[:k]
        for t in range(t, int(steps[k - 1])):
            idx = rows[t, :k]
            out, inputs = net.forward(x_all[idx], k)
            losses[t, :k], d_out = loss_fn(net, out, a_all[idx], ent_weight, k)
            net.backward(inputs, d_out, k)
            adam.step(flat, grad, learning_rate, rows=k)
        t += 1
        seconds[:k] += (time.perf_counter() - phase) / k
    net.write_back()
    seconds += (time.perf_counter() - start - seconds.sum()) / max(count, 1)
    by_goal_losses, by_goal_seconds = [[]] * count, [0.0] * count
    for j, i in enumerate(rank):
        by_goal_losses[i] = losses[:steps[j]:log_intervals[i], j].tolist()
        by_goal_seconds[i] = float(seconds[j])
    return StackedRun(by_goal_losses, by_goal_seconds)


def train_bc_torch(policy: ActorCriticPolicy, obs: np.ndarray, acts: np.ndarray, *, batch_size: int,
                   learning_rate: float, ent_weight: float, n_epochs: int | None = None, n_batches: int | None = None,
                   log_interval: int = 1) -> list[float]:
    """:func:`train_bc`'s loop in torch, for any SB3 actor-critic ``policy`` (arguments and result as there)."""
    if (n_epochs is None) == (n_batches is None):
        raise ValueError("train_bc needs exactly one of n_epochs and n_batches")
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    losses = []
    for step, idx in enumerate(batch_indices(len(obs), batch_size, n_epochs, n_batches)):
        _, log_prob, entropy = policy.evaluate_actions(torch.as_tensor(obs[idx]), torch.as_tensor(acts[idx]))
        loss = -log_prob.mean() - ent_weight * (entropy.mean() if entropy is not None else 0.0)
        if step % log_interval == 0:
            losses.append(float(loss.item()))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return losses


def _categorical(net: FlatMLPs, logits: np.ndarray, acts: np.ndarray, ent_weight: float) -> tuple[float, np.ndarray]:
    """Loss and its gradient by the logits: ``-mean(log p(a)) - ent_weight * mean(H)``."""
    batch, rows = len(acts), np.arange(len(acts))
    shifted = logits - logits.max(axis=1, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
    probs = np.exp(log_probs)
    entropy = -(probs * log_probs).sum(axis=1)
    d_logits = probs.copy()
    d_logits[rows, acts] -= 1.0
    d_logits += ent_weight * probs * (log_probs + entropy[:, None])  # dH/dlogits = -p (log p + H)
    d_logits /= batch
    return float(-log_probs[rows, acts].sum() - ent_weight * entropy.sum()) / batch, d_logits


def _gaussian(net: FlatMLPs, mean: np.ndarray, acts: np.ndarray, ent_weight: float) -> tuple[float, np.ndarray]:
    """As :func:`_categorical` for SB3's diagonal Gaussian (one state-independent ``log_std``); its gradient by
    ``log_std`` goes into the flat gradient."""
    (log_std,), (d_log_std,) = net.extra, net.extra_grad
    batch, dims = acts.shape
    std = np.exp(log_std)
    z = (acts - mean) / std
    squares = z * z
    d_log_std[:] = 1.0 - ent_weight - squares.sum(axis=0) / batch
    sum_log_std = float(log_std.sum())
    neg_log_prob = 0.5 * float(squares.sum()) / batch + sum_log_std + dims * _HALF_LOG_2PI
    entropy = dims * (0.5 + _HALF_LOG_2PI) + sum_log_std
    return neg_log_prob - ent_weight * entropy, (-z / std) / batch


def _categorical_stacked(net: StackedMLPs, logits: np.ndarray, acts: np.ndarray, ent_weight: float,
                         k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_categorical` on ``k`` batches at once (``(k, batch, actions)``): the losses ``(k,)`` and gradient,
    with the same arithmetic per batch."""
    batch = acts.shape[1]
    picks = (np.arange(k)[:, None], np.arange(batch), acts)
    shifted = logits - logits.max(axis=2, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=2, keepdims=True))
    probs = np.exp(log_probs)
    entropy = -(probs * log_probs).sum(axis=2)
    d_logits = probs.copy()
    d_logits[picks] -= 1.0
    d_logits += ent_weight * probs * (log_probs + entropy[:, :, None])
    d_logits /= batch
    # Per goal a float32 sum, then a Python float divided by the batch, as _categorical does.
    return (-log_probs[picks].sum(axis=1) - ent_weight * entropy.sum(axis=1)).astype(np.float64) / batch, d_logits


def _gaussian_stacked(net: StackedMLPs, mean: np.ndarray, acts: np.ndarray, ent_weight: float,
                      k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_gaussian` on ``k`` batches at once, as :func:`_categorical_stacked`."""
    log_std, d_log_std = net.extra[0][:k], net.extra_grad[0][:k]
    _, batch, dims = acts.shape
    std = np.exp(log_std)[:, None, :]
    z = (acts - mean) / std
    squares = z * z
    d_log_std[:] = 1.0 - ent_weight - squares.sum(axis=1) / batch
    sum_log_std = log_std.sum(axis=1).astype(np.float64)
    neg_log_prob = 0.5 * squares.reshape(k, -1).sum(axis=1).astype(np.float64) / batch + sum_log_std \
        + dims * _HALF_LOG_2PI
    entropy = dims * (0.5 + _HALF_LOG_2PI) + sum_log_std
    return neg_log_prob - ent_weight * entropy, (-z / std) / batch
