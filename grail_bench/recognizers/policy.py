"""GRAIL's recognition scheme: one policy per goal, scored in one batched pass."""

from __future__ import annotations

import abc
import time
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy

from grail_bench.core.cache import Busy, cached, needs_training
from grail_bench.core.errors import UserError
from grail_bench.core.provenance import model_versions
from grail_bench.core.seeding import goal_seed
from grail_bench.core.torchutil import single_thread
from grail_bench.core.trajectory import EnvFactory, Goal, Trajectory, demos_digest
from grail_bench.recognizers.contract import FitReport, settings_key
from grail_bench.recognizers.policy_bank import PolicyBank
from grail_bench.recognizers.scored import ScoredRecognizer
from grail_bench.recognizers.scoring import PolicyOutput

Curves = dict[str, list[float]]  # a training curve per name, e.g. {"loss": [...]}


@dataclass(frozen=True)
class Trained:
    """A policy :meth:`PolicyRecognizer.train_policies` trained before its goal's turn in its fit.

    Attributes:
        policy: The trained policy.
        curves: Its training curves.
        seconds: Its share of the training time.
        rng_state: torch's global generator state after the draws its training made, restored when the goal's
            turn comes, so later draws are those of training it then.
    """

    policy: BasePolicy
    curves: Curves
    seconds: float
    rng_state: torch.Tensor


