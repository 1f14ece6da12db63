"""Adversarial imitation: GAIL's and AIRL's discriminators and training loop, after imitation 1.0.1's algorithms.

What GAIL- and AIRL-GRAIL train with, written to reproduce imitation 1.0.1 (Gleave et al. 2022) step for step:
the same reward networks built in the same order (so a seed gives them the same initial weights), the same input
normalisation, the same discriminator losses, and random numbers drawn from the same generators in the same order
(the expert batches from a shuffling torch ``DataLoader``, the generator's samples from numpy's global generator).
The same seed therefore trains the same weights. The generator is any SB3 on-policy algorithm with an
``ActorCriticPolicy``; the trainer swaps its environment for one whose rewards are the discriminator's
(:attr:`AdversarialTrainer.venv_wrapped`) and keeps the transitions it collects for the discriminator.

* GAIL (Ho & Ermon 2016): the discriminator's logit is :class:`BasicRewardNet`'s output; the generator's reward
  is ``-log sigmoid(-logit)``.
* AIRL (Fu et al. 2018): the logit is a shaped reward (:class:`BasicShapedRewardNet`) minus the generator
  policy's ``log pi(a|s)``; the generator's reward is the shaped reward.

Parts follow imitation's code closely; imitation is MIT-licensed, Copyright (c) 2019-2022 Center for Human-Compatible
AI and Google LLC.
"""

from __future__ import annotations

import abc
import collections
import itertools
from typing import Any, Callable, Iterator, Mapping, Sequence

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.preprocessing import get_flattened_obs_dim, preprocess_obs
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from torch import nn
from torch.nn import functional as F
from torch.utils import data as th_data

from grail_bench.core.rl import silenced
from grail_bench.core.trajectory import Trajectory

#: ``reward_fn(obs, acts, next_obs, dones)``: one reward per transition.
RewardFn = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


# --- Reward networks -------------------------------------------------------------------------------------------


class VariableHorizonError(ValueError):
    """Generator episodes of different lengths, which the trainers refuse unless told to allow them."""


class RunningNorm(nn.Module):
    """Normalises its input to mean 0 and variance 1 with statistics of every batch seen in training mode.

    The statistics are updated (Chan et al. 1979's pairwise formulae) on each forward pass in training mode and
    left alone in evaluation mode.

    Args:
        num_features: Length of the input's non-batch dimension.
        eps: Added to the variance before its square root.
    """

    running_mean: torch.Tensor
    running_var: torch.Tensor
    count: torch.Tensor

    def __init__(self, num_features: int, eps: float = 1e-5) -> None:
        super().__init__()
        self.eps = eps
        self.register_buffer("running_mean", torch.zeros(num_features))
        self.register_buffer("running_var", torch.ones(num_features))
        self.register_buffer("count", torch.zeros((), dtype=torch.int))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.training:
            with torch.no_grad():
                self.update_stats(x)
        return (x - self.running_mean) / torch.sqrt(self.running_var + self.eps)

    def update_stats(self, batch: torch.Tensor) -> None:
        """Fold ``batch`` into the running mean, variance and count."""
        batch_mean = torch.mean(batch, dim=0)
        batch_var = torch.var(batch, dim=0, unbiased=False)
        batch_count = batch.shape[0]
        delta = batch_mean - self.running_mean
        tot_count = self.count + batch_count
        self.running_mean += delta * batch_count / tot_count
        self.running_var *= self.count
        self.running_var += batch_var * batch_count
        self.running_var += torch.square(delta) * self.count * batch_count / tot_count
        self.running_var /= tot_count
        self.count += batch_count


