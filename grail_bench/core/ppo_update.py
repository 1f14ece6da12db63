"""SB3's PPO update in numpy, for the small discrete-action MLP policies the suite trains.

A PPO round of the adversarial generators is 10 epochs of 32-sample
minibatches: 160 forward/backward passes, gradient clippings and Adam steps on
a network of about 12 000 weights. In torch each pass costs ~1.3 ms, nearly
all of it framework overhead per operation (the arithmetic is a few
microseconds), and these updates were two thirds of a GAIL or AIRL fit.
:class:`NumpyPPO` keeps SB3's ``PPO`` whole (rollouts, advantages, buffer,
minibatch order, schedules) and replaces only :meth:`PPO.train` by the same
update written out in numpy on one flat parameter vector: the clipped
surrogate with per-minibatch advantage normalisation, the value and entropy
terms, the global gradient-norm clip and Adam with the policy optimizer's
own settings. It agrees with SB3's ``train()`` to float32 rounding (tested on
a full round); policies it cannot mirror (continuous actions, custom
networks or extractors, value clipping, a KL target, SDE) fall back to SB3's.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import FlattenExtractor
from torch import nn

from grail_bench.core.spaces import preprocess

_ACTIVATIONS = {nn.Tanh: (np.tanh, lambda y: 1.0 - y * y), nn.ReLU: (lambda x: np.maximum(x, 0.0), lambda y: y > 0)}


class _FlatMLPs:
    """The actor and critic of an ``ActorCriticPolicy`` as views into one flat float32 vector (and its grads)."""

    def __init__(self, policy: ActorCriticPolicy) -> None:
        actor = [*policy.mlp_extractor.policy_net, policy.action_net]
        critic = [*policy.mlp_extractor.value_net, policy.value_net]
        self.params = [p for m in actor + critic for p in m.parameters()]
        sizes = [p.numel() for p in self.params]
        self.flat = np.zeros(sum(sizes), dtype=np.float32)
        self.grad = np.zeros_like(self.flat)
        views, grads, start = [], [], 0
        for p, n in zip(self.params, sizes):
            # torch's Linear stores (out, in); keep that layout so the flat vector matches the state_dict.
            views.append(self.flat[start:start + n].reshape(p.shape))
            grads.append(self.grad[start:start + n].reshape(p.shape))
            start += n
        pairs = iter(zip(views, grads))
        self.actor, self.critic = self._layers(actor, pairs), self._layers(critic, pairs)

    @staticmethod
    def _layers(modules: list[nn.Module], pairs: Any) -> list[tuple]:
        """``(weight, bias, weight grad, bias grad, activation or None)`` per Linear."""
        layers = []
        for i, module in enumerate(modules):
            if isinstance(module, nn.Linear):
                (w, gw), (b, gb) = next(pairs), next(pairs)
                follower = modules[i + 1] if i + 1 < len(modules) else None
                layers.append((w, b, gw, gb, _ACTIVATIONS.get(type(follower))))
        return layers

    @staticmethod
    def forward(layers: list[tuple], x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Output and every layer's input."""
        inputs = []
        for w, b, _, _, act in layers:
            inputs.append(x)
            x = x @ w.T + b
            if act is not None:
                x = act[0](x)
        return x, inputs

    @staticmethod
    def backward(layers: list[tuple], inputs: list[np.ndarray], grad_out: np.ndarray) -> None:
        """Write the gradients of ``sum(grad_out * output)`` into the flat gradient."""
        for (w, _, gw, gb, act), x, nxt in zip(reversed(layers), reversed(inputs), reversed(inputs[1:] + [None])):
            if act is not None:  # this layer's activated output is the next layer's input
                grad_out = grad_out * act[1](nxt)
            np.matmul(grad_out.T, x, out=gw)
            np.sum(grad_out, axis=0, out=gb)
            grad_out = grad_out @ w

    def read(self) -> None:
        """Copy the torch policy's parameters into the flat vector (in place: the views stay valid)."""
        self.flat[:] = np.concatenate([p.detach().numpy().reshape(-1) for p in self.params])

    def write_back(self) -> None:
        """Copy the flat parameters into the torch policy."""
        start = 0
        with torch.no_grad():
            for p in self.params:
                n = p.numel()
                p.copy_(torch.from_numpy(self.flat[start:start + n].reshape(p.shape)))
                start += n


def mirrorable(model: PPO) -> bool:
    """Whether :class:`NumpyPPO` can run ``model``'s update in numpy (else it uses SB3's)."""
    policy = model.policy
    if not (isinstance(policy, ActorCriticPolicy) and isinstance(model.action_space, spaces.Discrete)):
        return False
    group = policy.optimizer.param_groups[0]
    layers = [*policy.mlp_extractor.policy_net, *policy.mlp_extractor.value_net]
    flat_space = isinstance(model.observation_space, (spaces.Box, spaces.Discrete, spaces.MultiDiscrete))
    return (flat_space and isinstance(policy.features_extractor, FlattenExtractor) and policy.share_features_extractor
            and not model.use_sde and model.clip_range_vf is None and model.target_kl is None
            and model.normalize_advantage and type(policy.optimizer) is torch.optim.Adam
            and not (group.get("amsgrad") or group.get("maximize") or group.get("weight_decay"))
            and all(isinstance(m, (nn.Linear, *_ACTIVATIONS)) for m in layers))


