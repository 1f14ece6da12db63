"""Boltzmann-rational demonstrators on tabular dynamics: actions drawn with probability proportional to
``exp(beta * Q(s, a))`` for the goal's exact optimal action values.

The values come from the env's own tables (:class:`~grail_bench.core.tabular.TabularDynamics`): every step
costs 1 and the episode ends at the goal, so ``Q(s, a) = -1`` for a step that reaches it and
``-(1 + d(s'))`` otherwise, ``d`` the fewest steps from the successor ``s'`` to the goal (value iteration on the
tables, exact in as many sweeps as the longest distance). An action after which the goal can never be reached
(into lava, into a cut-off part of the world) has ``Q = -inf``: the demonstrator never takes it. So has an action
the env says is not one (``allowed_actions``: on the symbolic domain, an inapplicable operator, which leaves the
state as it is and is no step of any plan); on MiniGrid every action is one (stay and bumping into a wall
included). The values are
those of the undiscounted problem without a horizon; the demonstrator acts on them until it reaches the goal or
the horizon truncates its episode (it may not reach the goal: a low ``beta`` wanders).

``beta = 0`` is uniformly random over the actions that can still reach the goal; ``beta -> inf`` is uniform
among the optimal actions. On a state where the goal is reached already (the goal's states, where an env with a
fixed horizon keeps the agent) it takes the domain's no-op (``pad``); on states it never visits (no action there
reaches the goal) its row is uniform.

:class:`BoltzmannChain` is the demonstrator as a probability model: samples, and the exact likelihood of an
observation under a protocol (a prefix or an ordered random subset of the path to the goal, or of the whole
horizon padded with no-ops at the goal) by a forward pass over (state, observed pairs matched so far); it never
enumerates paths. :func:`pair_log_probs` and :func:`fit_beta` are what an inverse planner needs of it.
"""

from __future__ import annotations

from math import comb
from typing import TYPE_CHECKING, Any, Iterator, Sequence

import numpy as np

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import rollout
from grail_bench.task.observation import Selection, n_observed

if TYPE_CHECKING:
    from grail_bench.core.tabular import TabularDynamics
    from grail_bench.core.trajectory import Goal, Trajectory
    from grail_bench.task.model import GRTask


#: The rationality ``beta`` a task or a fit may take (beyond 50, a step's cost outweighs e^50: optimal).
BETA = Range(0.0, 50.0)
#: States the likelihood's forward pass holds at most (the states the demonstrator can reach from the start).
MAX_STATES = 200_000


def check_beta(beta: object, what: str = "beta") -> float:
    """``beta`` as a float within :data:`BETA`.

    Raises:
        UserError: For a non-number or a value outside the range.
    """
    if isinstance(beta, bool) or not isinstance(beta, (int, float)) or not BETA.low <= float(beta) <= BETA.high:
        raise UserError(f"{what} must be a number in [{BETA.low:g}, {BETA.high:g}], got {beta!r}")
    return float(beta)


def action_values(dyn: TabularDynamics, allowed: np.ndarray | None = None) -> np.ndarray:
    """The exact optimal action values ``Q(s, a)`` of every state and action (see the module docstring).

    Args:
        dyn: The goal's env as tables.
        allowed: ``(S, A)`` the actions the agent may take in each state (None: all).

    Returns:
        ``(S, A)`` floats: ``-1`` for a step onto the goal, ``-(1 + d(s'))`` else, ``-inf`` where the goal can no
        longer be reached (or the action is not allowed).
    """
    nxt, success = dyn.next_state, dyn.success
    ok = np.ones(nxt.shape, dtype=bool) if allowed is None else np.asarray(allowed, dtype=bool)
    q = np.where(success & ok, -1.0, -np.inf)
    while True:  # value iteration: unit costs, so it settles after the longest distance's number of sweeps
        dist = -q.max(axis=1)
        new = np.where(ok, np.where(success, -1.0, -(1.0 + dist[nxt])), -np.inf)
        if np.array_equal(new, q):
            return q
        q = new


