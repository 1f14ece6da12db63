"""Where each goal's policy has evidence: its support and its state occupancy, learnt from training demonstrations.

A goal's policy is trained on its own demonstrations, yet scoring asks it about every observed state.
:class:`Evidence` keeps, per goal, the states its training demonstrations visit (its *support*: exact states on
discrete observations; on continuous ones, the states within a radius of the nearest training state) and a
smoothed *occupancy* of them (visit counts with a Dirichlet prior, or a Gaussian kernel density), so that
recognizers can replace a policy's output off its support (``off_support``), train with the domain's no-op at
the other goals' states (BC's ``augment``), and score with the occupancy (the ``occupancy`` scorer).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import field
from typing import TYPE_CHECKING, Any, Callable, Literal, Sequence

import numpy as np
from gymnasium import spaces

from grail_bench.core.errors import UserError
from grail_bench.core.scaling import scale_of
from grail_bench.core.spaces import n_states, state_index
from grail_bench.core.trajectory import Demos, Goal, until_success
from grail_bench.recognizers.scoring import PolicyOutput

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

#: What a goal's policy outputs at a state off its goal's support (see :class:`Evidence`): ``"trust"`` its own
#: output (GRAIL's method), ``"stay"`` the domain's no-op, ``"uniform"`` no preference among actions.
OffSupport = Literal["trust", "stay", "uniform"]
#: The support radius on continuous observations: this percentile of the leave-one-out nearest-neighbour
#: distances among a goal's distinct training states.
RADIUS_PERCENTILE = 95.0
#: The smallest support radius, relative to the states' size (``floor * max(1, max |coordinate|)``): where a goal
#: has a single distinct training state (identical one-state demonstrations), only that state, up to rounding.
RADIUS_FLOOR = 1e-6
#: The Dirichlet prior weights the occupancy of discrete states is chosen among (per state of the space).
ALPHAS = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0)
#: The Gaussian kernel bandwidths the occupancy of continuous states is chosen among, in units of the training
#: states' standard deviation per coordinate; the smallest is the floor identical demonstrations reach.
BANDWIDTHS = tuple(float(h) for h in np.geomspace(0.01, 1.0, 9))
#: Where no goal has two demonstrations (nothing to leave out), the prior weight and the bandwidth used.
ALPHA_DEFAULT, BANDWIDTH_DEFAULT = 0.1, 0.1
#: Held-out states per goal at most in the bandwidth's leave-one-demonstration-out likelihood (evenly spaced).
HELD_OUT_STATES = 256


def off_support_setting() -> Any:
    """The ``off_support`` field of a settings dataclass (``off_support: OffSupport = off_support_setting()``).

    Its default, ``"trust"``, is the published method and is left out of the configuration's key (so earlier keys
    stay valid); it changes scoring only, so cached models are shared across its values (metadata ``scoring``).
    """
    return field(default="trust", metadata={"scoring": True, "omit_default": True})


#: Discrete observation spaces with at most this many states keep each goal's support as a table over every state.
SUPPORT_TABLE_STATES = 1 << 16
#: On continuous observations, squared distances from a matrix product within this share of the squared radius
#: (and of the training states' squared extent) of it are settled by the goal's KD-tree, as the radius was measured.
_ROUNDING = 1e-12
#: Kernel terms smaller than ``exp(_EXPONENT_FLOOR)`` times the goal's largest count as that (never subnormal,
#: which is slow to compute and changes no sum).
_EXPONENT_FLOOR = -700.0
#: Entries of one ``(states, stacked training states)`` product at most; more states are taken in blocks.
_BLOCK_ENTRIES = 1 << 22


def training_states(trajs: Sequence[Trajectory]) -> list[np.ndarray]:
    """Per demonstration, the states in which it takes an action, cut after its goal is reached (as BC trains)."""
    out = []
    for traj in trajs:
        cut = until_success(traj)
        out.append(np.asarray(cut.obs)[: len(cut.acts)])
    return out


def domain_noop(env: Any) -> Any:
    """The no-op action declared by the domain of the task that built ``env`` (``noop_action``), or None."""
    task = getattr(env.unwrapped, "task", None)
    return None if task is None else getattr(task.spec, "noop_action", None)


class Evidence:
    """Where each goal's training demonstrations went, learnt from them alone when a recognizer is fitted.

    A goal's *support* is the set of states its training demonstrations visit, each demonstration cut after the
    goal is reached as BC trains on it (the states in which an action is taken). On discrete observations it is
    those exact states. On continuous ones it is every state within a radius of the nearest of them (Euclidean
    distance in the raw coordinates), the radius being the 95th percentile (:data:`RADIUS_PERCENTILE`) of the
    leave-one-out nearest-neighbour distances among the goal's *distinct* training states: repeated states
    (identical demonstrations, e.g. PandaReach's optimal regime) count once, so the radius is then about the step
    between consecutive states; a goal with a single distinct state gets the floor (:data:`RADIUS_FLOOR`), that
    state up to rounding. A goal without demonstrations (a goal-conditioned model's new goal) has no support.

    A goal's *occupancy* ``d_g`` is the smoothed frequency of its training states (every visit counts). On
    discrete observations: ``d_g(s) = (c_g(s) + alpha) / (N_g + alpha * S)``, ``c_g(s)`` the visits of state
    ``s``, ``N_g`` all visits, ``S`` the states of the observation space (a Dirichlet prior ``alpha`` on every
    state). On continuous ones: a Gaussian kernel density of the training states with one isotropic bandwidth
    ``h``, in coordinates scaled by every goal's training states' standard deviation (a coordinate that never
    varies keeps scale 1). ``alpha`` (among :data:`ALPHAS`) and ``h`` (among :data:`BANDWIDTHS`) are one value
    for all goals, so their occupancies compare, chosen to maximise the leave-one-demonstration-out likelihood:
    each training demonstration's states scored by the estimate from the rest of its goal's demonstrations,
    summed over every demonstration of every goal with at least two (at most :data:`HELD_OUT_STATES` evenly
    spaced states per goal for ``h``). Identical demonstrations drive both to the grid's smallest value, which
    is then the floor (no jitter needed: the kernel has no covariance to estimate). Where no goal has two
    demonstrations, :data:`ALPHA_DEFAULT` and :data:`BANDWIDTH_DEFAULT`. A goal without demonstrations (or whose
    demonstrations take no action) has the prior alone: uniform over the observation space (refused on an
    unbounded box).

    On continuous observations every goal's distinct training states are stacked at first use (:class:`_Packed`),
    so that scoring meets all of them in one matrix product: the support compares squared distances with the
    squared radius (a state within rounding of it is measured by the goal's KD-tree, as the radius was) and the
    density sums each goal's kernel terms shifted by its nearest one; both agree with the per-goal definitions
    above to 1e-9 (``tests/test_support.py``).

    Args:
        demos: The training demonstrations of every fitted goal.
        observation_space: The env's observation space (``Discrete``, ``MultiDiscrete`` or ``Box``).
        action_space: The env's action space (``Discrete`` or ``Box``).
        noop: The domain's no-op action, or None when its domain declares none.

    Raises:
        UserError: For another observation space, or a no-op that is not an action of ``action_space``.
    """

    def __init__(self, demos: Demos, observation_space: spaces.Space, action_space: spaces.Space,
                 noop: Any = None) -> None:
        self.observation_space, self.action_space = observation_space, action_space
        self.discrete = isinstance(observation_space, (spaces.Discrete, spaces.MultiDiscrete))
        if not self.discrete and not isinstance(observation_space, spaces.Box):
            raise UserError(f"off-support rules need Discrete, MultiDiscrete or Box observations, got "
                            f"{observation_space}")
        if self.discrete and n_states(observation_space) >= 1 << 62:
            raise UserError(f"off-support rules need discrete observation spaces of fewer than 2**62 states, got "
                            f"{observation_space}")
        self.noop = None if noop is None else _checked_noop(noop, action_space)
        self.goals = [tuple(g) for g in demos]
        #: Per goal, the states of each training demonstration in which it acts (cut at the goal).
        self.states: dict[Goal, list[np.ndarray]] = {g: training_states(demos[g]) for g in demos}
        self._row = {g: i for i, g in enumerate(self.goals)}
        self.radius: dict[Goal, float] = {}
        if self.discrete:
            self._keys = {g: np.unique(self.keys(np.concatenate(self.states[g]))) for g in self.goals}
            self._off_table = None
            if n_states(observation_space) <= SUPPORT_TABLE_STATES:  # one extra all-True row: a goal without support
                self._off_table = np.ones((len(self.goals) + 1, n_states(observation_space)), dtype=bool)
                for g, keys in self._keys.items():
                    self._off_table[self._row[g], keys] = False
        else:
            from scipy.spatial import cKDTree

            self._trees, self._distinct = {}, {}
            for g in self.goals:
                distinct, visits = np.unique(self.flat(np.concatenate(self.states[g])), axis=0, return_counts=True)
                self._trees[g] = cKDTree(distinct)
                self.radius[g] = support_radius(distinct, self._trees[g])
                if len(distinct):
                    self._distinct[g] = distinct, visits
        self._others: dict[Goal, np.ndarray] = {}
        self._replacements: dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray | None]] = {}
        self.alpha: float | None = None
        self.bandwidth: float | None = None
        if self.discrete:
            self._learn_counts()
        else:
            self._learn_density()

    # ----------------------------------------------------------------------------------------------- occupancy

    def _learn_counts(self) -> None:
        """Visit counts per goal, and the Dirichlet prior weight chosen by leave-one-demonstration-out likelihood."""
        size = float(n_states(self.observation_space))
        per_demo = {g: [np.unique(self.keys(s), return_counts=True) for s in self.states[g]] for g in self.goals}
        self._counts = {g: np.unique(np.concatenate([self.keys(s) for s in self.states[g]]), return_counts=True)
                        for g in self.goals}
        scores = np.zeros(len(ALPHAS))
        held_out = False
        for g in self.goals:
            keys, counts = self._counts[g]
            total = counts.sum()
            if len(per_demo[g]) < 2:
                continue
            held_out = True
            for demo_keys, demo_counts in per_demo[g]:
                rest = counts[np.searchsorted(keys, demo_keys)] - demo_counts  # its states' visits by the others
                rest_total = total - demo_counts.sum()
                for i, alpha in enumerate(ALPHAS):
                    scores[i] += np.sum(demo_counts * (np.log(rest + alpha) - np.log(rest_total + alpha * size)))
        self.alpha = float(ALPHAS[int(np.argmax(scores))]) if held_out else ALPHA_DEFAULT
        self._size = size
        self._log_table = None
        if size <= SUPPORT_TABLE_STATES:  # one extra row: a goal without demonstrations (the prior alone)
            self._log_table = np.full((len(self.goals) + 1, int(size)), -math.log(size))
            for g, (keys, counts) in self._counts.items():
                row = self._log_table[self._row[g]]
                row[:] = math.log(self.alpha) - math.log(counts.sum() + self.alpha * size)
                row[keys] = np.log(counts + self.alpha) - math.log(counts.sum() + self.alpha * size)

    def _learn_density(self) -> None:
        """The shared scaling of coordinates, and the bandwidth chosen by leave-one-demonstration-out likelihood."""
        every = self.flat(np.concatenate([s for g in self.goals for s in self.states[g]]))
        self._centre, self._scale = every.mean(axis=0), scale_of(every)
        self._points = {g: self._scaled(np.concatenate(self.states[g])) for g in self._distinct}
        scores = np.zeros(len(BANDWIDTHS))
        held_out = False
        for g in self._distinct:
            if len(self.states[g]) < 2:
                continue
            held_out = True
            points = self._points[g]
            demo = np.concatenate([np.full(len(s), j) for j, s in enumerate(self.states[g])])
            chosen = np.unique(np.linspace(0, len(points) - 1, min(len(points), HELD_OUT_STATES)).astype(int))
            squared = _squared_distances(points[chosen], points)
            squared[demo[chosen][:, None] == demo[None, :]] = np.inf  # leave the state's own demonstration out
            rest = len(points) - np.bincount(demo)[demo[chosen]]  # the states the estimate is made from
            for i, h in enumerate(BANDWIDTHS):
                held = _log_kde(squared, h, rest, points.shape[1])
                scores[i] += np.sum(held[np.isfinite(held)])  # nothing to leave out for it: not counted
        self.bandwidth = float(BANDWIDTHS[int(np.argmax(scores))]) if held_out else BANDWIDTH_DEFAULT

    def _scaled(self, states: np.ndarray) -> np.ndarray:
        return (self.flat(states) - self._centre) / self._scale

    @functools.cached_property
    def _packed(self) -> _Packed:
        """Every goal's distinct training states stacked for one matrix product (built at first use)."""
        return _Packed.of(self)

    def log_occupancy(self, goals: Sequence[Goal], states: np.ndarray) -> np.ndarray:
        """``(K, T)``: the log of each goal's occupancy at each state (a density on continuous observations).

        Raises:
            UserError: For a goal without demonstrations on an unbounded observation box.
        """
        if self.discrete:
            keys = self.keys(states)
            if self._log_table is not None:
                rows = _rows(goals, self.goals)
                return self._log_table[:-1, keys] if rows is None else self._log_table[rows[:, None], keys[None, :]]
            out = np.full((len(goals), len(keys)), -math.log(self._size))
            for k, goal in enumerate(goals):
                if tuple(goal) in self._counts:
                    sorted_keys, counts = self._counts[tuple(goal)]
                    found = _member(sorted_keys, keys)
                    visits = np.zeros(len(keys))
                    visits[found] = counts[np.searchsorted(sorted_keys, keys[found])]
                    out[k] = np.log(visits + self.alpha) - math.log(counts.sum() + self.alpha * self._size)
            return out
        packed = self._packed
        rows = _rows(goals, packed.goals)
        own = packed.by_blocks(states, self._log_kde_block)
        if rows is None:
            return own
        missing = rows < 0
        return np.where(missing[:, None], -self._log_volume() if missing.any() else 0.0, own[rows])

    def _log_kde_block(self, features: np.ndarray, states: np.ndarray) -> np.ndarray:
        """``(T, G)``: the log density of each packed goal at a block of states (``features``: theirs)."""
        packed = self._packed
        terms = features @ packed.occupancy  # (T, M): -|x - y|^2 / (2 h^2) in scaled coordinates
        largest = np.maximum.reduceat(terms, packed.starts, axis=1)  # each goal's nearest state's term
        by_goal = terms.reshape(len(terms), len(packed.goals), packed.width)
        by_goal -= largest[:, :, None]  # so the sums cannot underflow
        np.maximum(terms, _EXPONENT_FLOOR, out=terms)  # a term that small is nothing beside the largest (1)
        np.exp(terms, out=terms)
        out = np.log(terms @ packed.counts)
        out += largest
        if packed.constant is not None:
            out += packed.constant
        return out

    def _log_volume(self) -> float:
        low, high = (np.asarray(b, dtype=np.float64) for b in (self.observation_space.low, self.observation_space.high))
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
            raise UserError(f"a goal without demonstrations has no occupancy on an unbounded observation box "
                            f"{self.observation_space}")
        return float(np.sum(np.log(high - low)))

    # ----------------------------------------------------------------------------------------------- support

    def keys(self, states: np.ndarray) -> np.ndarray:
        """Discrete states' flat indices, ``(T,)``."""
        return state_index(np.asarray(states), self.observation_space)

    @staticmethod
    def flat(states: np.ndarray) -> np.ndarray:
        """Continuous states as ``(T, D)`` float64 rows."""
        states = np.asarray(states, dtype=np.float64)
        return states.reshape(len(states), -1)

    def off_support(self, goals: Sequence[Goal], states: np.ndarray) -> np.ndarray:
        """``(K, T)``: whether each state lies off each goal's support."""
        if self.discrete:
            keys = self.keys(states)
            if self._off_table is not None:
                rows = _rows(goals, self.goals)
                return self._off_table[:-1, keys] if rows is None else self._off_table[rows[:, None], keys[None, :]]
            return np.stack([~_member(self._keys.get(tuple(g), np.empty(0, np.int64)), keys) for g in goals])
        packed = self._packed
        rows = _rows(goals, packed.goals)
        own = packed.by_blocks(states, self._off_support_block)
        return own if rows is None else np.where(rows[:, None] < 0, True, own[rows])

    def _off_support_block(self, features: np.ndarray, states: np.ndarray) -> np.ndarray:
        """``(T, G)``: whether a block of states lies off each packed goal's support."""
        packed = self._packed
        nearest = np.minimum.reduceat(features @ packed.support, packed.starts, axis=1)  # squared distances
        off = nearest > packed.high
        beyond = nearest > packed.low  # off, or within rounding of the radius
        if np.count_nonzero(beyond) != np.count_nonzero(off):  # those: the distance as the goal's KD-tree measures it
            unsure = beyond != off
            flat = self.flat(states)
            for t, k in zip(*np.nonzero(unsure)):
                goal = packed.goals[k]
                off[t, k] = self._trees[goal].query(flat[t], k=1)[0] > self.radius[goal]
        return off

    def others_off_support(self, goal: Goal) -> np.ndarray:
        """The distinct training states of every other goal that lie off ``goal``'s support, sorted, ``(N, ...)``
        (read-only; computed once per goal)."""
        goal = tuple(goal)
        if goal not in self._others:
            others = [s for g in self.goals if g != goal for s in self.states[g]]
            if not others:
                found = np.empty((0, *self.observation_space.shape), dtype=self.observation_space.dtype)
            else:
                distinct = np.unique(np.concatenate(others), axis=0)
                found = distinct[self.off_support([goal], distinct)[0]]
            found.flags.writeable = False
            self._others[goal] = found
        return self._others[goal]

    def replace_off_support(self, output: PolicyOutput, goals: Sequence[Goal], states: np.ndarray,
                            rule: str) -> PolicyOutput:
        """``output`` with each goal's outputs at states off its support replaced by ``rule``'s.

        ``"stay"``: the no-op (discrete actions: probability 1 on it; continuous ones: the mean set to it, the std
        kept). ``"uniform"``: no preference (discrete: equal probabilities; continuous: the uniform distribution
        over the action box as its mean, the box's centre, and std, its width over sqrt(12)). ``"trust"``: as it is.

        Raises:
            UserError: For ``"stay"`` without a no-op, or ``"uniform"`` on an unbounded action box.
        """
        if rule == "trust":
            return output
        off = self.off_support(goals, states)
        if not np.count_nonzero(off):
            return output
        mask = off[:, :, None]
        if output.probs is not None:
            return dataclasses.replace(output, probs=_put(output.probs, mask, self._replacement(rule, output)[0]))
        mean, std = self._replacement(rule, output)
        if std is None:
            return dataclasses.replace(output, mean=_put(output.mean, mask, mean))
        # a (K, 1, D) std (one per goal) becomes (K, T, D)
        return dataclasses.replace(output, mean=_put(output.mean, mask, mean), std=np.where(mask, std, output.std))

    def _replacement(self, rule: str, output: PolicyOutput) -> tuple[np.ndarray, np.ndarray | None]:
        """What ``rule`` puts at an off-support state in ``output``'s dtypes: action probabilities (discrete
        actions), or :meth:`replacement`'s mean and std (None: the policy's own); made once per rule and dtypes."""
        first = output.probs if output.probs is not None else output.mean
        key = (rule, first.dtype, None if output.std is None else output.std.dtype)
        if key not in self._replacements:
            if output.probs is not None:
                n = first.shape[-1]
                if rule == "uniform":
                    row = np.full(n, 1.0 / n)
                else:
                    row = np.eye(n)[self._noop(rule) - int(self.action_space.start)]
                self._replacements[key] = row.astype(first.dtype), None
            else:
                mean, std = self.replacement(rule)
                kept = std is None or output.std is None
                self._replacements[key] = mean.astype(first.dtype), None if kept else std.astype(output.std.dtype)
        return self._replacements[key]

    def replacement(self, rule: str) -> tuple[np.ndarray, np.ndarray | None]:
        """The mean and std (None: the policy's own) an off-support state gets under ``rule`` on a Box action space.

        Raises:
            UserError: For ``"stay"`` without a no-op, or ``"uniform"`` on an unbounded action box.
        """
        low, high = (np.asarray(b, dtype=np.float64) for b in (self.action_space.low, self.action_space.high))
        if rule == "stay":
            return np.asarray(self._noop(rule), dtype=np.float64), None
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
            raise UserError(f"off_support='uniform' needs a bounded action box, got {self.action_space}")
        return (low + high) / 2, (high - low) / math.sqrt(12)

    def _noop(self, rule: str) -> Any:
        if self.noop is None:
            raise UserError(f"off_support={rule!r} needs the domain's no-op action (noop_action); it declares none")
        return self.noop


@dataclasses.dataclass(frozen=True)
class _Packed:
    """Every goal's distinct training states stacked (continuous observations), so that a batch of states meets all
    of them in one matrix product: ``features(x) @ support`` gives the squared distances to them and
    ``features(x) @ occupancy`` the kernel's exponents, ``features(x) = [x', x' * x', 1]``, ``x'`` the state less
    the training states' mean (which keeps the expansion's cancellation small).

    Attributes:
        goals: The goals with training states, in the evidence's order; ``G`` of them, ``M = G * width`` stacked
            states: each goal's distinct ones, padded to ``width`` by repeating its first (with no visits).
        centre: ``(D,)`` the training states' mean.
        starts: ``(G,)`` where each goal's states begin among the stacked ones.
        width: The stacked states of each goal.
        support: ``(2D + 1, M)``: squared Euclidean distances in raw coordinates.
        low, high: ``(G,)`` each goal's squared support radius less and plus the rounding allowance; a squared
            distance between them is settled by the goal's KD-tree.
        occupancy: ``(2D + 1, M)``: ``-|x - y|^2 / (2 h^2)`` in scaled coordinates.
        counts: ``(M, G)``: each stacked state's visits by its goal (zero for the others), times ``exp(constant)``.
        constant: ``(G,)``: each goal's log normaliser (its visits, the kernel's and the scaling's) where ``counts``
            does not carry it (zero where it does, when its exponential is a normal float; None: every goal's does).
        ones: ``(B, 1)`` ones, the last feature of up to ``B`` states.
    """

    goals: list[Goal]
    centre: np.ndarray
    starts: np.ndarray
    width: int
    support: np.ndarray
    low: np.ndarray
    high: np.ndarray
    occupancy: np.ndarray
    counts: np.ndarray
    constant: np.ndarray | None
    ones: np.ndarray

    @classmethod
    def of(cls, evidence: Evidence) -> _Packed:
        goals = list(evidence._distinct)
        width = max(len(evidence._distinct[g][0]) for g in goals)
        # each goal's states padded to the same number by repeating its first one, with no visits
        y = np.concatenate([np.concatenate([d, np.repeat(d[:1], width - len(d), axis=0)])
                            for d, _ in (evidence._distinct[g] for g in goals)]) - evidence._centre
        m, dim = y.shape
        counts = np.zeros((m, len(goals)))
        for k, g in enumerate(goals):
            visits = evidence._distinct[g][1]
            counts[k * width: k * width + len(visits), k] = visits
        squared = np.einsum("md,md->m", y, y)
        support = np.concatenate([-2.0 * y.T, np.ones((dim, m)), squared[None]])
        radius2 = np.array([evidence.radius[g] ** 2 for g in goals])
        allowance = _ROUNDING * (16.0 * float(squared.max()) + radius2)
        h = evidence.bandwidth
        weight = 1.0 / (evidence._scale * evidence._scale)  # scaled coordinates' squared distances, from raw ones
        kappa = 1.0 / (2.0 * h * h)
        occupancy = np.concatenate([2.0 * kappa * weight[:, None] * y.T, np.repeat(-kappa * weight[:, None], m, 1),
                                    -kappa * (weight @ (y * y).T)[None]])
        jacobian = float(np.sum(np.log(evidence._scale)))
        constant = -np.log(counts.sum(axis=0)) - dim * math.log(h * math.sqrt(2.0 * math.pi)) - jacobian
        folded = np.abs(constant) < 600.0  # exp(constant) a normal float: the visits carry it
        counts *= np.where(folded, np.exp(np.where(folded, constant, 0.0)), 1.0)
        constant = None if folded.all() else np.where(folded, 0.0, constant)
        return cls(goals, evidence._centre, np.arange(len(goals)) * width, width, support, radius2 - allowance,
                   radius2 + allowance, occupancy, counts, constant, np.ones((256, 1)))

    def features(self, states: np.ndarray) -> np.ndarray:
        """``(T, 2D + 1)``: ``[x', x' * x', 1]`` for ``(T, ...)`` states."""
        centred = states.reshape(len(states), len(self.centre)) - self.centre
        ones = self.ones[: len(states)] if len(states) <= len(self.ones) else np.ones((len(states), 1))
        return np.concatenate((centred, centred * centred, ones), axis=1)

    def by_blocks(self, states: np.ndarray, block: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
        """``(G, T)``: ``block(features, states)``'s ``(T, G)`` over blocks of states small enough that their
        ``(T, M)`` products stay within :data:`_BLOCK_ENTRIES` entries, transposed."""
        states = np.asarray(states)
        step = max(1, _BLOCK_ENTRIES // self.support.shape[1])
        if len(states) <= step:
            return block(self.features(states), states).T
        return np.concatenate([block(self.features(states[i: i + step]), states[i: i + step])
                               for i in range(0, len(states), step)]).T


def _put(array: np.ndarray, mask: np.ndarray, value: np.ndarray) -> np.ndarray:
    """A copy of ``array`` holding ``value`` where ``mask`` is set (``np.where(mask, value, array)``, for an
    ``array`` of the result's shape and dtype)."""
    out = array.copy()
    np.copyto(out, value, where=mask)
    return out


def _rows(goals: Sequence[Goal], known: list[Goal]) -> np.ndarray | None:
    """Each of ``goals``' row among ``known`` (-1: not there), or None when ``goals`` are ``known`` in order."""
    if goals == known:
        return None
    at = {g: i for i, g in enumerate(known)}
    return np.array([at.get(tuple(g), -1) for g in goals], dtype=np.int64)


def _squared_distances(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(Q, N)`` squared Euclidean distances between rows."""
    squared = (queries * queries).sum(1)[:, None] - 2.0 * queries @ points.T + (points * points).sum(1)[None, :]
    return np.maximum(squared, 0.0)


def _log_kde(squared: np.ndarray, bandwidth: float, n: np.ndarray | int, dim: int) -> np.ndarray:
    """Log of an isotropic Gaussian kernel density at each query, from its ``(Q, N)`` squared distances to the
    ``n`` points (infinite distances: points left out)."""
    nearest = squared.min(axis=1, keepdims=True)
    scale = 1.0 / (2.0 * bandwidth * bandwidth)
    with np.errstate(invalid="ignore", divide="ignore"):
        shifted = np.exp((nearest - squared) * scale).sum(axis=1)  # the nearest point's term is 1: no underflow
    sums = np.log(shifted) - nearest[:, 0] * scale
    return sums - np.log(n) - dim * math.log(bandwidth * math.sqrt(2.0 * math.pi))


def support_radius(distinct: np.ndarray, tree: Any = None) -> float:
    """The support radius of a goal's distinct ``(N, D)`` training states (see :class:`Evidence`)."""
    floor = RADIUS_FLOOR * max(1.0, float(np.max(np.abs(distinct))) if distinct.size else 1.0)
    if len(distinct) < 2:
        return floor
    if tree is None:
        from scipy.spatial import cKDTree

        tree = cKDTree(distinct)
    nearest = tree.query(distinct, k=2)[0][:, 1]  # the first neighbour is the state itself
    return max(float(np.percentile(nearest, RADIUS_PERCENTILE)), floor)


def _member(sorted_keys: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Whether each of ``keys`` is in ``sorted_keys``."""
    if not len(sorted_keys):
        return np.zeros(len(keys), dtype=bool)
    at = np.minimum(np.searchsorted(sorted_keys, keys), len(sorted_keys) - 1)
    return sorted_keys[at] == keys


def _checked_noop(noop: Any, action_space: spaces.Space) -> Any:
    """The domain's no-op as an action of ``action_space`` (an int, or a float array of the box's shape)."""
    if isinstance(action_space, spaces.Discrete):
        if isinstance(noop, (bool, np.bool_)) or not isinstance(noop, (int, np.integer)) \
                or not action_space.start <= noop < action_space.start + action_space.n:
            raise UserError(f"the domain's noop_action {noop!r} is not an action of {action_space}")
        return int(noop)
    value = np.asarray(noop, dtype=np.float64)
    if not isinstance(action_space, spaces.Box) or value.shape != action_space.shape \
            or not np.all((value >= action_space.low) & (value <= action_space.high)):
        raise UserError(f"the domain's noop_action {noop!r} is not an action of {action_space}")
    return value
