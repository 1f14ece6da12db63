"""BC-GRAIL: one behavioural-cloning policy per goal (imitation 1.0.1's ``bc.BC`` loop, :mod:`grail_bench.core.bc_update`)."""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal, Mapping, Sequence

import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy

from grail_bench.core import bc_update
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import EnvFactory, Goal, Trajectory, flatten, until_success
from grail_bench.recognizers.policy import PolicyRecognizer, Trained, spaces_of
from grail_bench.recognizers.evidence import OffSupport, off_support_setting
from grail_bench.recognizers.scored import ActionBox, action_box_setting
from grail_bench.stats.metrics import thin


@dataclass(frozen=True)
class BCConfig:
    """BC-GRAIL's settings (the paper's hyperparameters where it states them).

    Attributes:
        n_epochs: Passes over the demonstrations (the paper states none). 100 is the plateau of the
            budget study (docs/guides/budgets.md): the smallest budget whose F1 reaches the best
            budget's 95 % interval on both MiniGrid 6-goal tasks (2-6 s per goal there; 25, the
            earlier default, left MiniGrid-Optimal-6Goals 0.21 F1 lower).
        batch_size: Paper: 8.
        learning_rate: Paper: 1e-3 (Adam).
        ent_weight: imitation's entropy regulariser weight (its default).
        off_support: What a goal's policy outputs at states off its goal's support when scored: ``"trust"``
            (its own output: the paper's method), ``"stay"`` (the domain's no-op) or ``"uniform"`` (no
            preference); see :class:`~grail_bench.recognizers.evidence.Evidence`. Scoring only: the trained
            policies are shared across its values.
        action_box: ``"ignore"`` (the mean as it is: the published method) or ``"clip"`` (the mean clipped to the
            env's action box, as SB3's deterministic ``predict`` returns it); continuous actions only, scoring
            only (:func:`~grail_bench.recognizers.scored.action_box_setting`).
        augment: ``"none"`` (the paper's method) or ``"stay"``: goal ``g``'s policy also learns the domain's
            no-op at every distinct training state of the other goals that lies off ``g``'s support (pairs
            ``(s, no-op)`` added once each to its demonstrations' pairs), so it learns to stay where its goal
            has no evidence. It changes training: its models are cached apart, keyed by those states too.
    """

    n_epochs: Annotated[int, Range(1, 100_000)] = 100
    batch_size: Annotated[int, Range(1, 1_000_000)] = 8
    learning_rate: float = 1e-3
    ent_weight: float = 1e-3
    off_support: OffSupport = off_support_setting()
    action_box: ActionBox = action_box_setting()
    augment: Literal["none", "stay"] = field(default="none", metadata={"omit_default": True})

    def __post_init__(self) -> None:
        if self.n_epochs < 1 or self.batch_size < 1 or self.learning_rate <= 0:
            raise UserError("n_epochs and batch_size must be positive, learning_rate > 0")


