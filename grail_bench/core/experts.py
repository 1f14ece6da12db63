"""RL experts that domains' demonstrators run: a SAC policy per goal, trained once and cached, acting
deterministically.

Demonstrations cached on disk are keyed by a digest of this module (not of :mod:`grail_bench.core.rl`, which
DRACO's and GC-DRACO's training also lives in), so editing how recognizers train leaves them valid.
"""

from __future__ import annotations

from importlib.metadata import version
from typing import Any, Callable, Sequence

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.sac.policies import SACPolicy

from grail_bench.core.cache import cached_state_dict
from grail_bench.core.rl import empty_policy, learn, make_sac
from grail_bench.core.torchutil import single_thread


def deterministic_actor(policy: SACPolicy) -> Callable[[np.ndarray], np.ndarray]:
    """``policy.predict(obs, deterministic=True)[0]`` for one flat observation, bit for bit, without SB3's
    per-call overhead (switching training mode, checking the observation): about 3.5x faster per step.

    The same torch operations on the same ``(1, obs_dim)`` batch (tanh of the actor's mean), then SB3's
    rescaling to the action bounds in float32.
    """
    actor = policy.actor
    low, high = policy.action_space.low, policy.action_space.high
    obs_shape, shape = policy.observation_space.shape, policy.action_space.shape

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            batch = torch.as_tensor(np.asarray(obs).reshape((1, *obs_shape)))
            mean = actor.mu(actor.latent_pi(actor.extract_features(batch, actor.features_extractor)))
            scaled = torch.tanh(mean).numpy().reshape((-1, *shape))
        return (low + (0.5 * (scaled + 1.0) * (high - low)))[0]

    return act


def sac_expert(kind: str, env: gym.Env, key: dict[str, Any], steps: int, seed: int,
               net_arch: Sequence[int]) -> Callable[[np.ndarray], np.ndarray]:
    """A SAC expert on ``env``'s reward, trained once per ``key`` and cached; its deterministic policy.

    Args:
        kind: Cache folder (e.g. ``"panda-sac-expert"``).
        env: The goal's env (not closed here).
        key: Everything the expert depends on besides ``steps``, ``seed`` and ``net_arch``.
        steps: SAC training steps.
        seed: Training seed.
        net_arch: Hidden layers.
    """
    full_key = {**key, "seed": seed, "steps": steps, "net": list(net_arch),
                "versions": [version("stable-baselines3"), version("torch")]}
    with single_thread():
        policy = empty_policy("sac", env.observation_space, env.action_space, net_arch)
        state, _ = cached_state_dict(kind, full_key, lambda: learn(make_sac(env, net_arch, seed), steps)[0],
                                     check=policy.load_state_dict)  # a wrong key or shape: retrained
    policy.load_state_dict(state)
    policy.set_training_mode(False)
    return deterministic_actor(policy)
