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
a full round). Continuous actions (SB3's diagonal Gaussian with one
state-independent ``log_std``) are mirrored only when asked
(``NumpyPPO(..., gaussian=True)``), so models trained before keep their
meaning; policies it cannot mirror (custom networks or extractors, value
clipping, a KL target, SDE, squashed actions) fall back to SB3's.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.distributions import CategoricalDistribution, DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import FlattenExtractor

from grail_bench.core.flat_mlp import Adam, FlatMLPs
from grail_bench.core.spaces import preprocess


def mirrorable(model: PPO) -> bool:
    """Whether :class:`NumpyPPO` can run ``model``'s update in numpy (else it uses SB3's)."""
    policy = model.policy
    if not isinstance(policy, ActorCriticPolicy):
        return False
    discrete = isinstance(model.action_space, spaces.Discrete) and isinstance(policy.action_dist,
                                                                              CategoricalDistribution)
    gaussian = (getattr(model, "gaussian", False) and isinstance(model.action_space, spaces.Box)
                and type(policy.action_dist) is DiagGaussianDistribution and not policy.squash_output)
    group = policy.optimizer.param_groups[0]
    layers = [*policy.mlp_extractor.policy_net, *policy.mlp_extractor.value_net]
    flat_space = isinstance(model.observation_space, (spaces.Box, spaces.Discrete, spaces.MultiDiscrete))
    return ((discrete or gaussian) and flat_space and isinstance(policy.features_extractor, FlattenExtractor)
            and policy.share_features_extractor
            and not model.use_sde and model.clip_range_vf is None and model.target_kl is None
            and model.normalize_advantage and type(policy.optimizer) is torch.optim.Adam
            and not (group.get("amsgrad") or group.get("maximize") or group.get("weight_decay"))
            and FlatMLPs.mirrors(layers))


class GAEBuffer(RolloutBuffer):
    """SB3's rollout buffer, its returns and advantages computed as every SB3 2.x before 2.3 did.

    SB3 2.3 turned the last step's ``1 - done`` into float32, and with it the whole backward GAE recursion, which
    had run in float64 (stored as float32 at each step). Every published PPO model was trained with the float64
    recursion; this buffer keeps it on every SB3 version, so the same seed trains the same weights.
    """

    def compute_returns_and_advantage(self, last_values: torch.Tensor, dones: np.ndarray) -> None:
        next_values = last_values.clone().cpu().numpy().flatten()
        next_non_terminal = 1.0 - np.asarray(dones, dtype=np.float64)
        last_gae_lam: Any = 0
        for step in reversed(range(self.buffer_size)):
            if step < self.buffer_size - 1:
                next_non_terminal = 1.0 - self.episode_starts[step + 1]
                next_values = self.values[step + 1]
            delta = self.rewards[step] + self.gamma * next_values * next_non_terminal - self.values[step]
            last_gae_lam = delta + self.gamma * self.gae_lambda * next_non_terminal * last_gae_lam
            self.advantages[step] = last_gae_lam
        self.returns = self.advantages + self.values