class BCRecognizer(PolicyRecognizer):
    """BC-GRAIL with the paper's hyperparameters (settings: :class:`BCConfig`).

    Each goal's policy is imitation 1.0.1's default BC policy (an SB3 actor-critic
    MLP with two hidden layers of 32 tanh units) trained by supervised
    learning on that goal's demonstrations, cut after the goal is reached
    (with ``augment="stay"``, plus the no-op at the other goals' states off its
    support). Its ``scorer`` defaults to ``"mse"`` (the paper's); any scorer the policies can serve.
    """

    name = "bc"
    paper_name = "BC-GRAIL"
    Config = BCConfig
    config: BCConfig
    #: Train the goals a fit needs together (:meth:`train_policies`); False trains them one by one (the same
    #: weights, slower).
    stacked: bool = True

    def new_policy(self, goal: Goal, env_factory: EnvFactory) -> ActorCriticPolicy:
        observation_space, action_space = spaces_of(env_factory, goal)
        return bc_update.bc_policy(observation_space, action_space, self.config.learning_rate)

    def noop_settings(self) -> list[str]:
        return super().noop_settings() + (["augment='stay'"] if self.config.augment == "stay" else [])

    def augmented_states(self, goal: Goal) -> np.ndarray:
        """The states at which ``goal``'s policy also learns the no-op (none unless ``augment="stay"``)."""
        if self.config.augment == "none":
            return np.empty((0,))
        return self.evidence.others_off_support(goal)

    def model_key(self, goal: Goal) -> dict[str, Any]:
        if self.config.augment == "none":
            return {}
        states = np.ascontiguousarray(self.augmented_states(goal))
        digest = hashlib.sha256(states.tobytes() + repr((states.dtype.str, states.shape)).encode()).hexdigest()
        return {"augmented": digest, "noop": np.asarray(self.evidence.noop).tolist()}

    def pairs(self, goal: Goal, demos: Sequence[Trajectory]) -> tuple[np.ndarray, np.ndarray]:
        """The ``(obs, acts)`` pairs ``goal``'s policy learns: its demonstrations cut at success, plus the
        :meth:`augmented_states` with the no-op."""
        obs, acts = flatten([until_success(t) for t in demos])
        extra = self.augmented_states(goal)
        if len(extra):
            noop = np.broadcast_to(np.asarray(self.evidence.noop, dtype=acts.dtype), (len(extra), *acts.shape[1:]))
            obs, acts = np.concatenate([obs, extra.astype(obs.dtype)]), np.concatenate([acts, noop])
        return obs, acts

    def train_policy(self, goal: Goal, demos: Sequence[Trajectory], env_factory: EnvFactory,
                     seed: int) -> tuple[ActorCriticPolicy, dict[str, list[float]]]:
        obs, acts = self.pairs(goal, demos)
        policy = self.new_policy(goal, env_factory)
        cfg = self.config
        return train_bc(policy, obs, acts, batch_size=cfg.batch_size, learning_rate=cfg.learning_rate,
                        ent_weight=cfg.ent_weight, n_epochs=cfg.n_epochs)

    def train_policies(self, jobs: Mapping[Goal, tuple[Sequence[Trajectory], int]],
                       env_factory: EnvFactory) -> dict[Goal, Trained]:
        """The goals' policies trained together (:func:`~grail_bench.core.bc_update.train_bc_stacked`), the same
        weights and curves as :meth:`train_policy` gives each alone. Goals whose policy the numpy loop cannot
        run are left to :meth:`train_policy`."""
        if not self.stacked:
            return {}
        cfg = self.config
        groups: dict[Any, list[Goal]] = {}
        ready = {}
        for goal, (demos, seed) in jobs.items():
            start = time.perf_counter()
            torch.manual_seed(seed)  # as fit seeds it before train_policy: the same draws, in the same order
            obs, acts = self.pairs(goal, demos)
            policy = self.new_policy(goal, env_factory)
            batch_size = min(cfg.batch_size, len(obs))
            key = bc_update.stack_key(policy)
            if key is None or not batch_size:
                continue
            order = bc_update.batch_order(len(obs), batch_size, cfg.n_epochs, None)
            ready[goal] = (policy, (obs, acts), order, torch.get_rng_state(), time.perf_counter() - start)
            groups.setdefault((key, batch_size), []).append(goal)
        trained = {}
        for (_, batch_size), goals in groups.items():
            policies, data, orders, states, prep = zip(*(ready[g] for g in goals))
            run = bc_update.train_bc_stacked(policies, data, orders, learning_rate=cfg.learning_rate,
                                             ent_weight=cfg.ent_weight,
                                             log_intervals=[log_interval(len(obs), batch_size, None) for obs, _ in data])
            for i, goal in enumerate(goals):  # each its own preparation and its share of the stacked run
                trained[goal] = Trained(policies[i], {"loss": thin(run.losses[i])}, prep[i] + run.seconds[i],
                                        states[i])
        return trained


def train_bc(policy: ActorCriticPolicy, obs: np.ndarray, acts: np.ndarray, *, batch_size: int,
             learning_rate: float, ent_weight: float, n_epochs: int | None = None,
             n_batches: int | None = None, numpy: bool = True) -> tuple[ActorCriticPolicy, dict[str, list[float]]]:
    """Train ``policy`` by behavioural cloning (imitation 1.0.1's ``bc.BC`` loop) on ``(obs, acts)`` pairs.

    The loop runs in numpy where :func:`~grail_bench.core.bc_update.mirrorable` allows (the same batches,
    loss and Adam steps to float32 rounding, and the same stored results; 8-13x faster in ``make bench``),
    else in torch. Torch's global generator orders the batches (the caller seeds it).

    Args:
        policy: The policy to train, built for ``obs``' observation space.
        obs: Observations, ``(N, *observation_shape)``.
        acts: The actions taken there, ``(N, *action_shape)``.
        batch_size: Capped at the number of pairs.
        n_epochs, n_batches: The budget: passes over the data, or gradient steps (exactly one of them).
        numpy: False runs the torch loop whatever the policy (to compare the two).

    Returns:
        The trained policy and its loss curve (``{"loss": [...]}``, one point per epoch or per 1 % of the
        steps, thinned).
    """
    batch_size = min(batch_size, len(obs))
    interval = log_interval(len(obs), batch_size, n_batches)
    loop = bc_update.train_bc if numpy and bc_update.mirrorable(policy) else bc_update.train_bc_torch
    losses = loop(policy, obs, acts, batch_size=batch_size, learning_rate=learning_rate, ent_weight=ent_weight,
                  n_epochs=n_epochs, n_batches=n_batches, log_interval=interval)
    return policy, {"loss": thin(losses)}


def log_interval(pairs: int, batch_size: int, n_batches: int | None) -> int:
    """Steps between logged losses: one per epoch (the loader drops the last, incomplete batch), or one per 1 %
    of the steps when the budget is ``n_batches``."""
    return max(1, pairs // batch_size) if n_batches is None else max(1, n_batches // 100)