class _Squeeze(nn.Module):
    """``(B, 1) -> (B,)``."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x.squeeze(1)


def build_mlp(in_size: int, hid_sizes: Sequence[int], *, flatten_input: bool = False,
              normalize_input_layer: type[nn.Module] | None = None) -> nn.Sequential:
    """A ReLU MLP with one squeezed output: ``(B, in_size) -> (B,)``.

    Its layers are named and built in imitation's order (``flatten``, ``normalize_input``, ``dense0``, ``act0``,
    ..., ``dense_final``, ``squeeze``), so a seed initialises the same weights.
    """
    layers: dict[str, nn.Module] = {}
    if flatten_input:
        layers["flatten"] = nn.Flatten()
    if normalize_input_layer is not None:
        layers["normalize_input"] = normalize_input_layer(in_size)
    prev_size = in_size
    for i, size in enumerate(hid_sizes):
        layers[f"dense{i}"] = nn.Linear(prev_size, size)
        prev_size = size
        layers[f"act{i}"] = nn.ReLU()
    layers["dense_final"] = nn.Linear(prev_size, 1)
    layers["squeeze"] = _Squeeze()
    return nn.Sequential(collections.OrderedDict(layers))


class RewardNet(nn.Module, abc.ABC):
    """A reward of transitions ``(state, action, next_state, done)``, as a torch module.

    Args:
        observation_space: The environment's observation space.
        action_space: Its action space.
        normalize_images: Scale image observations from [0, 255] to [0, 1] (SB3's ``preprocess_obs``).
    """

    def __init__(self, observation_space: gym.Space, action_space: gym.Space, normalize_images: bool = True) -> None:
        super().__init__()
        self.observation_space = observation_space
        self.action_space = action_space
        self.normalize_images = normalize_images

    @abc.abstractmethod
    def forward(self, state: torch.Tensor, action: torch.Tensor, next_state: torch.Tensor,
                done: torch.Tensor) -> torch.Tensor:
        """The rewards of a batch of preprocessed transitions, ``(B,)``, with gradients."""

    def preprocess(self, state: np.ndarray, action: np.ndarray, next_state: np.ndarray,
                   done: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Arrays to the tensors :meth:`forward` takes: SB3's ``preprocess_obs`` (one-hot for discrete spaces,
        float for boxes) on states and actions, dones as float32."""
        state_th, action_th, next_state_th, done_th = (_to_tensor(x) for x in (state, action, next_state, done))
        state_th = preprocess_obs(state_th, self.observation_space, self.normalize_images)
        action_th = preprocess_obs(action_th, self.action_space, self.normalize_images)
        next_state_th = preprocess_obs(next_state_th, self.observation_space, self.normalize_images)
        return state_th, action_th, next_state_th, done_th.to(torch.float32)

    def predict(self, state: np.ndarray, action: np.ndarray, next_state: np.ndarray,
                done: np.ndarray) -> np.ndarray:
        """The rewards of a batch of transitions as a flat array, computed in evaluation mode without gradients
        (input statistics stay as they are)."""
        before = self.training
        self.train(False)
        try:
            inputs = self.preprocess(state, action, next_state, done)
            with torch.no_grad():
                rewards = self(*inputs)
        finally:
            self.train(before)
        return rewards.detach().cpu().numpy().flatten()


def _to_tensor(array: np.ndarray | torch.Tensor) -> torch.Tensor:
    """``torch.as_tensor``, copying a read-only array first."""
    if isinstance(array, np.ndarray) and not array.flags.writeable:
        array = array.copy()
    return torch.as_tensor(array)


class BasicRewardNet(RewardNet):
    """An MLP of the flattened, concatenated state and action (and next state and done, if asked).

    Args:
        observation_space: The observation space.
        action_space: The action space.
        use_state: Input the state.
        use_action: Input the action.
        use_next_state: Input the next state.
        use_done: Input the done flag.
        hid_sizes: Hidden layer widths.
        normalize_input_layer: A normalisation of the input (e.g. :class:`RunningNorm`), or None.
    """

    def __init__(self, observation_space: gym.Space, action_space: gym.Space, use_state: bool = True,
                 use_action: bool = True, use_next_state: bool = False, use_done: bool = False,
                 hid_sizes: Sequence[int] = (32, 32), normalize_input_layer: type[nn.Module] | None = None) -> None:
        super().__init__(observation_space, action_space)
        self.use_state, self.use_action = use_state, use_action
        self.use_next_state, self.use_done = use_next_state, use_done
        size = ((get_flattened_obs_dim(observation_space) if use_state else 0)
                + (get_flattened_obs_dim(action_space) if use_action else 0)
                + (get_flattened_obs_dim(observation_space) if use_next_state else 0) + int(use_done))
        self.mlp = build_mlp(size, hid_sizes, normalize_input_layer=normalize_input_layer)

    def forward(self, state: torch.Tensor, action: torch.Tensor, next_state: torch.Tensor,
                done: torch.Tensor) -> torch.Tensor:
        inputs = []
        if self.use_state:
            inputs.append(torch.flatten(state, 1))
        if self.use_action:
            inputs.append(torch.flatten(action, 1))
        if self.use_next_state:
            inputs.append(torch.flatten(next_state, 1))
        if self.use_done:
            inputs.append(torch.reshape(done, [-1, 1]))
        return self.mlp(torch.cat(inputs, dim=1))


class BasicPotentialMLP(nn.Module):
    """A state potential: an MLP of the flattened state.

    Args:
        observation_space: The observation space.
        hid_sizes: Hidden layer widths.
        normalize_input_layer: A normalisation of the input, or None.
    """

    def __init__(self, observation_space: gym.Space, hid_sizes: Sequence[int],
                 normalize_input_layer: type[nn.Module] | None = None) -> None:
        super().__init__()
        self._potential_net = build_mlp(get_flattened_obs_dim(observation_space), hid_sizes, flatten_input=True,
                                        normalize_input_layer=normalize_input_layer)

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        return self._potential_net(state)


class BasicShapedRewardNet(RewardNet):
    """AIRL's reward: ``g(s, a) + discount * (1 - done) * h(s') - h(s)``, ``g`` a :class:`BasicRewardNet` and ``h``
    a :class:`BasicPotentialMLP`.

    Args:
        observation_space: The observation space.
        action_space: The action space.
        reward_hid_sizes: Hidden layer widths of ``g``.
        potential_hid_sizes: Hidden layer widths of ``h``.
        use_state: ``g`` inputs the state.
        use_action: ``g`` inputs the action.
        use_next_state: ``g`` inputs the next state.
        use_done: ``g`` inputs the done flag.
        discount_factor: The shaping's discount.
        normalize_input_layer: A normalisation of ``g``'s and ``h``'s inputs, or None.
    """

    def __init__(self, observation_space: gym.Space, action_space: gym.Space, *,
                 reward_hid_sizes: Sequence[int] = (32,), potential_hid_sizes: Sequence[int] = (32, 32),
                 use_state: bool = True, use_action: bool = True, use_next_state: bool = False,
                 use_done: bool = False, discount_factor: float = 0.99,
                 normalize_input_layer: type[nn.Module] | None = None) -> None:
        base = BasicRewardNet(observation_space, action_space, use_state=use_state, use_action=use_action,
                              use_next_state=use_next_state, use_done=use_done, hid_sizes=reward_hid_sizes,
                              normalize_input_layer=normalize_input_layer)
        potential = BasicPotentialMLP(observation_space, potential_hid_sizes,
                                      normalize_input_layer=normalize_input_layer)
        super().__init__(observation_space, action_space, base.normalize_images)
        self._base = base
        self.potential = potential
        self.discount_factor = discount_factor

    @property
    def base(self) -> BasicRewardNet:
        """``g``, the unshaped reward."""
        return self._base

    def forward(self, state: torch.Tensor, action: torch.Tensor, next_state: torch.Tensor,
                done: torch.Tensor) -> torch.Tensor:
        # The order of the three passes is the order the normalisation layers see their batches in.
        base_reward = self._base(state, action, next_state, done)
        new_shaping_output = self.potential(next_state).flatten()
        old_shaping_output = self.potential(state).flatten()
        new_shaping = (1 - done.float()) * new_shaping_output
        return base_reward + self.discount_factor * new_shaping - old_shaping_output


class _LogSigmoidReward(RewardNet):
    """GAIL's generator reward from its discriminator's logit ``L``: ``-log sigmoid(-L)``."""

    def __init__(self, base: RewardNet) -> None:
        super().__init__(base.observation_space, base.action_space, base.normalize_images)
        self.base = base

    def forward(self, state: torch.Tensor, action: torch.Tensor, next_state: torch.Tensor,
                done: torch.Tensor) -> torch.Tensor:
        return -F.logsigmoid(-self.base(state, action, next_state, done))


# --- Transitions: expert batches, the generator's replay buffer, and the wrapped environment ------------------


class _Transitions(th_data.Dataset):
    """Demonstrations as ``(obs, acts, next_obs, dones)`` rows (``dones``: the episode's last step, if terminal)."""

    def __init__(self, trajectories: Sequence[Trajectory]) -> None:
        self.obs, self.acts, self.next_obs, self.dones = _flatten(
            [(np.asarray(t.obs), np.asarray(t.acts), bool(t.terminal)) for t in trajectories])

    def __len__(self) -> int:
        return len(self.acts)

    def __getitem__(self, i: int) -> tuple[np.ndarray, ...]:
        return self.obs[i], self.acts[i], self.next_obs[i], self.dones[i]


def _flatten(trajectories: Sequence[tuple[np.ndarray, np.ndarray, bool]]) -> tuple[np.ndarray, ...]:
    """``(obs, acts, terminal)`` episodes as transition arrays ``(obs, acts, next_obs, dones)``, in order."""
    dones = []
    for _, acts, terminal in trajectories:
        done = np.zeros(len(acts), dtype=bool)
        done[-1] = terminal
        dones.append(done)
    return (np.concatenate([obs[:-1] for obs, _, _ in trajectories]), np.concatenate([a for _, a, _ in trajectories]),
            np.concatenate([obs[1:] for obs, _, _ in trajectories]), np.concatenate(dones))


def _stack_batch(rows: Sequence[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    return tuple(np.stack([np.asarray(row[k]) for row in rows]) for k in range(4))


def _endless_batches(loader: th_data.DataLoader) -> Iterator[tuple[np.ndarray, ...]]:
    """The loader's batches, pass after pass, forever.

    imitation first checks the loader is not an iterator and peeks at its first batch; each starts a pass over
    it, which draws torch's global generator, so both are made here too (and keep the later passes' shuffles).
    """
    iter(loader)
    next(iter(loader))
    return itertools.chain.from_iterable(itertools.repeat(loader))


class ReplayBuffer:
    """A ring buffer of the generator's transitions, sampled uniformly with replacement (numpy's global generator).

    Args:
        capacity: Transitions kept (the oldest are overwritten).
        venv: The environment, whose spaces give the arrays' shapes and dtypes.
    """

    def __init__(self, capacity: int, venv: VecEnv) -> None:
        self.capacity = capacity
        obs_space, act_space = venv.observation_space, venv.action_space
        self._arrays = {
            "obs": np.zeros((capacity, *obs_space.shape), dtype=obs_space.dtype),
            "acts": np.zeros((capacity, *act_space.shape), dtype=act_space.dtype),
            "next_obs": np.zeros((capacity, *obs_space.shape), dtype=obs_space.dtype),
            "dones": np.zeros(capacity, dtype=bool),
        }
        self._n_data = 0
        self._idx = 0

    def size(self) -> int:
        """Transitions held."""
        return self._n_data

    def store(self, transitions: Mapping[str, np.ndarray]) -> None:
        """Add transitions (only the last ``capacity`` if there are more)."""
        if len(transitions["obs"]) == 0:
            raise ValueError("no transitions to store")
        data = {k: transitions[k][-self.capacity:] for k in self._arrays}
        n = len(data["obs"])
        if self._idx + n > self.capacity:
            split = self.capacity - self._idx
            self._store_easy({k: v[:split] for k, v in data.items()})
            self._store_easy({k: v[split:] for k, v in data.items()})
        else:
            self._store_easy(data)

    def _store_easy(self, data: Mapping[str, np.ndarray]) -> None:
        n = len(data["obs"])
        for k, v in data.items():
            self._arrays[k][self._idx:self._idx + n] = v
        self._idx = (self._idx + n) % self.capacity
        self._n_data = min(self._n_data + n, self.capacity)

    def sample(self, n_samples: int) -> dict[str, np.ndarray]:
        """``n_samples`` transitions drawn uniformly with replacement."""
        if self._n_data == 0:
            raise ValueError("the replay buffer is empty")
        ind = np.random.randint(self._n_data, size=n_samples)
        return {k: v[ind] for k, v in self._arrays.items()}


class BufferingWrapper(VecEnvWrapper):
    """Keeps the transitions stepped through it, per episode, until :meth:`pop_transitions`.

    Args:
        venv: The environment.
    """

    def __init__(self, venv: VecEnv) -> None:
        super().__init__(venv)
        self._partial: list[tuple[list[np.ndarray], list[np.ndarray]]] = []
        self._finished: list[tuple[np.ndarray, np.ndarray, bool]] = []
        self._ep_lens: list[int] = []
        self._timesteps = np.zeros(0, dtype=int)
        self._saved_acts: np.ndarray | None = None
        self.n_transitions: int | None = None

    def reset(self, **kwargs: Any) -> Any:
        if self.n_transitions:
            raise RuntimeError("reset() before the transitions were popped")
        self.n_transitions = 0
        obs = self.venv.reset(**kwargs)
        self._partial = [([ob], []) for ob in obs]
        self._timesteps = np.zeros(len(obs), dtype=int)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(actions)
        self._saved_acts = actions

    def step_wait(self) -> Any:
        acts, self._saved_acts = self._saved_acts, None
        obs, rews, dones, infos = self.venv.step_wait()
        self.n_transitions += self.num_envs
        self._timesteps += 1
        self._ep_lens += list(self._timesteps[dones])
        self._timesteps[dones] = 0
        for i, (act, ob, done, info) in enumerate(zip(acts, obs, dones, infos)):
            observations, actions = self._partial[i]
            observations.append(info["terminal_observation"] if done else ob)
            actions.append(act)
            if done:
                self._finished.append(self._finish(i, terminal=True))
                self._partial[i] = ([ob], [])
        return obs, rews, dones, infos

    def _finish(self, i: int, terminal: bool) -> tuple[np.ndarray, np.ndarray, bool]:
        observations, actions = self._partial[i]
        return np.stack(observations), np.stack(actions), terminal

    def pop_transitions(self) -> tuple[dict[str, np.ndarray] | None, list[int]]:
        """The transitions since the last pop (whole episodes first, as they ended; then each copy's unfinished
        one) and the lengths of the episodes that ended; ``(None, [])`` if there are none."""
        if self.n_transitions == 0:
            return None, []
        for i, (_, actions) in enumerate(self._partial):
            if actions:
                episode = self._finish(i, terminal=False)
                self._finished.append(episode)
                self._partial[i] = ([episode[0][-1]], [])
        episodes, ep_lens = self._finished, self._ep_lens
        self._finished, self._ep_lens, self.n_transitions = [], [], 0
        obs, acts, next_obs, dones = _flatten(episodes)
        return {"obs": obs, "acts": acts, "next_obs": next_obs, "dones": dones}, ep_lens


class RewardVecEnvWrapper(VecEnvWrapper):
    """Replaces the environment's rewards with ``reward_fn``'s (settable); resets the environment when built.

    Args:
        venv: The environment.
        reward_fn: ``reward_fn(obs, acts, next_obs, dones)``, ``next_obs`` the episode's last observation where
            it ended (not the next episode's first).
    """

    def __init__(self, venv: VecEnv, reward_fn: RewardFn) -> None:
        super().__init__(venv)
        self.reward_fn = reward_fn
        self._old_obs: np.ndarray | None = None
        self._actions: np.ndarray | None = None
        self.reset()

    def reset(self, **kwargs: Any) -> Any:
        self._old_obs = self.venv.reset(**kwargs)
        return self._old_obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions
        self.venv.step_async(actions)

    def step_wait(self) -> Any:
        obs, _, dones, infos = self.venv.step_wait()
        next_obs = np.stack([info["terminal_observation"] if done else ob for ob, done, info in zip(obs, dones, infos)])
        rews = self.reward_fn(self._old_obs, self._actions, next_obs, np.array(dones))
        if len(rews) != len(obs):
            raise ValueError(f"reward_fn gave {len(rews)} rewards for {len(obs)} transitions")
        self._old_obs = obs
        return obs, rews, dones, infos


# --- Trainers --------------------------------------------------------------------------------------------------


class AdversarialTrainer(abc.ABC):
    """Alternates training a generator (an SB3 on-policy algorithm) on a discriminator's rewards and training the
    discriminator to tell the generator's transitions from the demonstrations'.

    Args:
        demonstrations: The expert's episodes.
        demo_batch_size: Expert transitions per discriminator update (as many of the generator's join them).
        venv: The environment the generator trains in.
        gen_algo: The generator; its environment is replaced by :attr:`venv_wrapped`, its logger by a silent one.
        reward_net: The discriminator's reward network.
        n_disc_updates_per_round: Discriminator updates per round (for the caller's loop; kept as given).
        gen_replay_buffer_capacity: Generator transitions the discriminator samples from (default: one round's).
        disc_opt_kwargs: Keyword arguments of the discriminator's Adam.
        allow_variable_horizon: Accept generator episodes of different lengths.

    Raises:
        ValueError: Fewer demonstration transitions than ``demo_batch_size``.
    """

    def __init__(self, *, demonstrations: Sequence[Trajectory], demo_batch_size: int, venv: VecEnv,
                 gen_algo: OnPolicyAlgorithm, reward_net: RewardNet, n_disc_updates_per_round: int = 2,
                 gen_replay_buffer_capacity: int | None = None, disc_opt_kwargs: Mapping[str, Any] | None = None,
                 allow_variable_horizon: bool = False) -> None:
        self.demo_batch_size = demo_batch_size
        self.allow_variable_horizon = allow_variable_horizon
        self._horizon: int | None = None
        expert = _Transitions(demonstrations)
        if len(expert) < demo_batch_size:
            raise ValueError(f"{len(expert)} demonstration transitions, fewer than a batch ({demo_batch_size})")
        loader = th_data.DataLoader(expert, batch_size=demo_batch_size, shuffle=True, drop_last=True,
                                    collate_fn=_stack_batch)
        self._expert_batches = _endless_batches(loader)
        self.n_disc_updates_per_round = n_disc_updates_per_round
        self.venv = venv
        self.gen_algo = gen_algo
        self._reward_net = reward_net.to(gen_algo.device)
        self._disc_opt = torch.optim.Adam(self._reward_net.parameters(), **(disc_opt_kwargs or {}))
        self.venv_buffering = BufferingWrapper(venv)
        self.venv_wrapped = RewardVecEnvWrapper(self.venv_buffering, reward_fn=self.reward_train.predict)
        gen_algo.set_env(self.venv_wrapped)
        silenced(gen_algo)  # the caller reads what it needs
        self.gen_train_timesteps = gen_algo.get_env().num_envs * gen_algo.n_steps
        self._gen_replay_buffer = ReplayBuffer(gen_replay_buffer_capacity or self.gen_train_timesteps, venv)

    @property
    def reward_net(self) -> RewardNet:
        """The discriminator's reward network (its weights are what the discriminator learns)."""
        return self._reward_net

    @property
    def gen_replay_buffer(self) -> ReplayBuffer:
        """The generator's latest transitions, which the discriminator samples."""
        return self._gen_replay_buffer

    @property
    def policy(self) -> ActorCriticPolicy:
        """The generator's policy."""
        return self.gen_algo.policy

    @property
    @abc.abstractmethod
    def reward_train(self) -> RewardNet:
        """The generator's reward."""

    @abc.abstractmethod
    def logits_expert_is_high(self, state: torch.Tensor, action: torch.Tensor, next_state: torch.Tensor,
                              done: torch.Tensor, log_policy_act_prob: torch.Tensor | None) -> torch.Tensor:
        """The discriminator's logits, ``(B,)``: high for transitions it takes for the expert's."""

    def train_gen(self, total_timesteps: int | None = None) -> None:
        """Train the generator for ``total_timesteps`` steps (default :attr:`gen_train_timesteps`) and keep its
        transitions in the replay buffer.

        Raises:
            VariableHorizonError: Generator episodes of different lengths (unless ``allow_variable_horizon``).
        """
        self.gen_algo.learn(total_timesteps=total_timesteps or self.gen_train_timesteps, reset_num_timesteps=False)
        transitions, ep_lens = self.venv_buffering.pop_transitions()
        self._check_fixed_horizon(ep_lens)
        if transitions is not None:
            self._gen_replay_buffer.store(transitions)

    def _check_fixed_horizon(self, ep_lens: Sequence[int]) -> None:
        if self.allow_variable_horizon:
            return
        horizons = set(ep_lens) | ({self._horizon} if self._horizon is not None else set())
        if len(horizons) > 1:
            raise VariableHorizonError(f"ran episodes of different lengths: {sorted(int(h) for h in horizons)}")
        if horizons:
            self._horizon = horizons.pop()

    def train_disc(self) -> dict[str, float]:
        """One discriminator update on a batch of expert and of generator transitions.

        Returns:
            ``disc_loss`` (the batch's binary cross-entropy) and ``disc_acc`` (the share of it classified right).

        Raises:
            RuntimeError: The generator has not been trained yet (no transitions to sample).
        """
        if self._gen_replay_buffer.size() == 0:
            raise RuntimeError("no generator transitions: call train_gen() first")
        self._disc_opt.zero_grad()
        e_obs, e_acts, e_next_obs, e_dones = next(self._expert_batches)
        gen = self._gen_replay_buffer.sample(self.demo_batch_size)
        obs = np.concatenate([e_obs, gen["obs"]])
        acts = np.concatenate([e_acts, gen["acts"]])
        next_obs = np.concatenate([e_next_obs, gen["next_obs"]])
        dones = np.concatenate([e_dones, gen["dones"]])
        labels = torch.as_tensor(np.concatenate([np.ones(self.demo_batch_size, dtype=int),
                                                 np.zeros(self.demo_batch_size, dtype=int)]))
        log_prob = self._log_policy_act_prob(obs, acts)
        logits = self.logits_expert_is_high(*self.reward_train.preprocess(obs, acts, next_obs, dones), log_prob)
        loss = F.binary_cross_entropy_with_logits(logits, labels.float())
        loss.backward()
        self._disc_opt.step()
        with torch.no_grad():
            acc = torch.mean(torch.eq(logits < 0, labels == 0).float())
        return {"disc_loss": float(loss.detach()), "disc_acc": float(acc)}

    def _log_policy_act_prob(self, obs: np.ndarray, acts: np.ndarray) -> torch.Tensor | None:
        """The generator policy's ``log pi(a|s)``, ``(B,)``; None where the discriminator does not use it."""
        return None


class GAIL(AdversarialTrainer):
    """GAIL: the reward network's output is the discriminator's logit; the generator is rewarded
    ``-log sigmoid(-logit)`` (the discriminator's belief that a transition is the expert's, as a reward)."""

    def __init__(self, *, reward_net: RewardNet, **kwargs: Any) -> None:
        self._processed_reward = _LogSigmoidReward(reward_net)
        super().__init__(reward_net=reward_net, **kwargs)

    @property
    def reward_train(self) -> RewardNet:
        return self._processed_reward

    def logits_expert_is_high(self, state: torch.Tensor, action: torch.Tensor, next_state: torch.Tensor,
                              done: torch.Tensor, log_policy_act_prob: torch.Tensor | None) -> torch.Tensor:
        return self._reward_net(state, action, next_state, done)


class AIRL(AdversarialTrainer):
    """AIRL: the discriminator's logit is the reward network's output minus the generator's ``log pi(a|s)``; the
    generator is rewarded the reward network's output.

    Raises:
        TypeError: A generator without an ``ActorCriticPolicy`` (its action log-probabilities are needed).
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if not isinstance(self.gen_algo.policy, ActorCriticPolicy):
            raise TypeError("AIRL needs a generator with an ActorCriticPolicy (a stochastic policy)")

    @property
    def reward_train(self) -> RewardNet:
        return self._reward_net

    def _log_policy_act_prob(self, obs: np.ndarray, acts: np.ndarray) -> torch.Tensor:
        with torch.no_grad():
            device = self.gen_algo.device
            _, log_prob, _ = self.policy.evaluate_actions(torch.as_tensor(obs, device=device),
                                                          torch.as_tensor(acts, device=device))
        return log_prob.reshape((len(obs),))

    def logits_expert_is_high(self, state: torch.Tensor, action: torch.Tensor, next_state: torch.Tensor,
                              done: torch.Tensor, log_policy_act_prob: torch.Tensor | None) -> torch.Tensor:
        return self._reward_net(state, action, next_state, done) - log_policy_act_prob
