"""``bip``: Bayesian inverse planning (Baker, Saxe & Tenenbaum, Cognition 2009).

The model-based counterpart of the recognizers that imitate: it learns no policy. Per candidate goal it
computes the exact optimal action values ``Q_g(s, a)`` of the task's own dynamics (value iteration on the
env's tables, :func:`grail_bench.domains.boltzmann.action_values`: shortest-path costs on MiniGrid, plan costs
on the symbolic domain), and models the observed agent as Boltzmann-rational,
``P(a | s, g) = exp(beta Q_g(s, a)) / sum_b exp(beta Q_g(s, b))``. The one parameter, ``beta``, is fitted by
maximum likelihood on the training demonstrations (each step under its own goal's values, up to the step that
reaches the goal; a bounded 1-D search, the log-likelihood being concave in ``beta``), unless
:attr:`BIPConfig.beta` fixes it. On a goal's own goal states (where an env with a fixed horizon keeps the agent
after it arrives) the agent takes the domain's no-op.

The score of a goal is its log posterior under a uniform prior, ``log P(g | O) = sum_t log P(a_t | s_t, g) -
log sum_g' (...)``, the observed pairs taken as independent given the goal (an online posterior: every prefix's
in one pass, ``score_prefixes``). An action impossible under a goal (one after which the goal cannot be reached
while another action could) counts as probability ``exp(LOG_ZERO)``, so a goal with fewer impossible steps
still wins. Under the ``boltzmann`` regime with the demonstrator's ``beta``, a prefix observation's likelihood
is the demonstrator's exact one.

Only where the values are exact: tasks of a domain whose env states its dynamics as tables
(``tabular_dynamics``: MiniGrid and the symbolic domain); others are refused in one line where the run is
planned (``check_task``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Annotated, Any, Mapping, Sequence

import numpy as np

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.spaces import state_index
from grail_bench.core.trajectory import Demos, EnvFactory, Goal, until_success
from grail_bench.domains.boltzmann import BETA, boltzmann_policy, env_values, fit_beta, goal_states
from grail_bench.recognizers.contract import FitReport, NotFittedError, RecognizerBase, checked_settings, observed_arrays

#: The domains whose envs state their dynamics as tables, so that the action values are exact.
EXACT_DOMAINS = ("minigrid", "symbolic")
#: The log-probability an impossible step counts with.
LOG_ZERO = -1000.0


@dataclass(frozen=True)
class BIPConfig:
    """Bayesian inverse planning's settings.

    Attributes:
        beta: The rationality, fixed (None: fitted by maximum likelihood on the training demonstrations).
        beta_max: The largest ``beta`` the fit may reach (it does when the demonstrations take optimal actions
            only).
    """

    beta: Annotated[float, BETA] | None = field(default=None, metadata={"omit_none": True})
    beta_max: Annotated[float, Range(0.001, BETA.high)] = BETA.high

    def __post_init__(self) -> None:
        if self.beta is not None and not (math.isfinite(self.beta) and BETA.low <= self.beta <= BETA.high):
            raise UserError(f"beta must be in [{BETA.low:g}, {BETA.high:g}], got {self.beta}")
        if not (math.isfinite(self.beta_max) and 0 < self.beta_max <= BETA.high):
            raise UserError(f"beta_max must be in (0, {BETA.high:g}], got {self.beta_max}")


class BIPRecognizer(RecognizerBase):
    """Bayesian inverse planning: a Boltzmann likelihood over each goal's exact action values (module docstring).

    Settings: :class:`BIPConfig`. After :meth:`fit`, :attr:`beta` is the rationality it scores with.
    """

    name = "bip"
    paper_name = "BIP (Baker et al. 2009)"
    Config = BIPConfig
    config: BIPConfig

    def __init__(self, **settings: Any) -> None:
        self.config = checked_settings(BIPConfig, settings, self.name)
        self.goals: list[Goal] = []
        self.beta: float | None = None
        self.log_policies: np.ndarray | None = None  # (K, S, A)
        self.observation_space = self.action_space = None

    def check_task(self, task: Any) -> None:
        """Refuse, before anything is built, a task whose action values are not exact.

        Raises:
            UserError: In one line, naming the task's domain and those served.
        """
        domain = getattr(task, "domain", None)
        if domain not in EXACT_DOMAINS:
            raise UserError(f"bip: {getattr(task, 'id', task)} is a {domain} task; exact action values (from the "
                            f"env's tables) exist on {' and '.join(EXACT_DOMAINS)} tasks only")

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0) -> FitReport:
        """Compute every goal's action values from its env, then fit ``beta`` on the demonstrations.

        Raises:
            UserError: Without goals or an env factory, for an env without tables, or without a demonstrated
                step on a state from which its goal can be reached (when ``beta`` is fitted).
        """
        goals = list(demos)
        if env_factory is None or not goals:
            raise UserError("bip: fit needs goals and an env_factory building the task's envs")
        start = time.perf_counter()
        values, at_goal = [], []
        pad = None
        for goal in goals:
            env = env_factory(goal)
            try:
                try:
                    dyn, q = env_values(env)
                except UserError as exc:
                    raise UserError(f"bip: goal {list(goal)}: {exc}") from None
                task = getattr(env.unwrapped, "task", None)
                if task is not None and task.env_params.get("fixed_horizon"):
                    pad = getattr(task.spec, "noop_action", None)
                self.observation_space, self.action_space = env.observation_space, env.action_space
            finally:
                env.close()
            values.append(q)
            at_goal.append(goal_states(dyn))
        if self.config.beta is not None:
            beta = float(self.config.beta)
        else:
            pairs = [self._demo_pairs(demos[goal]) for goal in goals]
            beta = fit_beta(values, [s for s, _ in pairs], [a for _, a in pairs], (BETA.low, self.config.beta_max))
        with np.errstate(divide="ignore"):
            logs = np.stack([np.log(boltzmann_policy(q, beta, g, pad)) for q, g in zip(values, at_goal)])
        self.log_policies = np.maximum(logs, LOG_ZERO)
        self.goals, self.beta = goals, beta
        return FitReport(train_seconds=time.perf_counter() - start, trained=len(goals))

    def _demo_pairs(self, trajectories: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
        """The (state index, action) pairs of demonstrations, each up to the step that reaches its goal."""
        states, actions = [], []
        for traj in trajectories:
            cut = until_success(traj)
            acts = np.asarray(cut.acts, dtype=np.int64).reshape(-1)
            states.append(state_index(np.asarray(cut.obs)[: len(acts)], self.observation_space))
            actions.append(acts)
        return (np.concatenate(states) if states else np.zeros(0, dtype=np.int64),
                np.concatenate(actions) if actions else np.zeros(0, dtype=np.int64))

    def _step_log_likelihoods(self, observed: Any) -> np.ndarray:
        """``(K, T)``: each observed step's log-probability under each goal."""
        if self.log_policies is None:
            raise NotFittedError("bip: call fit() before score()")
        states, acts = observed_arrays(observed, self.observation_space, self.action_space)
        idx = state_index(states, self.observation_space)
        return self.log_policies[:, idx, np.asarray(acts, dtype=np.int64).reshape(-1)]

    def log_likelihoods(self, observed: Any) -> np.ndarray:
        """``(K,)``: each goal's log-likelihood of the observed steps (the goals in :attr:`goals`' order)."""
        return self._step_log_likelihoods(observed).sum(axis=1)

    def score(self, observed: Any) -> Mapping[Goal, float]:
        """Every goal's log posterior given the observed steps (uniform prior).

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For a malformed observation.
        """
        total = self.log_likelihoods(observed)
        post = total - np.logaddexp.reduce(total)
        return {goal: float(p) for goal, p in zip(self.goals, post)}

    def score_prefixes(self, observed: Any, scorer: str | None = None) -> Mapping[Goal, np.ndarray]:
        """Every goal's log posterior after each observed step, ``(T,)`` per goal, in one pass.

        Raises:
            UserError: For a scorer (it scores with its own posterior only).
        """
        if scorer is not None:
            raise UserError(f"bip scores with its own posterior only, not {scorer!r}")
        cum = np.cumsum(self._step_log_likelihoods(observed), axis=1)
        post = cum - np.logaddexp.reduce(cum, axis=0)
        return {goal: post[k] for k, goal in enumerate(self.goals)}
