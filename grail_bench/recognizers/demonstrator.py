"""The ``demonstrator`` reference recognizer: the task's own demonstrator as every goal's policy (perfect imitation).

It learns nothing: each goal's policy is the action distribution the task's
domain states for its demonstrator (the optional domain capability
``demonstrator_policy``, see :class:`grail_bench.task.domain.Domain`), so a
board can show what perfect imitation scores under each scorer, beside the
methods that imitate from demonstrations.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Literal, Mapping, Sequence

import numpy as np
from gymnasium import spaces
from grail_bench.core.trajectory import Trajectory

from grail_bench.core.errors import UserError
from grail_bench.core.spaces import state_index
from grail_bench.core.trajectory import EnvFactory, Goal
from grail_bench.recognizers.contract import FitReport
from grail_bench.recognizers.scored import ScoredRecognizer
from grail_bench.recognizers.scoring import PolicyOutput
from grail_bench.task.domain import DOMAINS, get_domain

CAPABILITY = "demonstrator_policy"


@dataclass(frozen=True)
class DemonstratorConfig:
    """The demonstrator's settings.

    Attributes:
        support: Where its policy states a preference: ``"everywhere"`` (goal-directed from every state: on a
            state the demonstrator from the task's start never visits, its action distribution as if it
            started there) or ``"demonstrated"`` (on the states the demonstrator visits from the task's start;
            no preference elsewhere: uniform over discrete actions, the action box's uniform mean and std over
            continuous ones).
    """

    support: Literal["everywhere", "demonstrated"] = "everywhere"


class DemonstratorRecognizer(ScoredRecognizer):
    """Perfect imitation: every goal's policy is its demonstrator's stated action distribution.

    ``fit`` reads nothing of the demonstrations but their goals: it asks the
    task's domain (through ``env_factory(goal).unwrapped.task``) for each
    goal's demonstrator policy and keeps it, a ``(K, S, A)`` table of action
    probabilities on discrete domains (MiniGrid, every regime) or per-goal
    Gaussians on continuous ones (PointMaze's scripted optimal and biased
    regimes); what a row is per regime is the domain's to say
    (:mod:`grail_bench.domains.minigrid.policy`,
    :mod:`grail_bench.domains.point_maze.policy`). A domain that states no
    demonstrator policy (PandaReach), or a regime it states none for (noisy
    actions), is refused in one line where a run is planned (:meth:`check_task`),
    and again when ``fit`` starts.

    Settings: :class:`DemonstratorConfig`. Its ``scorer`` defaults to ``"mse"`` (GRAIL's, so it reads beside
    BC, GAIL and AIRL); it exposes action probabilities on discrete actions, mean and std on continuous ones.
    """

    name = "demonstrator"
    paper_name = "Demonstrator (perfect imitation)"
    reference = True  # what perfect imitation reaches, not a method to rank
    default_scorer = "mse"
    Config = DemonstratorConfig
    config: DemonstratorConfig

    def __init__(self, scorer: str | None = None, **settings: Any) -> None:
        super().__init__(scorer=scorer, **settings)
        self.probs: np.ndarray | None = None  # (K, S, A) on discrete actions
        self.gaussians: list[Any] = []  # per goal, states -> (mean, std), on continuous actions

    def exposes(self, action_space: Any) -> frozenset[str]:
        """Action probabilities on discrete actions; mean and std on continuous ones."""
        return frozenset({"probs"}) if isinstance(action_space, spaces.Discrete) else frozenset({"mean", "std"})

    def check_task(self, task: Any) -> None:
        """Refuse, before any training, a task whose domain states no demonstrator policy for its regime.

        Raises:
            UserError: In one line (see :func:`_domain_policy`).
        """
        _domain_policy(task, self.config.support)

    def fit(self, demos: Mapping[Goal, Sequence[Trajectory]], env_factory: EnvFactory | None = None, *,
            seed: int = 0) -> FitReport:
        """Build every goal's demonstrator policy from the task (the demonstrations' actions are not read).

        Raises:
            UserError: Without an env factory, for envs not built by a task, for a task whose demonstrations
                come from a dataset, or for a domain or regime without a stated demonstrator policy.
        """
        goals = list(demos)
        if env_factory is None or not goals:
            raise UserError(f"{self.name}: fit needs goals and an env_factory building the task's envs")
        env = env_factory(goals[0])
        try:
            task = getattr(env.unwrapped, "task", None)
            observation_space, action_space = env.observation_space, env.action_space
        finally:
            env.close()
        domain = _domain_policy(task, self.config.support)
        start = time.perf_counter()
        policies = [domain(task, goal, self.config.support) for goal in goals]
        if isinstance(action_space, spaces.Discrete):
            self.probs, self.gaussians = np.stack([np.asarray(p, dtype=np.float64) for p in policies]), []
        else:
            self.probs, self.gaussians = None, policies
        seconds = time.perf_counter() - start
        self.goals, self.curves = goals, {}
        self.observation_space, self.action_space = observation_space, action_space
        return FitReport(train_seconds=seconds, trained=len(goals))

    def outputs_at(self, states: np.ndarray) -> PolicyOutput:
        if self.probs is not None:
            return PolicyOutput(probs=self.probs[:, state_index(states, self.observation_space)])
        outputs = [policy(states) for policy in self.gaussians]
        return PolicyOutput(mean=np.stack([m for m, _ in outputs]), std=np.stack([s for _, s in outputs]))


def _domain_policy(task: Any, support: str) -> Any:
    """The task's domain's ``demonstrator_policy``, once its ``check_demonstrator_policy`` accepts the task.

    Raises:
        UserError: In one line: for envs not built by a task, a task whose demonstrations come from a dataset,
            a domain that states no demonstrator policy (naming those that do), or what the domain refuses.
    """
    if task is None or not hasattr(task, "spec"):
        raise UserError("demonstrator: the envs must be built by a grail-bench task (env.unwrapped.task is unset)")
    if getattr(task, "demos", ""):
        raise UserError(f"demonstrator: {task.id} takes its demonstrations from a dataset, not from its domain's "
                        "demonstrator")
    policy = getattr(task.spec, CAPABILITY, None)
    if not callable(policy):
        served = [name for name in DOMAINS.names() if callable(getattr(get_domain(name), CAPABILITY, None))]
        raise UserError(f"demonstrator: {task.id}: the {task.domain} domain states no demonstrator action "
                        f"distribution; the demonstrator serves {', '.join(served) or 'no domain'}")
    check = getattr(task.spec, "check_demonstrator_policy", None)
    if callable(check):
        try:
            check(task, support)
        except UserError as exc:
            raise UserError(f"demonstrator: {exc}") from None
    return policy