class NumpyPPO(PPO):
    """SB3's PPO whose update (:meth:`train`) runs in numpy when the policy allows (:func:`mirrorable`).

    Its rollouts go to a :class:`GAEBuffer` unless another buffer class is given.

    Args:
        gaussian: Mirror continuous actions too (SB3's update runs them otherwise).
        args, kwargs: SB3's ``PPO``'s.
    """

    _mlps: FlatMLPs | None = None
    _adam: Adam | None = None

    def __init__(self, *args: Any, gaussian: bool = False, **kwargs: Any) -> None:
        self.gaussian = gaussian
        kwargs.setdefault("rollout_buffer_class", GAEBuffer)
        super().__init__(*args, **kwargs)

    def train(self) -> None:
        if not mirrorable(self):
            super().train()
            return
        group = self.policy.optimizer.param_groups[0]
        if self._mlps is None:
            policy = self.policy
            gaussian = isinstance(self.action_space, spaces.Box)
            self._mlps = FlatMLPs([[*policy.mlp_extractor.policy_net, policy.action_net],
                                   [*policy.mlp_extractor.value_net, policy.value_net]],
                                  extra=[policy.log_std] if gaussian else [])
            self._adam = Adam(self._mlps.flat.size, group["betas"], float(group["eps"]))
        self._mlps.read()
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)  # as SB3 does: logs it and keeps the optimizer in step
        lr = float(group["lr"])
        clip_range = float(self.clip_range(self._current_progress_remaining))
        mlps, buffer = self._mlps, self.rollout_buffer

        def flat(name: str) -> np.ndarray:  # SB3's swap_and_flatten, read without changing the buffer
            arr = getattr(buffer, name)
            return arr.swapaxes(0, 1).reshape(arr.shape[0] * arr.shape[1], *arr.shape[2:])

        n = buffer.buffer_size * buffer.n_envs
        features = preprocess(flat("observations"), self.observation_space)
        actions = flat("actions").reshape(n, -1) if isinstance(self.action_space, spaces.Box) else (
            flat("actions").reshape(n).astype(np.int64))
        old_log_prob, advantages, returns = flat("log_probs"), flat("advantages"), flat("returns")
        for _ in range(self.n_epochs):
            indices = np.random.permutation(n)  # SB3's draw per epoch, so minibatches are SB3's
            for start in range(0, n, self.batch_size):
                idx = indices[start:start + self.batch_size]
                self._minibatch(features[idx], actions[idx], old_log_prob[idx], advantages[idx], returns[idx],
                                clip_range)
                # The global-norm clip, then Adam.
                norm = float(np.sqrt(np.dot(mlps.grad, mlps.grad)))
                mlps.grad *= min(1.0, self.max_grad_norm / (norm + 1e-6))
                self._adam.step(mlps.flat, mlps.grad, lr)
        self._n_updates += self.n_epochs
        mlps.write_back()
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/clip_range", clip_range)

    def _minibatch(self, x: np.ndarray, actions: np.ndarray, old_log_prob: np.ndarray, advantages: np.ndarray,
                   returns: np.ndarray, clip_range: float) -> None:
        """Gradients of SB3's PPO loss on one minibatch, into the flat gradient."""
        mlps, batch = self._mlps, len(actions)
        actor, critic = mlps.chains
        out, actor_inputs = mlps.forward(actor, x)
        values, critic_inputs = mlps.forward(critic, x)
        gaussian = actions.ndim == 2
        log_prob, grads = (_gaussian if gaussian else _categorical)(out, actions, mlps.extra)
        ratio = np.exp(log_prob - old_log_prob)
        if batch > 1:
            advantages = (advantages - advantages.mean()) / (advantages.std(ddof=1) + 1e-8)
        # d(-mean(min(A r, A clip(r))))/dr: A where the unclipped term is the smaller, A only inside the clip range
        # where the clipped one is. (torch.min splits a tie's gradient in half between both terms; a tie means
        # r is inside the range or A = 0, where both halves are A or 0, so the sum is the same.)
        unclipped, clipped = advantages * ratio, advantages * np.clip(ratio, 1 - clip_range, 1 + clip_range)
        inside = (ratio >= 1 - clip_range) & (ratio <= 1 + clip_range)
        weight = np.where(unclipped <= clipped, 1.0, inside)
        d_log_prob = -(advantages * weight * ratio) / batch
        d_out = grads(d_log_prob, self.ent_coef / batch, mlps.extra_grad)
        d_values = (self.vf_coef * 2.0 / batch) * (values[:, 0] - returns)
        mlps.backward(actor, actor_inputs, d_out.astype(np.float32))
        mlps.backward(critic, critic_inputs, d_values[:, None].astype(np.float32))


# The two action heads: each returns the log-probabilities of the taken actions and a function that, given the
# loss's gradient by them and the entropy term's weight (ent_coef / batch: the loss has -ent_coef * mean(H)),
# returns the gradient by the head's output (writing any other parameter's, e.g. log_std's, into ``extra_grad``).

def _categorical(logits: np.ndarray, actions: np.ndarray, extra: list) -> tuple[np.ndarray, Any]:
    shifted = logits - logits.max(axis=1, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
    probs, rows = np.exp(log_probs), np.arange(len(actions))

    def grads(d_log_prob: np.ndarray, entropy_weight: float, extra_grad: list) -> np.ndarray:
        d_logits = -probs * d_log_prob[:, None]
        d_logits[rows, actions] += d_log_prob
        if entropy_weight:  # dH/dlogits = -p (log p + H)
            entropy = -(probs * log_probs).sum(axis=1)
            d_logits += entropy_weight * probs * (log_probs + entropy[:, None])
        return d_logits

    return log_probs[rows, actions], grads


def _gaussian(mean: np.ndarray, actions: np.ndarray, extra: list) -> tuple[np.ndarray, Any]:
    (log_std,) = extra
    std = np.exp(log_std)
    z = (actions - mean) / std
    log_prob = -0.5 * (z * z).sum(axis=1) - log_std.sum() - 0.5 * len(log_std) * np.log(2 * np.pi)

    def grads(d_log_prob: np.ndarray, entropy_weight: float, extra_grad: list) -> np.ndarray:
        # d log p / d mean = z / std; d log p / d log_std = z^2 - 1; H = sum(log_std) + const per sample.
        (d_log_std,) = extra_grad
        d_log_std[:] = d_log_prob @ (z * z - 1.0) - entropy_weight * len(mean)
        return d_log_prob[:, None] * z / std

    return log_prob, grads
