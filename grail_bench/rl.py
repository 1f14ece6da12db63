"""Reinforcement learning on a goal env's true reward (Panda experts, DRACO)."""

from __future__ import annotations

import sys
from typing import Any, Callable, Sequence

import gymnasium as gym
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv

SAC_DEFAULTS = {"learning_starts": 500, "batch_size": 128}


def make_sac(env: gym.Env, net_arch: Sequence[int], seed: int = 0) -> SAC:
    """SB3 SAC with a small MLP, as the suite trains it (also used to rebuild cached models)."""
    return SAC("MlpPolicy", env, policy_kwargs={"net_arch": list(net_arch)}, seed=seed, verbose=0, device="cpu",
               **SAC_DEFAULTS)


def make_ppo(env_fn: Callable[[], gym.Env], net_arch: Sequence[int], seed: int = 0, n_envs: int = 8) -> PPO:
    """SB3 PPO on ``n_envs`` copies of an env (also used to rebuild cached models)."""
    venv = DummyVecEnv([env_fn for _ in range(n_envs)])
    venv.seed(seed)
    return PPO("MlpPolicy", venv, policy_kwargs={"net_arch": list(net_arch)}, n_steps=128, batch_size=64,
               seed=seed, verbose=0, device="cpu")


def learn(model: BaseAlgorithm, steps: int) -> dict[str, Any]:
    """Train (with a progress bar on a terminal) and return the policy's ``state_dict``."""
    from grail_bench.recognizers._torch import single_thread

    with single_thread():
        model.learn(steps, progress_bar=sys.stderr.isatty())
    return model.policy.state_dict()
