"""DRACO (Nageris et al. 2024): one RL policy per goal on the true reward, Wasserstein scoring."""

from __future__ import annotations

import time
from importlib.metadata import version
from typing import Sequence

from gymnasium import spaces
from imitation.data.types import Trajectory
from stable_baselines3.common.policies import BasePolicy

from grail_bench.cache import cached_state_dict
from grail_bench.recognizers.base import EnvFactory, Goal
from grail_bench.recognizers.policy import PolicyRecognizer
from grail_bench.rl import learn, make_ppo, make_sac


class DRACORecognizer(PolicyRecognizer):
    """DRACO: SAC (continuous actions) or PPO (discrete) per goal, on the env's own reward.

    It learns from interaction only (the demonstrations are ignored). When the
    env factory has a ``cache_key`` (the harness's does), trained policies are
    cached on disk and reused by every regime of the domain.

    Args:
        sac_steps: SAC steps per goal (continuous actions).
        ppo_steps: PPO steps per goal (discrete actions), over 8 env copies.
        net_arch: Hidden layers of the policy.
        scorer: Default ``"wasserstein"`` (DRACO's).
    """

    name = "draco"
    default_scorer = "wasserstein"

    def __init__(self, *, sac_steps: int = 15_000, ppo_steps: int = 100_000, net_arch: Sequence[int] = (64, 64),
                 scorer: str | None = None) -> None:
        if sac_steps < 1 or ppo_steps < 1:
            raise ValueError("draco: step budgets must be positive")
        super().__init__(scorer, sac_steps=sac_steps, ppo_steps=ppo_steps, net_arch=list(net_arch))

    def train_policy(self, goal: Goal, demos: Sequence[Trajectory], env_factory: EnvFactory,
                     seed: int) -> BasePolicy:
        cfg = self.config
        env = env_factory(goal)
        continuous = isinstance(env.action_space, spaces.Box)
        if continuous:
            model, steps = make_sac(env, cfg["net_arch"], seed), cfg["sac_steps"]
        else:
            model, steps = make_ppo(lambda: env_factory(goal), cfg["net_arch"], seed), cfg["ppo_steps"]
        cache_key = getattr(env_factory, "cache_key", None)
        if cache_key is None:
            start = time.perf_counter()
            learn(model, steps)
            seconds = time.perf_counter() - start
        else:
            key = {"env": cache_key, "goal": list(goal), "seed": seed, "config": cfg,
                   "versions": [version("stable-baselines3"), version("torch")]}
            state, seconds = cached_state_dict(f"draco-{'sac' if continuous else 'ppo'}", key,
                                               lambda: learn(model, steps))
            model.policy.load_state_dict(state)
        self.fit_seconds += seconds
        env.close()
        return model.policy

    def fit(self, demos, env_factory, *, seed: int) -> None:
        """Train (or reload) one policy per goal; :attr:`fit_seconds` is what training cost."""
        self.fit_seconds = 0.0
        super().fit(demos, env_factory, seed=seed)