class NumpyPPO(PPO):
    """SB3's PPO whose update (:meth:`train`) runs in numpy when the policy allows (:func:`mirrorable`)."""

    _mlps: _FlatMLPs | None = None
    _adam: tuple[np.ndarray, np.ndarray] | None = None
    _adam_steps: int = 0

    def train(self) -> None:
        if not mirrorable(self):
            super().train()
            return
        if self._mlps is None:
            self._mlps = _FlatMLPs(self.policy)
            self._adam = (np.zeros_like(self._mlps.flat), np.zeros_like(self._mlps.flat))
        self._mlps.read()
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)  # as SB3 does: logs it and keeps the optimizer in step
        group = self.policy.optimizer.param_groups[0]
        lr, (beta1, beta2), eps = float(group["lr"]), group["betas"], float(group["eps"])
        clip_range = float(self.clip_range(self._current_progress_remaining))
        mlps, (m, v), buffer = self._mlps, self._adam, self.rollout_buffer

        def flat(name: str) -> np.ndarray:  # SB3's swap_and_flatten, read without changing the buffer
            arr = getattr(buffer, name)
            return arr.swapaxes(0, 1).reshape(arr.shape[0] * arr.shape[1], *arr.shape[2:])

        n = buffer.buffer_size * buffer.n_envs
        features = preprocess(flat("observations"), self.observation_space)
        actions = flat("actions").reshape(n).astype(np.int64)
        old_log_prob, advantages, returns = flat("log_probs"), flat("advantages"), flat("returns")
        for _ in range(self.n_epochs):
            indices = np.random.permutation(n)  # SB3's draw per epoch, so minibatches are SB3's
            for start in range(0, n, self.batch_size):
                idx = indices[start:start + self.batch_size]
                self._minibatch(features[idx], actions[idx], old_log_prob[idx], advantages[idx], returns[idx],
                                clip_range)
                # The global-norm clip, then Adam (torch's update rule, bias-corrected).
                norm = float(np.sqrt(np.dot(mlps.grad, mlps.grad)))
                mlps.grad *= min(1.0, self.max_grad_norm / (norm + 1e-6))
                self._adam_steps += 1
                m *= beta1
                m += (1 - beta1) * mlps.grad
                v *= beta2
                v += (1 - beta2) * mlps.grad * mlps.grad
                correction1, correction2 = 1 - beta1 ** self._adam_steps, 1 - beta2 ** self._adam_steps
                mlps.flat -= (lr / correction1) * m / (np.sqrt(v) / np.sqrt(correction2) + eps)
        self._n_updates += self.n_epochs
        mlps.write_back()
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/clip_range", clip_range)

    def _minibatch(self, x: np.ndarray, actions: np.ndarray, old_log_prob: np.ndarray, advantages: np.ndarray,
                   returns: np.ndarray, clip_range: float) -> None:
        """Gradients of SB3's PPO loss on one minibatch, into the flat gradient."""
        mlps, batch = self._mlps, len(actions)
        logits, actor_inputs = mlps.forward(mlps.actor, x)
        values, critic_inputs = mlps.forward(mlps.critic, x)
        shifted = logits - logits.max(axis=1, keepdims=True)
        log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
        probs = np.exp(log_probs)
        rows = np.arange(batch)
        ratio = np.exp(log_probs[rows, actions] - old_log_prob)
        if batch > 1:
            advantages = (advantages - advantages.mean()) / (advantages.std(ddof=1) + 1e-8)
        # d(-mean(min(A r, A clip(r))))/dr: A where the unclipped term is the smaller, A only inside the clip range
        # where the clipped one is. (torch.min splits a tie's gradient in half between both terms; a tie means
        # r is inside the range or A = 0, where both halves are A or 0, so the sum is the same.)
        unclipped, clipped = advantages * ratio, advantages * np.clip(ratio, 1 - clip_range, 1 + clip_range)
        inside = (ratio >= 1 - clip_range) & (ratio <= 1 + clip_range)
        weight = np.where(unclipped <= clipped, 1.0, inside)
        d_log_prob = -(advantages * weight * ratio) / batch
        d_logits = -probs * d_log_prob[:, None]
        d_logits[rows, actions] += d_log_prob
        if self.ent_coef:  # -ent_coef * mean(entropy); dH/dlogits = -p (log p + H)
            entropy = -(probs * log_probs).sum(axis=1)
            d_logits += (self.ent_coef / batch) * probs * (log_probs + entropy[:, None])
        d_values = (self.vf_coef * 2.0 / batch) * (values[:, 0] - returns)
        mlps.backward(mlps.actor, actor_inputs, d_logits.astype(np.float32))
        mlps.backward(mlps.critic, critic_inputs, d_values[:, None].astype(np.float32))
