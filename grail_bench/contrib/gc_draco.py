"""GC-DRACO: one goal-conditioned RL agent for every goal, scored by DRACO's Wasserstein distance.

DRACO (:mod:`grail_bench.recognizers.draco`) trains one agent per candidate
goal on the env's own reward. GC-DRACO, as gr_libs' ``GCDraco`` (Nageris et
al.), trains one agent ``pi(a | s, g)`` instead: each episode pursues a
training goal drawn at random, in that goal's env (``env_factory(goal)``, its
reward included), and the agent sees the goal beside the state. It learns from
interaction alone, as DRACO does; the demonstrations only say which goals to
train on (and where each has evidence, for the ``occupancy`` scorer and
``off_support``). An observation is scored against every candidate goal by
conditioning the agent on it and taking DRACO's score, the negative
1-Wasserstein distance between the agent's action distribution and each
observed action (the ``wasserstein`` scorer; gr_libs' ``mean_wasserstein_distance``
measures the distance from the distribution's mean, an L1 distance). A goal it
was never trained on is scored the same way (:meth:`GCDRACORecognizer.set_goals`,
zero-shot mode): gr_libs' ``goals_adaptation_phase``.

The goal enters the observation through GC-BC's
:class:`~grail_bench.recognizers.gcbc.GoalEncoder` (standardised goal
coordinates and the goal relative to the agent), so both goal-conditioned
methods read states and goals alike; scoring, ``set_goals`` and diagnostics
are GC-BC's, only the training differs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from importlib.metadata import version
from typing import Annotated, Any, Callable, Literal, Sequence

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy

from grail_bench.core.cache import cached
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.rl import empty_policy, learn, make_ppo, make_sac
from grail_bench.core.spaces import all_states, n_states, state_index
from grail_bench.core.torchutil import single_thread
from grail_bench.core.trajectory import Demos, EnvFactory, Goal
from grail_bench.recognizers.contract import FitReport, settings_key
from grail_bench.recognizers.gcbc import GCBCRecognizer, GoalEncoder, goal_locator
from grail_bench.recognizers.policy_bank import PolicyBank

ALGORITHMS = ("auto", "ppo", "sac")


@dataclass(frozen=True)
class GCDRACOConfig:
    """GC-DRACO's settings.

    Attributes:
        algorithm: ``"auto"`` (PPO on discrete actions, SAC on continuous ones), ``"ppo"`` or ``"sac"``
            (continuous actions only).
        ppo_steps: PPO env steps in all (over 8 env copies), whatever the number of goals. 100 000 train the
            MiniGrid agent in 40 s on an idle core (2-3 minutes on a busy one).
        sac_steps: SAC env steps in all.
        net_arch: Hidden layers of the agent (DRACO's).
        learning_rate: PPO's Adam step size.
        ent_coef: PPO's entropy bonus. With SB3's defaults (3e-4, none) the agent learnt to head for one goal
            whatever goal it was given, on MiniGrid-Optimal at 40 000-100 000 steps (3 seeds): once one goal is
            found from the sparse reward, nothing keeps it exploring for the other. With 1e-3 and 0.05 it
            reaches both goals on 2 of 3 seeds at 60 000 and at 100 000 steps (the third still heads for one).
        off_support: GC-BC's rule for a goal's outputs at states off its support when scored (``"trust"``: the
            agent's own output, the published method); scoring only.
    """

    algorithm: Literal["auto", "ppo", "sac"] = "auto"
    ppo_steps: Annotated[int, Range(1, 100_000_000)] = 100_000
    sac_steps: Annotated[int, Range(1, 100_000_000)] = 30_000
    net_arch: Annotated[tuple[int, ...], Range(1, 4096)] = (64, 64)
    learning_rate: float = 1e-3
    ent_coef: float = 0.05
    off_support: Literal["trust", "stay", "uniform"] = field(default="trust", metadata={"scoring": True})

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise UserError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {self.algorithm!r}")
        if self.ppo_steps < 1 or self.sac_steps < 1 or not self.net_arch or min(self.net_arch) < 1:
            raise UserError("step budgets and hidden layer sizes must be positive")
        if not self.learning_rate > 0 or not self.ent_coef >= 0:
            raise UserError(f"learning_rate must be > 0 and ent_coef >= 0, got {self.learning_rate} and "
                            f"{self.ent_coef}")
        object.__setattr__(self, "net_arch", tuple(self.net_arch))


#: Discrete state spaces with at most this many states have every (goal, state)'s features encoded once.
TABLE_STATES = 4096


class GoalSampling(gym.Env):
    """The env of a training goal drawn per episode, its observation the state and goal as the encoder gives them.

    Args:
        env_factory: Builds each goal's env (its dynamics and reward).
        goals: The training goals, drawn uniformly at each reset.
        encoder: Turns (state, goal) into the agent's input.
    """

    def __init__(self, env_factory: EnvFactory, goals: Sequence[Goal], encoder: GoalEncoder) -> None:
        self.goals = list(goals)
        self.envs = [env_factory(g) for g in self.goals]
        self.encoder = encoder
        self.observation_space = encoder.space()
        self.action_space = self.envs[0].action_space
        self._goal = 0
        space = self.envs[0].observation_space
        self._states = space if _small_discrete(space) else None
        self._table = encoder.encode(all_states(space), self.goals) if self._states is not None else None

    def _features(self, obs: np.ndarray) -> np.ndarray:
        if self._table is not None:
            return self._table[self._goal, state_index(np.asarray(obs)[None], self._states)[0]]
        return self.encoder.encode(np.asarray(obs)[None], [self.goals[self._goal]])[0, 0]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._goal = int(self.np_random.integers(len(self.goals)))
        obs, info = self.envs[self._goal].reset(seed=int(self.np_random.integers(2**31)), options=options)
        return self._features(obs), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.envs[self._goal].step(action)
        return self._features(obs), reward, terminated, truncated, info

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _small_discrete(space: spaces.Space) -> bool:
    discrete = isinstance(space, spaces.Discrete) or (isinstance(space, spaces.MultiDiscrete) and space.nvec.ndim == 1)
    return discrete and n_states(space) <= TABLE_STATES


class GCDRACORecognizer(GCBCRecognizer):
    """GC-DRACO: one goal-conditioned PPO (discrete actions) or SAC (continuous) agent on the env's reward.

    Settings: :class:`GCDRACOConfig`. Its ``scorer`` defaults to ``"wasserstein"`` (DRACO's); any scorer the
    agent's outputs can serve.
    """

    name = "gc-draco"
    paper_name = "GC-DRACO"
    default_scorer = "wasserstein"
    Config = GCDRACOConfig
    config: GCDRACOConfig

    def __init__(self, scorer: str | None = None, **settings: Any) -> None:
        super().__init__(scorer=scorer, **settings)
        self.agent: BasePolicy | None = None  # the trained agent's policy (SB3), on the encoder's features
        self._locate: Callable[[Goal], np.ndarray] | None = None

    def exposes(self, action_space: Any) -> frozenset[str]:
        """As GC-BC; SAC on discrete actions is refused here, where a run is planned, rather than at fit."""
        self._algorithm(action_space)
        return super().exposes(action_space)

    def _algorithm(self, action_space: spaces.Space) -> str:
        continuous = isinstance(action_space, spaces.Box)
        if self.config.algorithm == "sac" and not continuous:
            raise UserError(f"{self.name}: SAC needs continuous actions; use algorithm=ppo or auto on this domain")
        if self.config.algorithm == "auto":
            return "sac" if continuous else "ppo"
        return self.config.algorithm

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0,
            cache_key: str | None = None) -> FitReport:
        """Train the one agent by RL over the goals of ``demos`` (see :class:`grail_bench.Recognizer`).

        The demonstrations are not trained on: their goals are, each episode's drawn at random. The result does
        not depend on the order the goals are listed in. With a ``cache_key`` the agent is cached on disk, keyed
        by the env, the goals, the seed and the settings (every regime of a domain shares it, as DRACO's).
        """
        if len(demos) < 2:
            raise UserError(f"{self.name}: need at least two goals to train on, got {len(demos)}")
        if env_factory is None:
            raise UserError(f"{self.name}: learns by interaction and needs the env factory")
        self.learn_evidence(demos, env_factory)  # before training: a setting the domain cannot serve fails first
        ordered = sorted(tuple(g) for g in demos)
        probe = env_factory(ordered[0])
        observation_space, action_space = probe.observation_space, probe.action_space
        probe.close()
        algorithm = self._algorithm(action_space)
        self._locate = goal_locator(env_factory, ordered[0])
        encoder = GoalEncoder(observation_space, ordered, self._locate)
        net_arch = list(self.config.net_arch)

        def train() -> tuple[dict[str, Any], dict[str, Any]]:
            torch.manual_seed(seed)
            if algorithm == "sac":
                model = make_sac(GoalSampling(env_factory, ordered, encoder), net_arch, seed)
                steps = self.config.sac_steps
            else:
                model = make_ppo(lambda: GoalSampling(env_factory, ordered, encoder), net_arch, seed,
                                 learning_rate=self.config.learning_rate, ent_coef=self.config.ent_coef)
                steps = self.config.ppo_steps
            state, returns = learn(model, steps)
            model.get_env().close()
            trained["policy"] = model.policy
            return state, {"curves": {"return": returns}}

        trained: dict[str, BasePolicy] = {}
        key = {"recognizer": self.name, "config": settings_key(self.config, models=True), "algorithm": algorithm,
               "env": cache_key, "seed": seed, "goals": [list(g) for g in ordered],
               "versions": [version("stable-baselines3"), version("torch")]}
        if algorithm == "ppo" and isinstance(action_space, spaces.Box):
            key["update"] = "numpy"  # keyed apart from agents SB3's update trained (discrete ones always had numpy's)
        with single_thread():
            if cache_key is None:
                start = time.perf_counter()
                _, extra = train()
                seconds, reused = time.perf_counter() - start, False
            else:
                entry = cached(f"policy-{self.name}", key, train)
                seconds, reused, extra = entry.seconds, entry.reused, entry.extra
                if reused:
                    trained["policy"] = empty_policy(algorithm, encoder.space(), action_space, net_arch)
                    trained["policy"].load_state_dict(entry.state)
        self.agent = trained["policy"]
        self.agent.set_training_mode(False)
        self.encoder, self.bank = encoder, PolicyBank([self.agent])
        self.observation_space, self.action_space = observation_space, action_space
        self.goals = list(demos)
        self.curves = {g: dict(extra.get("curves") or {}) for g in self.goals}
        return FitReport(train_seconds=seconds, trained=0 if reused else 1, reused=int(reused))

    def set_goals(self, goals: Sequence[Goal]) -> None:
        """Score these candidate goals from now on, trained on or not (gr_libs' goal adaptation phase): each new
        goal is located in the state once, here, rather than at its first scoring.

        Raises:
            grail_bench.recognizers.scored.NotFittedError: Before :meth:`fit`.
            UserError: For goals of the wrong dimension.
        """
        super().set_goals(goals)
        if self._locate is not None:
            for goal in self.goals:
                self.encoder.position(goal)