class PolicyRecognizer(ScoredRecognizer):
    """Base of recognizers that learn one SB3 policy per goal.

    Subclasses implement :meth:`train_policy`. Scoring is shared and runs all
    goals in one batched pass; the default scorer is the negative MSE between
    each policy's action (probability vector against the one-hot observed
    action for discrete actions, mean action for continuous ones) and the
    observed action. Discrete policies expose action probabilities, continuous
    ones their mean and std; every goal's state occupancy in its training
    demonstrations is exposed too (the ``occupancy`` scorer), estimated in
    :meth:`fit` from the demonstrations whether the policies are trained or
    reloaded from the cache. The ``off_support`` setting of a subclass's
    :attr:`Config` applies (see :class:`~grail_bench.recognizers.scored.ScoredRecognizer`).
    """

    #: Whether the policies are learned from the demonstrations (their digest then keys the cache).
    uses_demos: bool = True

    def __init__(self, scorer: str | None = None, **settings: Any) -> None:
        super().__init__(scorer=scorer, **settings)
        self.bank: PolicyBank | None = None
        self._ahead: dict[Goal, Trained] = {}  # policies train_policies trained during the current fit

    @abc.abstractmethod
    def new_policy(self, goal: Goal, env_factory: EnvFactory) -> BasePolicy:
        """An untrained policy of the architecture :meth:`train_policy` returns."""

    @abc.abstractmethod
    def train_policy(self, goal: Goal, demos: Sequence[Trajectory], env_factory: EnvFactory,
                     seed: int) -> tuple[BasePolicy, Curves]:
        """Train the policy of one goal; return it and the training curves its learner logged (kept short)."""

    def train_policies(self, jobs: Mapping[Goal, tuple[Sequence[Trajectory], int]],
                       env_factory: EnvFactory) -> dict[Goal, Trained]:
        """Train several goals' policies at once, where that is cheaper than one by one.

        :meth:`fit` calls it, before its per-goal loop, with the goals whose policies it will train (not
        cached, not being trained by another process): ``{goal: (demos, seed)}``, where :meth:`train_policy`
        would be called with torch seeded by ``seed``. Each returned policy must be the one
        :meth:`train_policy` trains for its goal; goals left out train one by one in :meth:`train_policy`, as
        all do by default.
        """
        return {}

    def model_key(self, goal: Goal) -> dict[str, Any]:
        """What else a goal's trained policy depends on, beyond its settings, env, seed and own demonstrations
        (entries added to its cache key; none by default). Called after :meth:`learn_evidence`."""
        return {}

    def fit(self, demos: Mapping[Goal, Sequence[Trajectory]], env_factory: EnvFactory, *, seed: int,
            cache_key: str | None = None) -> FitReport:
        """Train one policy per goal (see :class:`grail_bench.Recognizer`).

        With a ``cache_key`` (the harness passes one), trained policies are
        cached on disk and reloaded by later fits of the same configuration.
        """
        if len(demos) < 2:
            raise UserError(f"{self.name}: need demonstrations of at least two goals, got {len(demos)}")
        self.learn_evidence(demos, env_factory)  # before training: a setting the domain cannot serve fails first
        fitted: dict[Goal, tuple[BasePolicy, float, bool, Curves]] = {}
        seeds = {g: goal_seed(seed, g) for g in demos}  # keyed by the goal, not its position in the task
        keys = {g: None if cache_key is None else self._cache_key(g, demos[g], seeds[g], cache_key) for g in demos}
        with single_thread():
            together = type(self).train_policies is not PolicyRecognizer.train_policies  # else skip the look
            todo = [g for g in demos
                    if together and (keys[g] is None or needs_training(f"policy-{self.name}", keys[g]))]
            self._ahead = self.train_policies({g: (demos[g], seeds[g]) for g in todo}, env_factory) if todo else {}
            try:
                # A goal whose model another process is training now is left for later, so parallel
                # fits of overlapping goal sets share the work rather than wait for each other.
                for wait in (False, True):
                    for goal in [g for g in demos if g not in fitted]:
                        torch.manual_seed(seeds[goal])
                        try:
                            fitted[goal] = self._policy(goal, demos[goal], env_factory, seeds[goal], keys[goal], wait)
                        except Busy:
                            continue
            finally:
                self._ahead = {}
        self.goals = list(demos)
        self.bank = PolicyBank([fitted[g][0] for g in self.goals])
        self.observation_space, self.action_space = self.bank.observation_space, self.bank.action_space
        self.curves = {g: fitted[g][3] for g in self.goals if fitted[g][3]}
        reused = sum(hit for _, _, hit, _ in fitted.values())
        return FitReport(train_seconds=sum(cost for _, cost, _, _ in fitted.values()), trained=len(fitted) - reused,
                         reused=reused)

    def _policy(self, goal: Goal, demos: Sequence[Trajectory], env_factory: EnvFactory, seed: int,
                key: dict[str, Any] | None, wait: bool = True) -> tuple[BasePolicy, float, bool, Curves]:
        """``(policy, training seconds, reloaded from the cache, training curves)``; cached under ``key``
        (:meth:`_cache_key`; None: not cached).

        The curves are kept in the cache beside the weights, so a reloaded policy has them too (empty for
        entries cached before they were kept).

        Raises:
            grail_bench.core.cache.Busy: With ``wait=False``, when another process is training it.
        """
        ahead = self._ahead.get(goal)
        spent = ahead.seconds if ahead is not None else 0.0

        def train_now() -> tuple[BasePolicy, Curves]:
            if ahead is None:
                return self.train_policy(goal, demos, env_factory, seed)
            torch.set_rng_state(ahead.rng_state)
            return ahead.policy, ahead.curves

        if key is None:
            start = time.perf_counter()
            policy, curves = train_now()
            return policy, spent + time.perf_counter() - start, False, curves
        trained: dict[str, BasePolicy] = {}

        def train() -> tuple[dict[str, Any], dict[str, Any]]:
            trained["policy"], curves = train_now()
            return trained["policy"].state_dict(), {"curves": curves}

        loaded: dict[str, BasePolicy] = {}

        def check(state: dict[str, Any]) -> None:  # a wrong key or shape: RuntimeError, the entry retrained
            loaded["policy"] = self.new_policy(goal, env_factory)
            loaded["policy"].load_state_dict(state)

        entry = cached(f"policy-{self.name}", key, train, wait=wait, spent=spent, check=check)
        curves = dict(entry.extra.get("curves") or {})
        if "policy" in trained:
            return trained["policy"], entry.seconds, False, curves
        return loaded["policy"], entry.seconds, True, curves

    def _cache_key(self, goal: Goal, demos: Sequence[Trajectory], seed: int, cache_key: str) -> dict[str, Any]:
        """The cache key of a goal's trained policy."""
        key = {"recognizer": self.name, "config": settings_key(self.config, models=True), "env": cache_key,
               "goal": list(goal), "seed": seed,
               "versions": model_versions()}
        if self.uses_demos:
            key["demos"] = demos_digest(demos)
        key.update(self.model_key(goal))
        return key

    def exposes(self, action_space: Any) -> frozenset[str]:
        """Action probabilities (discrete actions) or mean and std (continuous ones), and every goal's state
        occupancy in its training demonstrations (:class:`~grail_bench.recognizers.evidence.Evidence`)."""
        policy = {"probs"} if isinstance(action_space, spaces.Discrete) else {"mean", "std"}
        return frozenset(policy | {"occupancy"})

    def outputs_at(self, states: np.ndarray) -> PolicyOutput:
        if self.bank.discrete:
            return PolicyOutput(probs=self.bank.action_probs(states))
        mean, std = self.bank.mean_std(states)
        return PolicyOutput(mean=mean, std=std)

    def ruled_outputs(self, states: np.ndarray) -> PolicyOutput:
        """:meth:`outputs_at` with the ``off_support`` rule applied; on a tabled discrete bank the rule is applied
        once to the table of every state, so scoring under it costs what trusting the policies does."""
        rule = self.off_support
        if rule == "trust" or not (self.bank.discrete and self.bank.tabled):
            return super().ruled_outputs(states)
        evidence = self._evidence()

        def ruled(every: np.ndarray) -> np.ndarray:
            trusted = PolicyOutput(probs=self.bank.action_probs(every))
            return evidence.replace_off_support(trusted, self.goals, every, rule).probs

        return PolicyOutput(probs=self.bank.lookup(f"probs off_support={rule}", ruled, states))


def spaces_of(env_factory: EnvFactory, goal: Goal) -> tuple[spaces.Space, spaces.Space]:
    """Observation and action space of a goal's env."""
    env = env_factory(goal)
    try:
        return env.observation_space, env.action_space
    finally:
        env.close()