def env_values(env: Any) -> tuple[TabularDynamics, np.ndarray]:
    """A goal env's tables and its exact action values, over the actions it allows (``allowed_actions``, when the
    env says: the symbolic domain's applicable operators; else every action).

    Raises:
        UserError: For an env that states no tables of its dynamics (``tabular_dynamics``).
    """
    base = env.unwrapped
    if not callable(getattr(base, "tabular_dynamics", None)):
        raise UserError(f"{type(base).__name__} states no tables of its dynamics (tabular_dynamics): its action "
                        "values are not exact")
    dyn = base.tabular_dynamics()
    allowed = base.allowed_actions() if callable(getattr(base, "allowed_actions", None)) else None
    return dyn, action_values(dyn, allowed)


def goal_states(dyn: TabularDynamics) -> np.ndarray:
    """``(S,)`` whether a state is one a step reaching the goal lands on."""
    out = np.zeros(len(dyn.next_state), dtype=bool)
    out[dyn.next_state[dyn.success]] = True
    return out


def boltzmann_policy(q: np.ndarray, beta: float, at_goal: np.ndarray, pad: int | None) -> np.ndarray:
    """``(S, A)`` action probabilities ``exp(beta Q) / sum``: the no-op ``pad`` on goal states (uniform when
    None), uniform on states from which no action reaches the goal."""
    s, a = q.shape
    probs = np.full((s, a), 1.0 / a)
    live = np.isfinite(q).any(axis=1) & ~at_goal
    rows = q[live]
    finite = np.isfinite(rows)
    gap = np.where(finite, rows - rows.max(axis=1, keepdims=True), 0.0)  # <= 0 where finite
    e = np.where(finite, np.exp(beta * gap), 0.0)
    probs[live] = e / e.sum(axis=1, keepdims=True)
    if pad is not None:
        probs[at_goal] = 0.0
        probs[at_goal, pad] = 1.0
    return probs


