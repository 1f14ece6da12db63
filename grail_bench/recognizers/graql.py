"""GRAQL (Amado et al. 2022): tabular Q-learning per goal, KL-divergence scoring."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Annotated, Any, Callable, Mapping, Sequence

import numpy as np
from gymnasium import spaces
from grail_bench.core.trajectory import Trajectory
from scipy.special import softmax

from grail_bench.core.cache import cached
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.seeding import goal_seed
from grail_bench.core.spaces import n_states, state_index
from grail_bench.core.tabular import TabularDynamics
from grail_bench.core.trajectory import EnvFactory, Goal
from grail_bench.recognizers.contract import FitReport, settings_key
from grail_bench.recognizers.scored import ScoredRecognizer
from grail_bench.recognizers.scoring import PolicyOutput
from grail_bench.stats.metrics import thin

_CHUNK = 4096  # exploration draws made at a time


#: The most states a Q-table holds (its rows live in Python lists: 2**20 rows of 20 actions take ~0.7 GB).
MAX_STATES = 1 << 20

@dataclass(frozen=True)
class GRAQLConfig:
    """GRAQL's settings.

    Attributes:
        episodes: Q-learning episodes per goal.
        alpha: Learning rate.
        gamma: Discount factor.
        epsilon_start: Initial exploration rate of the epsilon-greedy policy.
        epsilon_end: Final exploration rate, reached after 80 % of the episodes.
        temperature: Of the softmax turning Q-values into a policy.
        max_episode_steps: Cut episodes after this many steps; ``None``: the env's own horizon (left out of
            the configuration's key unless set).
    """

    episodes: Annotated[int, Range(1, 10_000_000)] = 15_000
    alpha: float = 0.5
    gamma: float = 0.9
    epsilon_start: float = 1.0
    epsilon_end: float = 0.05
    temperature: float = 1.0
    max_episode_steps: Annotated[int, Range(1, 100_000)] | None = field(default=None, metadata={"omit_none": True})

    def __post_init__(self) -> None:
        if self.episodes < 1 or not 0 < self.alpha <= 1 or not 0 < self.gamma <= 1 or not self.temperature > 0:
            raise UserError("need episodes >= 1, alpha and gamma in (0, 1], temperature > 0")
        if not 0 <= self.epsilon_end <= 1 or not 0 <= self.epsilon_start <= 1:
            raise UserError(f"epsilon_start and epsilon_end must be in [0, 1], got {self.epsilon_start} "
                            f"and {self.epsilon_end}")
        if self.max_episode_steps is not None and self.max_episode_steps < 1:
            raise UserError(f"max_episode_steps must be positive, got {self.max_episode_steps}")


class GRAQLRecognizer(ScoredRecognizer):
    """GRAQL: Q-learning on the environment's own reward, then KL scoring.

    It learns from interaction only (the demonstrations are ignored), so the
    same Q-tables serve every behaviour regime of a domain. A step counts as
    terminal when the env terminates or reports ``info["is_success"]``; an
    episode runs until the env ends it (every GRAIL domain has a fixed
    horizon) or ``max_episode_steps``. It needs discrete observations: on a
    continuous domain ``fit`` refuses with an error saying so.

    The defaults were chosen on MiniGrid. The episodes (the paper states none)
    are the plateau of the budget study (docs/guides/budgets.md): 15000 is
    the smallest budget whose F1 reaches the best budget's 95 % interval on
    both 6-goal tasks (5000, the earlier default, reached it on the optimal
    task only). On MiniGrid, whose env offers its dynamics as tables, 15000
    episodes take about 0.5 s per goal. At 5000 episodes the greedy policy already
    reaches every goal on a shortest path; a discount of 0.95-0.99 or a smaller
    learning rate left some goals unreached.

    Settings: :class:`GRAQLConfig`. Its ``scorer`` defaults to ``"kl"`` (GRAQL's); it exposes softmax(Q)
    probabilities and Q-values.
    """

    name = "graql"
    paper_name = "GRAQL"
    default_scorer = "kl"
    Config = GRAQLConfig
    config: GRAQLConfig

    def __init__(self, scorer: str | None = None, **settings: Any) -> None:
        super().__init__(scorer=scorer, **settings)
        self.q: np.ndarray | None = None  # (K, S, A)
        self.visited: np.ndarray | None = None  # (K, S)
        self.probs: np.ndarray | None = None  # (K, S, A), the policy scoring reads, computed once per fit
        self.observation_space: spaces.Space | None = None
        self.action_space: spaces.Space | None = None

    def fit(self, demos: Mapping[Goal, Sequence[Trajectory]], env_factory: EnvFactory, *, seed: int,
            cache_key: str | None = None) -> FitReport:
        """Learn one Q-table per goal by interacting with ``env_factory(goal)``.

        With a ``cache_key`` (the harness passes one), the tables are cached
        on disk, keyed by the domain env, goal, seed and configuration (not the
        demonstrations, which GRAQL ignores), so every regime and goal set of
        a domain shares them.
        """
        tables, visits, seconds, reused, curves = [], [], 0.0, 0, {}
        for goal in demos:
            env = env_factory(goal)
            try:
                own_seed = goal_seed(seed, goal)
                if cache_key is None:
                    start = time.perf_counter()
                    q, v, returns = self._q_learning(env, own_seed)
                    cost, hit = time.perf_counter() - start, False
                else:
                    key = {"recognizer": self.name, "config": settings_key(self.config), "env": cache_key, "goal": list(goal),
                           "seed": own_seed}
                    entry = cached(f"policy-{self.name}", key, lambda: self._train(env, own_seed), arrays=True,
                                   check=lambda state, env=env: _check_tables(state, env))
                    q, v, cost, hit = entry.state["q"], entry.state["visited"], entry.seconds, entry.reused
                    returns = entry.extra.get("return", [])
                    self.observation_space, self.action_space = env.observation_space, env.action_space
            finally:
                env.close()
            tables.append(q)
            visits.append(v)
            if returns:
                curves[goal] = {"return": list(returns)}
            seconds += cost
            reused += hit
        self.goals = list(demos)
        self.q, self.visited, self.curves = np.stack(tables), np.stack(visits), curves
        self.probs = self._softmax_policy(self.q, self.visited)
        return FitReport(train_seconds=seconds, trained=len(tables) - reused, reused=reused)

    def _train(self, env: Any, seed: int) -> tuple[dict[str, np.ndarray], dict[str, list[float]]]:
        """The tables to cache, and the episode returns kept beside them."""
        q, visited, returns = self._q_learning(env, seed)
        return {"q": q, "visited": visited}, {"return": returns}

    def _q_learning(self, env: Any, seed: int) -> tuple[np.ndarray, np.ndarray, list[float]]:
        """Q-table, visited states and the episode returns (thinned to a short curve).

        An env offering ``tabular_dynamics()`` (:class:`~grail_bench.core.tabular.TabularDynamics`) is not
        stepped: its tables give the same transitions, rewards and episode ends, and so the same Q-table, at a
        fraction of the cost. Either way the table lives in Python lists, whose float arithmetic is numpy's.
        """
        obs_space, act_space = env.observation_space, env.action_space
        if not isinstance(obs_space, (spaces.Discrete, spaces.MultiDiscrete)) or not isinstance(act_space, spaces.Discrete):
            raise UserError("graql needs discrete observations and actions (tabular Q-learning); this domain's "
                            f"observations are {type(obs_space).__name__} and actions {type(act_space).__name__}")
        if n_states(obs_space) > MAX_STATES:
            raise UserError(f"graql keeps a Q-table row for every state: this domain's observations have "
                            f"{n_states(obs_space):.3g} states, more than the {MAX_STATES} it holds")
        self.observation_space, self.action_space = obs_space, act_space
        reset, step = _transitions(env)
        cfg = self.config
        rng = np.random.default_rng(seed)
        n_actions = int(act_space.n)
        # Tiny random initial values break argmax ties without a per-step draw.
        q = rng.uniform(0, 1e-6, size=(n_states(obs_space), n_actions)).tolist()
        visited = np.zeros(n_states(obs_space), dtype=bool)
        alpha, gamma = cfg.alpha, cfg.gamma
        decay_episodes = max(1, int(0.8 * cfg.episodes))
        limit = cfg.max_episode_steps
        returns = []
        for episode in range(cfg.episodes):
            frac = min(1.0, episode / decay_episodes)
            epsilon = cfg.epsilon_start + frac * (cfg.epsilon_end - cfg.epsilon_start)
            s = reset(int(rng.integers(1 << 31)) if episode == 0 else None)
            t, episode_return = 0, 0.0
            while True:
                if t % _CHUNK == 0:  # indexed, not converted: an episode reads a few of the draws
                    explore, random_actions = rng.random(_CHUNK), rng.integers(n_actions, size=_CHUNK)
                row = q[s]
                a = int(random_actions[t % _CHUNK]) if explore[t % _CHUNK] < epsilon else row.index(max(row))
                t += 1
                s2, reward, done, truncated = step(s, a, t)
                target = reward if done else reward + gamma * max(q[s2])
                row[a] += alpha * (target - row[a])
                visited[s] = True
                s, episode_return = s2, episode_return + reward
                if done or truncated or t == limit:
                    break
            returns.append(episode_return)
        return np.array(q), visited, thin(returns)

    def _softmax_policy(self, q: np.ndarray, visited: np.ndarray) -> np.ndarray:
        """Boltzmann policy of every state, ``(K, S, A)``; uniform in states never visited in training."""
        probs = softmax(q / self.config.temperature, axis=-1)
        probs[~visited] = 1.0 / probs.shape[-1]
        return probs

    def exposes(self, action_space: Any) -> frozenset[str]:
        """Softmax(Q) probabilities and Q-values; continuous actions are refused here, where a run is planned,
        rather than when its fit starts (:meth:`fit` checks the observations too)."""
        if not isinstance(action_space, spaces.Discrete):
            raise UserError("graql needs discrete observations and actions (tabular Q-learning); this domain's "
                            f"actions are {type(action_space).__name__}")
        return frozenset({"probs", "q"})

    def outputs_at(self, states: np.ndarray) -> PolicyOutput:
        idx = state_index(states, self.observation_space)
        return PolicyOutput(probs=self.probs[:, idx], q=self.q[:, idx])


Reset = Callable[[int | None], int]
Step = Callable[[int, int, int], tuple[int, float, bool, bool]]


def _transitions(env: Any) -> tuple[Reset, Step]:
    """``reset(seed) -> state`` and ``step(state, action, t) -> (next state, reward, done, truncated)``.

    ``t`` counts the episode's steps, this one included. A step is done when the env terminates or reports
    ``info["is_success"]``. From the env's ``tabular_dynamics()`` where an unwrapped env offers them, else by
    stepping it.
    """
    if env is env.unwrapped and callable(getattr(env, "tabular_dynamics", None)):  # a wrapper may change them
        dynamics: TabularDynamics = env.tabular_dynamics()
        nxt, success = dynamics.next_state.tolist(), dynamics.success.tolist()
        start, horizon, success_reward = dynamics.start, dynamics.horizon, dynamics.success_reward

        def table_step(s: int, a: int, t: int) -> tuple[int, float, bool, bool]:
            done = success[s][a]
            return nxt[s][a], success_reward(t) if done else 0.0, done, t >= horizon

        return (lambda seed: start), table_step

    space = env.observation_space

    def env_reset(seed: int | None) -> int:
        obs, _ = env.reset(seed=seed)
        return int(state_index(obs[None], space)[0])

    def env_step(s: int, a: int, t: int) -> tuple[int, float, bool, bool]:
        obs, reward, terminated, truncated, info = env.step(a)
        return int(state_index(obs[None], space)[0]), reward, terminated or bool(info.get("is_success")), truncated

    return env_reset, env_step


def _check_tables(state: dict[str, Any], env: Any) -> None:
    """Refuse cached tables that do not fit ``env``: a ``(states, actions)`` Q-table and a ``(states,)`` visited
    flag per state."""
    size = n_states(env.observation_space)
    if set(state) != {"q", "visited"}:
        raise ValueError(f"it holds {sorted(state)}, not the Q-table and visited states")
    if state["q"].shape != (size, int(env.action_space.n)) or state["q"].dtype.kind != "f":
        raise ValueError(f"its Q-table has shape {state['q'].shape}, not {(size, int(env.action_space.n))}")
    if state["visited"].shape != (size,) or state["visited"].dtype.kind != "b":
        raise ValueError(f"its visited states have shape {state['visited'].shape}, not {(size,)}")
