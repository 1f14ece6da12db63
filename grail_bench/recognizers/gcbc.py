"""GC-BC: one goal-conditioned behavioural-cloning policy for every goal, including goals it never saw.

Per-goal GRAIL trains a policy per candidate goal, so its cost grows with the
goal set and a new goal means new training. GC-BC trains one policy
``pi(a | s, g)`` on every training goal's demonstrations, the goal given as an
input, and scores an observation against each candidate goal by feeding that
goal in: the same scorers (MSE, KL, ...) then apply to its outputs per goal.
Its budget is a fixed number of gradient steps, so its fit cost does not grow
with the number of goals; and a goal without demonstrations can be scored
(:meth:`GCBCRecognizer.set_goals`), which the ``zero-shot`` mode measures.

Inputs: the state as SB3 encodes it (one-hot for discrete spaces), for
discrete spaces also the raw coordinates scaled to [0, 1], the goal's
coordinates standardised with the training goals' mean and spread, and, when
the domain's env says where a goal lies in its state (``goal_in_state``: every
built-in domain does), the goal relative to the agent: that position minus the
state's first coordinates. The relative goal is what lets the policy act
towards a goal it never saw ("the goal is north: go north").
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Annotated, Any, Callable, Mapping, Sequence

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy

from grail_bench.core.cache import cached
from grail_bench.core.provenance import model_versions
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.scaling import scale_of
from grail_bench.core.torchutil import single_thread
from grail_bench.core.trajectory import Demos, EnvFactory, Goal, Trajectory, demos_digest, flatten, until_success
from grail_bench.recognizers.bc import train_bc
from grail_bench.recognizers.contract import FitReport, settings_key
from grail_bench.recognizers.policy import spaces_of
from grail_bench.recognizers.policy_bank import PolicyBank, preprocess
from grail_bench.recognizers.evidence import OffSupport, off_support_setting
from grail_bench.recognizers.contract import NotFittedError
from grail_bench.recognizers.scored import ActionBox, ScoredRecognizer, action_box_setting
from grail_bench.recognizers.scoring import PolicyOutput


class GoalEncoder:
    """Turns (state, goal) pairs into the policy's input features.

    Args:
        observation_space: The domain env's observation space.
        goals: The training goals; their mean and spread standardise every goal's coordinates.
        locate: A goal's position in the state's coordinates (the state's first entries), or None when the
            domain does not say: then no relative goal.
    """

    def __init__(self, observation_space: spaces.Space, goals: Sequence[Goal],
                 locate: Callable[[Goal], np.ndarray] | None = None) -> None:
        self.observation_space = observation_space
        self.mean, self.scale = _standardiser(np.asarray(goals, dtype=np.float64))
        if isinstance(observation_space, spaces.MultiDiscrete):
            self._raw = np.maximum(observation_space.nvec - 1, 1).astype(np.float32)
        elif isinstance(observation_space, spaces.Discrete):
            self._raw = np.array([max(int(observation_space.n) - 1, 1)], dtype=np.float32)
        else:
            self._raw = None  # Box states enter as they are
        self._locate, self._positions = locate, {}
        self._relative_scale = np.ones(0)
        if locate is not None:
            located = np.stack([self.position(g) for g in goals])
            # Relative positions in grid cells over the grid's size, or over the training goals' spread.
            self._relative_scale = (self._raw[:located.shape[1]] if self._raw is not None
                                    else _standardiser(located)[1])

    @property
    def size(self) -> int:
        """Number of input features."""
        space = self.observation_space
        if isinstance(space, spaces.MultiDiscrete):
            state = int(space.nvec.sum())
        elif isinstance(space, spaces.Discrete):
            state = int(space.n)
        else:
            state = int(np.prod(space.shape))
        return state + (len(self._raw) if self._raw is not None else 0) + len(self.mean) + len(self._relative_scale)

    def position(self, goal: Goal) -> np.ndarray:
        """``goal``'s position in the state's coordinates (located once per goal)."""
        key = tuple(goal)
        if key not in self._positions:
            self._positions[key] = np.asarray(self._locate(key), dtype=np.float64)
        return self._positions[key]

    def goal_features(self, goals: Sequence[Goal]) -> np.ndarray:
        """``(K, G)`` standardised goal coordinates."""
        return ((np.asarray(goals, dtype=np.float64) - self.mean) / self.scale).astype(np.float32)

    def encode(self, states: np.ndarray, goals: Sequence[Goal]) -> np.ndarray:
        """``(K, T, F)`` features of every state paired with every goal."""
        parts = [preprocess(states, self.observation_space)]
        if self._raw is not None:
            parts.append(np.asarray(states, dtype=np.float32).reshape(len(states), -1) / self._raw)
        base = np.concatenate(parts, axis=1)  # (T, P)
        goal = self.goal_features(goals)  # (K, G)
        parts = [np.broadcast_to(base, (len(goal), *base.shape)),
                 np.broadcast_to(goal[:, None, :], (len(goal), len(base), goal.shape[1]))]
        if self._locate is not None:
            parts.append(self.relative(states, goals))
        return np.concatenate(parts, axis=2)

    def relative(self, states: np.ndarray, goals: Sequence[Goal]) -> np.ndarray:
        """``(K, T, P)`` each goal's position minus the agent's (the state's first ``P`` coordinates), scaled."""
        located = np.stack([self.position(g) for g in goals])  # (K, P)
        agent = np.asarray(states, dtype=np.float64).reshape(len(states), -1)[:, :located.shape[1]]
        return ((located[:, None, :] - agent[None]) / self._relative_scale).astype(np.float32)

    def space(self) -> spaces.Box:
        """The features' space, as the policy is built for it."""
        return spaces.Box(-np.inf, np.inf, shape=(self.size,), dtype=np.float32)


def _standardiser(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and spread of ``(N, D)`` points; a coordinate they all share keeps scale 1 (:func:`scale_of`)."""
    return points.mean(axis=0), scale_of(points)


def goal_locator(env_factory: EnvFactory, goal: Goal) -> Callable[[Goal], np.ndarray] | None:
    """Where a goal lies in the state, read from the domain env (``goal_in_state``), or None if it does not say."""
    probe = env_factory(goal)
    try:
        if not hasattr(probe.unwrapped, "goal_in_state"):
            return None
    finally:
        probe.close()

    def locate(g: Goal) -> np.ndarray:
        env = env_factory(g)
        try:
            return np.asarray(env.unwrapped.goal_in_state, dtype=np.float64)
        finally:
            env.close()

    return locate


@dataclass(frozen=True)
class GCBCConfig:
    """GC-BC's settings.

    Attributes:
        n_batches: Gradient steps; the budget, the same whatever the number of goals.
        batch_size: Transitions per step.
        learning_rate: Adam's step size.
        ent_weight: imitation's entropy regulariser weight (its default).
        hidden: Units of each of the two tanh hidden layers.
        off_support: What the policy outputs for a goal at states off that goal's support when scored:
            ``"trust"`` (its own output), ``"stay"`` (the domain's no-op) or ``"uniform"`` (no preference); see
            :class:`~grail_bench.recognizers.evidence.Evidence`. A goal without demonstrations (zero-shot) has no
            support: every state is off it. Scoring only: the trained policy is shared across its values.
        action_box: ``"ignore"`` (the mean as it is: the published method) or ``"clip"`` (the mean clipped to the
            env's action box, as SB3's deterministic ``predict`` returns it); continuous actions only, scoring
            only (:func:`~grail_bench.recognizers.scored.action_box_setting`).
    """

    n_batches: Annotated[int, Range(1, 10_000_000)] = 4000
    batch_size: Annotated[int, Range(1, 1_000_000)] = 32
    learning_rate: float = 1e-3
    ent_weight: float = 1e-3
    hidden: Annotated[int, Range(1, 4096)] = 64
    off_support: OffSupport = off_support_setting()
    action_box: ActionBox = action_box_setting()

    def __post_init__(self) -> None:
        if self.n_batches < 1 or self.batch_size < 1 or self.hidden < 1 or self.learning_rate <= 0:
            raise UserError("n_batches, batch_size and hidden must be positive, learning_rate > 0")


class GCBCRecognizer(ScoredRecognizer):
    """GC-BC: one goal-conditioned BC policy (imitation 1.0.1's ``bc.BC`` loop) trained on every goal's demonstrations.

    Settings: :class:`GCBCConfig`. Its ``scorer`` defaults to ``"mse"`` (as BC-GRAIL); any scorer the
    policy can serve.
    """

    name = "gc-bc"
    paper_name = "GC-BC"
    Config = GCBCConfig
    config: GCBCConfig

    def __init__(self, scorer: str | None = None, **settings: Any) -> None:
        super().__init__(scorer=scorer, **settings)
        self.encoder: GoalEncoder | None = None
        self.bank: PolicyBank | None = None

    def _new_policy(self, encoder: GoalEncoder, action_space: spaces.Space) -> ActorCriticPolicy:
        hidden = self.config.hidden
        return ActorCriticPolicy(encoder.space(), action_space, lambda _: self.config.learning_rate,
                                 net_arch=[hidden, hidden])

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0,
            cache_key: str | None = None) -> FitReport:
        """Train the one policy on every goal's demonstrations (see :class:`grail_bench.Recognizer`).

        The result does not depend on the order the goals are listed in. With a ``cache_key``, the policy is
        cached on disk like per-goal policies.
        """
        if len(demos) < 2:
            raise UserError(f"{self.name}: need demonstrations of at least two goals, got {len(demos)}")
        if env_factory is None:
            raise UserError(f"{self.name}: needs the env factory, to read the observation and action spaces")
        self.learn_evidence(demos, env_factory)  # before training: a setting the domain cannot serve fails first
        ordered = sorted(tuple(g) for g in demos)  # the training set's order: by goal, not as listed
        observation_space, action_space = spaces_of(env_factory, ordered[0])
        encoder = GoalEncoder(observation_space, ordered, goal_locator(env_factory, ordered[0]))

        def train() -> tuple[dict[str, Any], dict[str, Any]]:
            torch.manual_seed(seed)
            policy, curves = train_bc(self._new_policy(encoder, action_space), *self._pairs(encoder, demos, ordered),
                                      batch_size=self.config.batch_size,
                                      learning_rate=self.config.learning_rate, ent_weight=self.config.ent_weight,
                                      n_batches=self.config.n_batches)
            trained["policy"] = policy
            return policy.state_dict(), {"curves": curves}

        trained: dict[str, ActorCriticPolicy] = {}
        with single_thread():
            if cache_key is None:
                start = time.perf_counter()
                _, extra = train()
                seconds, reused = time.perf_counter() - start, False
            else:
                key = {"recognizer": self.name, "config": settings_key(self.config, models=True),
                       "inputs": "state+goal+relative",
                       "env": cache_key, "seed": seed,
                       "goals": [list(g) for g in ordered], "demos": [demos_digest(demos[g]) for g in ordered],
                       "versions": model_versions()}
                loaded: dict[str, Any] = {}

                def check(state: dict[str, Any]) -> None:  # a wrong key or shape: the entry is retrained
                    loaded["policy"] = self._new_policy(encoder, action_space)
                    loaded["policy"].load_state_dict(state)

                entry = cached(f"policy-{self.name}", key, train, check=check)
                seconds, reused, extra = entry.seconds, entry.reused, entry.extra
                if reused:
                    trained["policy"] = loaded["policy"]
        self.encoder, self.bank = encoder, PolicyBank([trained["policy"]])
        self.observation_space, self.action_space = observation_space, action_space
        self.goals = list(demos)
        self.curves = {g: dict(extra.get("curves") or {}) for g in self.goals}
        return FitReport(train_seconds=seconds, trained=0 if reused else 1, reused=int(reused))

    @staticmethod
    def _pairs(encoder: GoalEncoder, demos: Mapping[Goal, Sequence[Trajectory]],
               ordered: Sequence[Goal]) -> tuple[np.ndarray, np.ndarray]:
        """Every goal's (features, action) pairs, cut after the goal is reached, in goal order."""
        obs, acts = [], []
        for goal in ordered:
            goal_obs, goal_acts = flatten([until_success(t) for t in demos[goal]])
            obs.append(encoder.encode(goal_obs, [goal])[0])
            acts.append(goal_acts)
        return np.concatenate(obs), np.concatenate(acts)

    def set_goals(self, goals: Sequence[Goal]) -> None:
        """Score these candidate goals from now on, whether or not they had demonstrations (zero-shot).

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For goals of the wrong dimension.
        """
        if self.encoder is None:
            raise NotFittedError(f"{self.name}: call fit() before set_goals()")
        goals = [tuple(g) for g in goals]
        if not goals or any(len(g) != len(self.encoder.mean) for g in goals):
            raise UserError(f"{self.name}: candidate goals need {len(self.encoder.mean)} coordinates each")
        self.goals = goals

    def exposes(self, action_space: Any) -> frozenset[str]:
        """Action probabilities or mean and std, and every goal's state occupancy in its training demonstrations
        (a goal without demonstrations: the prior alone, uniform over the observation space)."""
        policy = {"probs"} if isinstance(action_space, spaces.Discrete) else {"mean", "std"}
        return frozenset(policy | {"occupancy"})

    def outputs_at(self, states: np.ndarray) -> PolicyOutput:
        outputs = self.bank.outputs_of(self.encoder.encode(states, self.goals))
        if self.bank.discrete:
            return PolicyOutput(probs=outputs[0])
        return PolicyOutput(mean=outputs[0], std=outputs[1])