def pair_log_probs(q: np.ndarray, beta: float, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """``log pi(a | s)`` of each (state index, action) pair under the Boltzmann policy of ``q`` (``-inf`` for an
    action that cannot reach the goal where another can; ``log(1 / A)`` where none can)."""
    rows = q[states]
    finite = np.isfinite(rows)
    any_finite = finite.any(axis=1)
    top = np.where(finite, rows, -np.inf).max(axis=1, initial=-np.inf)
    z = beta * np.where(finite, rows - np.where(any_finite, top, 0.0)[:, None], 0.0)
    lse = np.log(np.where(finite, np.exp(z), 0.0).sum(axis=1).clip(min=1e-300))
    chosen = np.where(finite, z, -np.inf)[np.arange(len(states)), actions]
    uniform = -np.log(q.shape[1])
    return np.where(any_finite, chosen - lse, uniform)


def fit_beta(qs: Sequence[np.ndarray], states: Sequence[np.ndarray], actions: Sequence[np.ndarray],
             bounds: tuple[float, float] = (BETA.low, BETA.high)) -> float:
    """The maximum-likelihood ``beta`` of (state index, action) pairs, each set under its own goal's values.

    Pairs on states where no action reaches the goal, or whose action cannot (impossible under every ``beta``),
    say nothing about ``beta`` and are left out. The log-likelihood is concave in ``beta`` (a log-partition
    function's), so a bounded scalar search finds its maximum; it is ``bounds[1]`` when only optimal actions
    were seen.
    """
    rows, gaps = [], []
    for q, s, a in zip(qs, states, actions):
        r = q[s]
        keep = np.isfinite(r).any(axis=1) & np.isfinite(r[np.arange(len(s)), a])
        rows.append(r[keep])
        gaps.append(a[keep])
    q_all = np.concatenate(rows) if rows else np.zeros((0, 1))
    a_all = np.concatenate(gaps) if gaps else np.zeros(0, dtype=np.int64)
    if len(a_all) == 0:
        raise UserError("fitting beta needs demonstrated steps on states from which the goal can be reached")
    rows_all = np.arange(len(q_all))  # each row of q_all is one pair's state

    def nll(beta: float) -> float:
        return -float(pair_log_probs(q_all, beta, rows_all, a_all).sum())

    from scipy.optimize import minimize_scalar

    result = minimize_scalar(nll, bounds=bounds, method="bounded", options={"xatol": 1e-4})
    best = float(result.x)
    return bounds[1] if nll(bounds[1]) <= nll(best) else best


class BoltzmannChain:
    """One goal's Boltzmann demonstrator as a Markov chain over the env's state indices.

    Args:
        dyn: The goal's env as tables.
        beta: The rationality.
        pad: The no-op the agent takes on the goal after reaching it, until the horizon (None: episodes end at
            the goal, so horizon protocols observe the path to the goal as well).
        q: The action values (default: :func:`action_values` of ``dyn``, every action allowed).

    Raises:
        UserError: When the demonstrator can reach more than :data:`MAX_STATES` states, or never the goal.
    """

    def __init__(self, dyn: TabularDynamics, beta: float, pad: int | None, q: np.ndarray | None = None) -> None:
        from scipy import sparse

        self.dyn, self.beta, self.pad, self.horizon = dyn, float(beta), pad, int(dyn.horizon)
        self.q = action_values(dyn) if q is None else q
        if not np.isfinite(self.q[dyn.start]).any():
            raise UserError("the goal cannot be reached from the start")
        self.at_goal = goal_states(dyn)
        self.policy = boltzmann_policy(self.q, self.beta, self.at_goal, pad)
        # the states it can be in before reaching the goal, and those it reaches the goal on: a compact index
        live = self.policy > 0
        seen, frontier = {dyn.start}, [dyn.start]
        while frontier:
            s = frontier.pop()
            for a in np.flatnonzero(live[s]):
                t = int(dyn.next_state[s, a])
                if t not in seen and (dyn.success[s, a] or not self.at_goal[t]):
                    seen.add(t)
                    if not dyn.success[s, a]:
                        frontier.append(t)
            if len(seen) > MAX_STATES:
                raise UserError(f"the Boltzmann demonstrator can reach more than {MAX_STATES} states; its exact "
                                "likelihood stops there")
        self.states = np.array(sorted(seen), dtype=np.int64)
        self.local = np.full(len(dyn.next_state), -1, dtype=np.int64)  # state index -> row of the forward pass
        self.local[self.states] = np.arange(len(self.states))
        r, n_actions = len(self.states), self.policy.shape[1]
        src = np.repeat(np.arange(r), n_actions)
        acts = np.tile(np.arange(n_actions), r)
        glob = self.states[src]
        p = self.policy[glob, acts]
        dst_glob = dyn.next_state[glob, acts]
        ok = (p > 0) & ~self.at_goal[glob]
        dst = self.local[dst_glob]
        ok &= dst >= 0
        hit = dyn.success[glob, acts]
        keep_on, keep_hit = ok & ~hit, ok & hit
        # transposed transition matrices: live mass moves by T, arriving mass by U (column-vector convention)
        self._t = sparse.csr_matrix((p[keep_on], (dst[keep_on], src[keep_on])), shape=(r, r))
        self._u = sparse.csr_matrix((p[keep_hit], (dst[keep_hit], src[keep_hit])), shape=(r, r))

    def sample(self, rng: np.random.Generator) -> list[int]:
        """One demonstration's actions up to the goal (or the horizon, if it never gets there)."""
        s, actions = self.dyn.start, []
        cum = np.cumsum(self.policy, axis=1)
        while len(actions) < self.horizon:
            a = int(min(np.searchsorted(cum[s], rng.random() * cum[s, -1], side="right"), cum.shape[1] - 1))
            actions.append(a)
            if self.dyn.success[s, a]:
                break
            s = int(self.dyn.next_state[s, a])
        return actions

    def path(self, actions: Sequence[int]) -> tuple[list[int], bool]:
        """The state index each action is taken in, and whether the last one reached the goal."""
        states, s, arrived = [], self.dyn.start, False
        for a in actions:
            states.append(s)
            arrived = bool(self.dyn.success[s, a])
            s = int(self.dyn.next_state[s, a])
        return states, arrived

    def padding(self, actions: Sequence[int], horizon_span: bool) -> tuple[int, int] | None:
        """The (state index, no-op) pair repeated after the goal and how often, when the span is padded."""
        if not horizon_span or self.pad is None:
            return None
        states, arrived = self.path(actions)
        if not arrived:
            return None
        return int(self.dyn.next_state[states[-1], actions[-1]]), self.horizon - len(actions)

    def likelihood(self, states: Sequence[int], actions: Sequence[int], selection: Selection) -> float:
        """Probability that the demonstrator's protocol observation is exactly these (state index, action) pairs.

        A forward pass over time: ``alpha[s, j]`` is the probability of being in ``s`` not at the goal yet,
        weighted by the number of ways the pairs emitted so far pick out the first ``j`` observed pairs in order
        (a prefix protocol: only the first ``j``). A path ends at the goal (its span has as many pairs as it took
        steps) or, with padding, emits the no-op at the goal until the horizon; an observation of ``k`` pairs of an
        ``n``-pair span has probability ``1 / C(n, k)`` per embedding (a prefix: 1) when the level observes ``k``
        of ``n``.
        """
        k = len(states)
        if k == 0 or len(actions) != k:
            return 0.0
        glob = np.asarray(states, dtype=np.int64)
        obs_a = np.asarray(actions, dtype=np.int64)
        if ((glob < 0) | (glob >= len(self.local)) | (obs_a < 0) | (obs_a >= self.policy.shape[1])).any():
            return 0.0
        obs_s = self.local[glob]
        if (obs_s < 0).any():
            return 0.0  # a state the demonstrator never visits
        p_obs = self.policy[glob, obs_a]
        nxt = self.local[self.dyn.next_state[glob, obs_a]]
        hits = self.dyn.success[glob, obs_a]
        from_goal = self.at_goal[glob]
        p_obs = np.where(from_goal | (nxt < 0), 0.0, p_obs)
        cols = np.arange(k)
        padded = selection.horizon and self.pad is not None
        pad_match = (obs_a == self.pad) if padded else np.zeros(k, dtype=bool)

        def weight(n: int) -> float:
            if n_observed(selection.level, n, selection.rounding) != k:
                return 0.0
            return 1.0 / comb(n, k) if selection.random_subset else 1.0

        def skipping(a: np.ndarray) -> np.ndarray:
            if selection.random_subset:
                return a
            out = np.zeros_like(a)
            out[:, k] = a[:, k]
            return out

        r = len(self.states)
        alpha = np.zeros((r, k + 1))
        alpha[self.local[self.dyn.start], 0] = 1.0
        done = np.zeros((r, k + 1)) if padded else None
        total = 0.0
        for t in range(self.horizon):
            move = skipping(alpha)
            live = np.asarray(self._t @ move)
            arrived = np.asarray(self._u @ move)
            take = alpha[obs_s, cols] * p_obs
            on, hit = (take > 0) & ~hits, (take > 0) & hits
            np.add.at(live, (nxt[on], cols[on] + 1), take[on])
            np.add.at(arrived, (nxt[hit], cols[hit] + 1), take[hit])
            if padded:
                stay = skipping(done)
                taken = done[obs_s, cols] * pad_match * from_goal
                np.add.at(stay, (obs_s[taken > 0], cols[taken > 0] + 1), taken[taken > 0])
                done = stay + arrived
            else:
                total += weight(t + 1) * float(arrived[:, k].sum())
            alpha = live
            if not alpha.any() and (done is None or not done.any()):
                return total
        end = float(alpha[:, k].sum()) + (float(done[:, k].sum()) if padded else 0.0)
        return total + weight(self.horizon) * end


def task_beta(task: GRTask) -> float:
    """The ``beta`` of a task of the Boltzmann regime."""
    return check_beta(task.params["beta"])


def task_chain(task: GRTask, goal: Goal) -> tuple[BoltzmannChain, object]:
    """The Boltzmann demonstrator of ``goal`` under ``task`` and the goal's env (the caller closes it).

    The no-op pads the span only where the env keeps the agent on the goal until the horizon (a domain's
    ``noop_action`` with ``fixed_horizon``); elsewhere the episode ends at the goal.
    """
    env = task.make_env(goal)
    pad = getattr(task.spec, "noop_action", None) if task.env_params.get("fixed_horizon") else None
    dyn, q = env_values(env)
    return BoltzmannChain(dyn, task_beta(task), pad, q), env


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal by the Boltzmann demonstrator, rolled out in the goal's env (after the goal, the
    no-op until the horizon where the env runs on; a demonstration that never reaches the goal is kept)."""
    chain, env = task_chain(task, goal)
    pad = chain.pad if chain.pad is not None else 0
    demos = []
    for _ in range(n):
        actions = chain.sample(rng)
        demos.append(rollout(env, lambda obs, t: actions[t] if t < len(actions) else pad))
    env.close()
    return demos


def demonstrator_policy(task: GRTask, goal: Goal, support: str) -> np.ndarray:
    """The Boltzmann demonstrator's action probabilities on every state index (its own policy: it is Markov).

    ``support="demonstrated"`` keeps them on the states it can visit from the start (the rest uniform).
    """
    chain, env = task_chain(task, goal)
    env.close()
    probs = chain.policy.copy()
    if support == "demonstrated":
        outside = np.ones(len(probs), dtype=bool)
        outside[chain.states] = False
        probs[outside] = 1.0 / probs.shape[1]
    return probs


class BoltzmannDemonstrator:
    """One goal's Boltzmann demonstrator as the Bayes ceiling reads it (a
    :class:`~grail_bench.domains.base.GoalModel`): pairs are ``(state index, action)``."""

    action_size = 1
    enumerable = False  # every path of up to the horizon has positive probability

    def __init__(self, task: GRTask, goal: Goal) -> None:
        self.chain, env = task_chain(task, goal)
        env.close()

    def support(self) -> Iterator[tuple[tuple[int, ...], float]]:
        raise ValueError("the support of a Boltzmann demonstrator is not enumerated")

    def span(self, actions: Sequence[int], selection: Selection) -> list[tuple[int, int]]:
        """The pairs a protocol samples from: the path, plus the no-op at the goal for padded horizon protocols."""
        states, _ = self.chain.path(actions)
        pairs = list(zip(states, (int(a) for a in actions)))
        padding = self.chain.padding(actions, selection.horizon)
        if padding is not None:
            state, count = padding
            pairs += [(state, int(self.chain.pad))] * count
        return pairs

    def observations(self, actions: Sequence[int], selection: Selection) -> Iterator[tuple[tuple, float]]:
        return selection.observations(self.span(actions, selection))

    def sample_observation(self, rng: np.random.Generator, selection: Selection) -> tuple:
        return selection.sample(self.span(self.chain.sample(rng), selection), rng)

    def likelihood(self, observation: tuple, selection: Selection) -> float:
        """Probability that the demonstrator yields ``observation`` under the protocol (exact)."""
        return self.chain.likelihood([p[0] for p in observation], [p[1] for p in observation], selection)
