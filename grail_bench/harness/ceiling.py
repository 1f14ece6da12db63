"""The Bayes ceiling: the best accuracy any recognizer can reach on a task.

A recognizer that knew the demonstrator exactly would answer, for each
observation ``o``, the goal with the largest posterior ``P(g | o)`` (goals are
equally likely in every task). Its expected accuracy, ``E_o[max_g P(g | o)]``,
bounds every recognizer's accuracy under that protocol and level.

* ``exact``: every demonstration and every observation of it is enumerated
  (optimal and biased demonstrators, path-span protocols and prefixes).
* ``monte-carlo``: observations are drawn as the harness draws them, and the
  posterior of each is computed exactly; the estimate comes with its
  standard error.

The *pairs-only* ceiling asks less of a recognizer's knowledge and more of its
form: each goal is scored from the observed pairs through that goal's policy
alone (GRAIL, GRAQL and DRACO all score so), with every policy the
demonstrator's own (``P(action | state)`` over the states it visits, zero
elsewhere) and the observed actions' log-probability summed; ties are broken
at random. It leaves out what the pairs say beyond their actions: how many
there are (a longer path yields more) and how likely the demonstrator is to
visit their states. Where a demonstrator is deterministic (one route per goal)
two goals whose demonstrators act alike on every observed state score alike
under any per-pair score, so no such recognizer does better.

Under an observation model (:mod:`grail_bench.task.observation`) the
ceilings score what the recognizer sees:

* ``noise``: a noisy observation's likelihood sums, over which ``m`` of its
  ``k`` steps were spurious and what they showed before, the clean
  observations' likelihoods, each weighted ``1 / (C(k, m) (n - 1)^m)`` for
  ``n`` discrete actions. Exact where the demonstrator is enumerated (each
  observation spread over its noisy versions), else a Monte Carlo estimate
  whose likelihoods enumerate the ``C(k, m) (n - 1)^m`` clean candidates
  (refused beyond :data:`NOISY_LIMIT` of them). The pairs-only ceiling scores
  each observed pair with the mixture ``(1 - w) pi(a | s) + w (1 - pi(a | s)) / (n - 1)``,
  ``w = m / k`` the share of spurious steps (a step's probability of showing
  ``a`` when it is spurious with probability ``w`` and shows one of the
  ``n - 1`` other actions uniformly then); states the policy never visits
  stay impossible, as noise keeps the states. Noise on a continuous (``Box``)
  action space is refused: the demonstrators' pairs are not densities.
* ``states`` or ``actions`` channel: each observation is projected on its
  channel and equal projections pooled, which marginalises the hidden one
  exactly; only where the demonstrator is enumerated (the likelihood of a
  projection is a sum over every hidden sequence otherwise), and not for the
  pairs-only ceiling, which scores actions in states.

Only regimes whose demonstrator has a known likelihood have a ceiling: a
domain lists them in ``ceiling_regimes`` and builds the per-goal model
(:class:`~grail_bench.domains.base.GoalModel`) in ``demonstrator`` (MiniGrid:
every regime; PointMaze: the noise-free ones; PandaReach: none).

Reports never compute a ceiling themselves: :func:`ceilings_for` gives every
ceiling a set of records needs, once (each level is cached on disk), and
:func:`online_ceilings` the curves of online records.
"""

from __future__ import annotations

import itertools
import json
import math
from collections import defaultdict
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, Hashable, Iterable, Iterator, NamedTuple, Sequence

import numpy as np

from grail_bench.core.atomic import write_text
from grail_bench.core.bounds import Range
from grail_bench.core.cache import key_digest
from grail_bench.core.errors import UserError
from grail_bench.core.paths import cache_dir
from grail_bench.domains.base import GoalModel
from grail_bench.harness.executors import Executor, SerialExecutor
from grail_bench.task import GRTask, find_task
from grail_bench.task.overrides import TaskOverrides
from grail_bench.task.observation import (
    BUILTIN,
    PREFIX_OF,
    ObservationProtocol,
    Selection,
    SpuriousActions,
    get_protocol,
    n_observed,
    n_spurious,
    parse_label,
    protocol_label,
)

METHODS = ("auto", "exact", "monte-carlo")
EXACT_LIMIT = 2_000_000  # observations enumerated at most before "auto" samples instead
CACHED_SEED = 0  # the Monte Carlo seed of every cached ceiling: its cache key records it
NOISY_LIMIT = 500  # clean candidates of one noisy observation a Monte Carlo likelihood sums at most
#: Monte Carlo observations of one ceiling (published ceilings draw 2000; checked before any work).
SAMPLES = Range(2, 1_000_000)


@dataclass(frozen=True)
class Ceiling:
    """The Bayes ceiling of a task under one protocol and level.

    Attributes:
        task: The task ID.
        protocol: The protocol as stored (``"subset"``, ``"prefix+floor"``, ...).
        observability: The level.
        accuracy: Best achievable expected accuracy.
        stderr: Standard error of a Monte Carlo estimate (0 when exact).
        chance: Accuracy of guessing, ``1 / n_goals``.
        method: ``"exact"`` or ``"monte-carlo"``.
        samples: Observations drawn (0 when exact).
        pairs_only: Whether this is the pairs-only ceiling (see the module docstring).
    """

    task: str
    protocol: str
    observability: float
    accuracy: float
    stderr: float
    chance: float
    method: str
    samples: int
    pairs_only: bool = False

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def normalised(score: float, ceiling: float, chance: float) -> float | None:
    """``(score - chance) / (ceiling - chance)``: 0 at chance, 1 at the ceiling (None if the ceiling is chance)."""
    if ceiling - chance <= 1e-12:
        return None
    return (score - chance) / (ceiling - chance)


def has_ceiling(task: GRTask) -> bool:
    """Whether the demonstrator of the task's test demonstrations has a known likelihood: its test regime's,
    under the shifts of the dynamics the domain's likelihood takes exactly (its ``ceiling_shifts``)."""
    test = task.test_task()
    exact = getattr(task.spec, "ceiling_shifts", frozenset())
    return test.regime in task.spec.ceiling_regimes and set(test.test_params) <= set(exact)


def _selection(protocol: str, level: float, rounding: str) -> Selection:
    chosen = get_protocol(protocol)
    if not isinstance(chosen, ObservationProtocol):
        raise UserError(f"the Bayes ceiling knows only the built-in protocols, not {chosen.name!r}")
    return Selection(horizon=chosen.span == "horizon", random_subset=chosen.random_subset, level=level,
                     rounding=rounding)


@dataclass(frozen=True)
class ObservationModel:
    """What the recognizer sees of a protocol's observation: its noise and channel.

    Attributes:
        noise: Share of the observed steps that are spurious.
        channel: ``"pairs"``, ``"states"`` or ``"actions"``.
        spurious: The action space's spurious actions (needed when ``noise > 0``).
    """

    noise: float = 0.0
    channel: str = "pairs"
    spurious: SpuriousActions | None = None

    @property
    def plain(self) -> bool:
        """Whether it shows the protocol's observations as they are."""
        return not self.noise and self.channel == "pairs"

    def check(self, demonstrators: Sequence[GoalModel], pairs_only: bool, task_id: str) -> None:
        """Refuse what the ceiling cannot compute generically (see the module docstring).

        Raises:
            UserError: In one line, saying why.
        """
        if self.noise and (self.spurious is None or not self.spurious.discrete
                           or any(d.action_size != 1 for d in demonstrators)):
            raise UserError(f"{task_id}: the noisy ceiling needs one discrete action per step; spurious actions "
                            "drawn from a continuous box have a density the demonstrator's pairs do not")
        if self.channel != "pairs" and pairs_only:
            raise UserError(f"{task_id}: the pairs-only ceiling scores actions in states; it has no "
                            f"{self.channel}-only form")
        if self.channel != "pairs" and not all(d.enumerable for d in demonstrators):
            raise UserError(f"{task_id}: the {self.channel}-only ceiling needs a demonstrator whose "
                            "demonstrations can be enumerated (marginalising the hidden channel of a sampled one "
                            "sums over every hidden sequence)")

    def views(self, observation: tuple, action_size: int) -> Iterator[tuple[tuple, float]]:
        """Every observation the recognizer can see of a protocol's ``observation``, with its probability."""
        for noisy, p in self.noisy(observation):
            yield self.project(noisy, action_size), p

    def noisy(self, observation: tuple) -> Iterator[tuple[tuple, float]]:
        """Every noisy version of ``observation`` with its probability; the relation is symmetric, so these are
        also the clean observations a noisy one can come from, with the same weights."""
        k = len(observation)
        m = n_spurious(self.noise, k) if self.noise else 0
        if m == 0:
            yield observation, 1.0
            return
        weight = 1.0 / (math.comb(k, m) * (self.spurious.n - 1) ** m)
        for steps in itertools.combinations(range(k), m):
            for shown in itertools.product(*(self.spurious.others(observation[i][-1]) for i in steps)):
                out = list(observation)
                for i, a in zip(steps, shown):
                    out[i] = (*observation[i][:-1], a)
                yield tuple(out), weight

    def n_noisy(self, k: int) -> int:
        """How many noisy versions an observation of ``k`` pairs has."""
        m = n_spurious(self.noise, k) if self.noise else 0
        return math.comb(k, m) * (self.spurious.n - 1) ** m if m else 1

    def project(self, observation: tuple, action_size: int) -> tuple:
        """The channel's part of each pair."""
        if self.channel == "states":
            return tuple(pair[:-action_size] for pair in observation)
        if self.channel == "actions":
            return tuple(pair[-action_size:] for pair in observation)
        return observation

    def sample(self, observation: tuple, rng: np.random.Generator) -> tuple:
        """One noisy version of ``observation``, drawn as the harness draws it (only for the pairs channel)."""
        k = len(observation)
        m = n_spurious(self.noise, k) if self.noise else 0
        if m == 0:
            return observation
        out = list(observation)
        steps = rng.choice(k, size=m, replace=False)
        shown = self.spurious.draw(np.array([out[i][-1] for i in steps]), rng)
        for i, a in zip(steps, shown.tolist()):
            out[i] = (*out[i][:-1], a)
        return tuple(out)

    def likelihood(self, d: GoalModel, observation: tuple, selection: Selection) -> float:
        """Probability that ``d`` yields the (noisy) ``observation`` (pairs channel).

        Raises:
            UserError: Beyond :data:`NOISY_LIMIT` clean candidates.
        """
        if not self.noise:
            return d.likelihood(observation, selection)
        if self.n_noisy(len(observation)) > NOISY_LIMIT:
            raise UserError(f"a noisy observation of {len(observation)} pairs has {self.n_noisy(len(observation))} "
                            f"clean candidates, more than the {NOISY_LIMIT} the Monte Carlo ceiling sums; use a "
                            "lower level or noise")
        return math.fsum(w * d.likelihood(clean, selection) for clean, w in self.noisy(observation))


PLAIN = ObservationModel()


def _demonstrators(task: GRTask) -> list[GoalModel]:
    if not has_ceiling(task):
        known = ", ".join(task.spec.ceiling_regimes) or "none"
        shifts = ", ".join(sorted(getattr(task.spec, "ceiling_shifts", ()))) or "none"
        raise UserError(f"{task.id}: the Bayes ceiling needs a demonstrator with a known likelihood; "
                        f"{task.domain} has one for these regimes: {known} (and these test shifts: {shifts})")
    test = task.test_task()  # the test demonstrations' demonstrator: what a recognizer is judged on
    return [task.spec.demonstrator(test, goal) for goal in task.goals]


def _exact_size(demonstrators: list, selection, model: ObservationModel = PLAIN) -> int | None:
    """Observations an exact enumeration visits, or None if it cannot enumerate."""
    if not all(d.enumerable for d in demonstrators):
        return None
    size = 0
    for d in demonstrators:
        for actions, _ in d.support():
            n = len(d.span(actions, selection))
            k = n_observed(selection.level, n, selection.rounding)
            size += (math.comb(n, k) if selection.random_subset else 1) * model.n_noisy(k)
    return size


def _exact(demonstrators: list, selection, model: ObservationModel = PLAIN) -> float:
    joint: dict[tuple, np.ndarray] = defaultdict(lambda: np.zeros(len(demonstrators)))
    for g, d in enumerate(demonstrators):
        for actions, p_demo in d.support():
            for obs, p_obs in d.observations(actions, selection):
                for seen, p_seen in model.views(obs, d.action_size):
                    joint[seen][g] += p_demo * p_obs * p_seen
    total = math.fsum(float(v.max()) for v in joint.values()) / len(demonstrators)
    return min(1.0, total)  # rounding in the many small terms can push a certain answer past 1


def _monte_carlo(demonstrators: list, selection, samples: int, rng: np.random.Generator,
                 hit: Callable[[tuple, int], float], model: ObservationModel = PLAIN) -> tuple[float, float, int]:
    """Mean of ``hit(observation, goal index)`` over observations drawn from each goal alike (then made noisy
    by ``model``), its standard error and the number drawn."""
    per_goal = max(1, math.ceil(samples / len(demonstrators)))  # stratified: equal draws per goal
    values = np.array([hit(model.sample(d.sample_observation(rng, selection), rng), g)
                       for g, d in enumerate(demonstrators) for _ in range(per_goal)])
    stderr = float(values.std(ddof=1) / math.sqrt(len(values))) if len(values) > 1 else float("nan")
    return float(values.mean()), stderr, len(values)


def _bayes_hit(demonstrators: list, selection, model: ObservationModel = PLAIN) -> Callable[[tuple, int], float]:
    """The Bayes recognizer's expected accuracy on one observation: its largest posterior."""
    def hit(observation: tuple, goal: int) -> float:
        like = np.array([model.likelihood(d, observation, selection) for d in demonstrators])
        return float(like.max() / like.sum())
    return hit


def _policies(demonstrators: list[GoalModel], selection: Selection, samples: int,
              rng: np.random.Generator) -> list[dict[Hashable, float]]:
    """Each demonstrator as a policy over the pairs the protocol samples from: ``{pair: P(action | state)}``,
    states weighted by how often it visits them (over its support, else over ``samples`` demonstrations)."""
    whole = replace(selection, random_subset=False, level=1.0)  # a demonstration's every pair
    policies = []
    for d in demonstrators:
        visits: dict[Hashable, float] = defaultdict(float)
        if d.enumerable:
            for demonstration, p in d.support():
                for pair in d.span(demonstration, selection):
                    visits[pair] += p
        else:
            for _ in range(samples):
                for pair in d.sample_observation(rng, whole):
                    visits[pair] += 1.0
        per_state: dict[Hashable, float] = defaultdict(float)
        for pair, w in visits.items():
            per_state[pair[:-d.action_size]] += w
        policies.append({pair: w / per_state[pair[:-d.action_size]] for pair, w in visits.items()})
    return policies


def _pair_log_prob(pi: dict[Hashable, float], states: set, pair: tuple, action_size: int, w: float,
                   u: float) -> float:
    """Log-probability of one observed pair under a policy when a share ``w`` of the steps show one of the other
    actions, each with probability ``u`` (the mixture of the module docstring; ``w = 0``: the policy's own)."""
    if not w:
        return math.log(pi[pair]) if pair in pi else -math.inf
    if pair[:-action_size] not in states:
        return -math.inf  # noise keeps the states: one the demonstrator never visits stays impossible
    p = pi.get(pair, 0.0)
    return math.log((1.0 - w) * p + w * u * (1.0 - p))


def _pairs_only_hit(policies: list[dict[Hashable, float]], visited: list[set], observation: tuple, goal: int,
                    model: ObservationModel = PLAIN, action_size: int = 1) -> float:
    """Expected accuracy of the summed log-probability under each policy (visiting the states ``visited``; the
    noise mixture under a noisy ``model``) on one observation, ties at random."""
    w = n_spurious(model.noise, len(observation)) / len(observation) if model.noise else 0.0
    u = model.spurious.density() if model.noise else 0.0
    scores = np.array([math.fsum(_pair_log_prob(pi, states, pair, action_size, w, u) for pair in observation)
                       for pi, states in zip(policies, visited)])
    best = np.flatnonzero(scores >= scores.max() - 1e-9)  # equal policies can differ in the last bits
    return float(goal in best) / len(best)


def _pairs_only(demonstrators: list[GoalModel], selection: Selection, exact: bool, samples: int,
                seed: int, model: ObservationModel = PLAIN) -> tuple[float, float, int]:
    rng = np.random.default_rng(seed)
    policies = _policies(demonstrators, selection, samples, rng)
    size = demonstrators[0].action_size
    visited = [{pair[:-size] for pair in pi} for pi in policies]
    hit = partial(_pairs_only_hit, policies, visited, model=model, action_size=size)
    if exact:
        total = math.fsum(p_demo * p_obs * p_seen * hit(seen, g)
                          for g, d in enumerate(demonstrators) for demonstration, p_demo in d.support()
                          for obs, p_obs in d.observations(demonstration, selection)
                          for seen, p_seen in model.noisy(obs))
        return total / len(demonstrators), 0.0, 0
    return _monte_carlo(demonstrators, selection, samples, rng, hit, model)


def _observation_model(task: GRTask, noise: float, channel: str) -> ObservationModel:
    """The observation model of a ceiling (the task's action space read only under noise)."""
    if not noise:
        return ObservationModel(channel=channel)
    return ObservationModel(noise, channel, SpuriousActions.of(task.action_space()))


def _applies(task: GRTask | None, label: str, pairs_only: bool = False) -> bool:
    """Whether a stored protocol label on ``task`` has a ceiling (known demonstrator, built-in protocol, an
    observation model it can compute)."""
    if task is None or not has_ceiling(task):
        return False
    parts = parse_label(label)
    if parts.protocol not in BUILTIN:
        return False
    if parts.noise or parts.channel != "pairs":
        try:
            _observation_model(task, parts.noise, parts.channel).check(_demonstrators(task), pairs_only, task.id)
        except UserError:
            return False
    return True


def _cache_path(task: GRTask, label: str, level: float, samples: int,
                pairs_only: bool) -> tuple[dict[str, Any], Path]:
    """The cache key of one ceiling (computed at :data:`CACHED_SEED`) and the file it is stored in."""
    key = {"task": task.id, "regime": task.regime, "goals": [list(g) for g in task.goals],
           "params": dict(task.params), "env": dict(task.env_params), "protocol": label, "level": level,
           "samples": samples, "seed": CACHED_SEED, "schema": 1,
           "domain": task.domain} | ({"pairs_only": True} if pairs_only else {})
    key |= {"test": dict(task.test_params)} if task.test_params else {}  # unshifted ceilings keep their keys
    generator = int(getattr(task.spec, "generator_version", 1))
    key |= {"generator": generator} if generator != 1 else {}  # a domain's new demonstrator: new ceilings
    return key, cache_dir() / "ceilings" / f"{key_digest(key)}.json"


def _parse(key: dict[str, Any], text: str | None) -> Ceiling | None:
    """The ceiling of a cache entry's text if it is ``key``'s and well formed, else None (compute it again)."""
    try:
        stored = json.loads(text) if text else {}
        if stored.get("key") == json.loads(json.dumps(key)):
            ceiling = Ceiling(**stored["ceiling"])
            numbers = (ceiling.observability, ceiling.accuracy, ceiling.stderr, ceiling.chance, ceiling.samples)
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in numbers) \
                    and 0 <= ceiling.accuracy <= 1 and ceiling.stderr >= 0 and ceiling.samples >= 0:
                return ceiling
    except (ValueError, TypeError, AttributeError, KeyError):
        pass
    return None


def _read(key: dict[str, Any], path: Path) -> Ceiling | None:
    """The stored ceiling, or None when it is missing, unreadable or malformed (compute it again)."""
    try:
        return _parse(key, path.read_text(encoding="utf-8"))
    except OSError:
        return None


def _entry(key: dict[str, Any], ceiling: Ceiling) -> str:
    return json.dumps({"key": key, "ceiling": ceiling.as_dict()})


def _write(key: dict[str, Any], path: Path, ceiling: Ceiling) -> None:
    write_text(path, _entry(key, ceiling))


def bayes_ceiling(task: GRTask, protocol: str, level: float, *, rounding: str | None = None, method: str = "auto",
                  samples: int = 2000, seed: int = 0, pairs_only: bool = False, noise: float = 0.0,
                  channel: str = "pairs") -> Ceiling:
    """Bayes-optimal expected accuracy of ``task`` under a protocol at one observability level.

    Args:
        task: A task whose regime has a known likelihood (see :func:`has_ceiling`).
        protocol: A built-in protocol name.
        level: Observability fraction in (0, 1].
        rounding: ``"ceil"`` or ``"floor"`` for the number of observed pairs; defaults to the task's.
        method: ``"exact"``, ``"monte-carlo"`` or ``"auto"`` (exact when it can enumerate).
        samples: Monte Carlo observations (split equally across goals); for the pairs-only ceiling of a
            demonstrator that cannot be enumerated, also the demonstrations its policy is estimated from.
        seed: Monte Carlo seed.
        pairs_only: The pairs-only ceiling instead (see the module docstring).
        noise: Share of the observed steps that are spurious (see the module docstring).
        channel: ``"pairs"``, ``"states"`` or ``"actions"``.

    Raises:
        UserError: For regimes without a known likelihood, plugin protocols, ``exact`` where it
            cannot enumerate, or an observation model it cannot compute (see the module docstring).
    """
    if method not in METHODS:
        raise UserError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    SAMPLES.check("samples", samples)
    rounding = rounding or task.rounding
    selection = _selection(protocol, level, rounding)
    demonstrators = _demonstrators(task)
    label = protocol_label(protocol, rounding, noise, channel)  # checks the noise and channel
    model = _observation_model(task, noise, channel)
    model.check(demonstrators, pairs_only, task.id)
    size = _exact_size(demonstrators, selection, model) if method != "monte-carlo" else None
    if model.channel != "pairs" and method == "monte-carlo":
        raise UserError(f"{task.id}: the {channel}-only ceiling is exact only; drop --method monte-carlo")
    if method == "exact" and (size is None or size > EXACT_LIMIT):
        raise UserError(f"{task.id}: cannot enumerate {protocol} at {level:g} exactly "
                         f"({'the demonstrator is random' if size is None else f'{size} observations'}); "
                         f"use the Monte Carlo estimate")
    common = dict(task=task.id, protocol=label, observability=level, chance=1.0 / len(task.goals))
    if pairs_only:
        exact = size is not None and size <= EXACT_LIMIT
        accuracy, stderr, n = _pairs_only(demonstrators, selection, exact, samples, seed, model)
        return Ceiling(accuracy=accuracy, stderr=stderr, method="exact" if exact else "monte-carlo", samples=n,
                       pairs_only=True, **common)
    if size is not None and size <= EXACT_LIMIT:
        return Ceiling(accuracy=_exact(demonstrators, selection, model), stderr=0.0, method="exact", samples=0,
                       **common)
    if model.channel != "pairs":
        raise UserError(f"{task.id}: the {channel}-only ceiling of {protocol} at {level:g} would enumerate {size} "
                        f"observations, more than {EXACT_LIMIT}")
    accuracy, stderr, n = _monte_carlo(demonstrators, selection, samples, np.random.default_rng(seed),
                                       _bayes_hit(demonstrators, selection, model), model)
    return Ceiling(accuracy=accuracy, stderr=stderr, method="monte-carlo", samples=n, **common)


class Cell(NamedTuple):
    """A board cell whose ceiling is asked for: a task with the parameters its runs used, a protocol and a level.

    A plain ``(task, parameters mapping, protocol label, level)`` tuple is taken too (:meth:`of`).
    """

    task: str
    params: TaskOverrides
    protocol: str
    level: float

    @classmethod
    def of(cls, cell: Sequence[Any]) -> Cell:
        """A cell from a cell or a ``(task, parameters, protocol label, level)`` tuple."""
        task, params, protocol, level = cell
        return cls(task, TaskOverrides.of(params), protocol, float(level))


def distinct_cells(cells: Iterable[Sequence[Any]]) -> list[Cell]:
    """``cells`` without repeats, in order (an offline level may also be an online fraction)."""
    return list(dict.fromkeys(Cell.of(cell) for cell in cells))


def _cell_ceiling(cell: Cell, samples: int, pairs_only: bool) -> Ceiling | None:
    """One cell's ceiling, computed (an executor's work item: no cache access, so any worker can run it), or None
    where :func:`bayes_ceiling` refuses its observation model as intractable (e.g. a noisy observation with more
    clean candidates than the Monte Carlo ceiling sums): that cell has no ceiling."""
    parts = parse_label(cell.protocol)
    try:
        return bayes_ceiling(find_task(cell.task, cell.params.as_dict()), parts.protocol, cell.level,
                             rounding=parts.rounding, samples=samples, seed=CACHED_SEED, pairs_only=pairs_only,
                             noise=parts.noise, channel=parts.channel)
    except UserError:
        return None


def ceilings_for(cells: Iterable[Sequence[Any]], samples: int = 2000, on_cell: Callable[[], None] | None = None,
                 pairs_only: bool = False, executor: Executor | None = None,
                 store: Any | None = None) -> dict[Cell, Ceiling]:
    """The Bayes ceiling (or the pairs-only one) of each ``(task, task parameters, protocol label, level)`` cell
    that has one.

    Cached cells are read here, from ``store`` (a results store's
    :class:`~grail_bench.harness.ceiling_cache.CeilingCache`) first, then from the user's cache folder; the others are
    computed on ``executor`` (default: in this process, in order) and cached by this process in both. Each entry is
    keyed by what determines the ceiling (the task's goals, regime and env parameters, the demonstrator's version,
    the protocol, level, samples and seed), so a changed task gets its ceiling computed again. ``on_cell`` is
    called once per distinct cell (for a progress bar).

    Returns:
        ``{Cell: Ceiling}``, without the cells that have none.

    Raises:
        UserError: For ``samples`` outside :data:`SAMPLES`.
    """
    SAMPLES.check("samples", samples)
    out, missing, keys = {}, {}, {}

    def tick() -> None:
        if on_cell is not None:
            on_cell()

    for cell in distinct_cells(cells):
        task = find_task(cell.task, cell.params.as_dict())
        if _applies(task, cell.protocol, pairs_only):
            keys[cell] = _cache_path(task, cell.protocol, cell.level, samples, pairs_only)
        else:
            tick()
    stored = store.get(key_digest(key) for key, _ in keys.values()) if store is not None else {}
    to_store = {}
    for cell, (key, path) in keys.items():
        ceiling = _parse(key, stored.get(key_digest(key)))
        if ceiling is None:
            ceiling = _read(key, path)
            if ceiling is None:
                missing[cell] = (key, path)
                continue
            to_store[key_digest(key)] = _entry(key, ceiling)
        out[cell] = ceiling
        tick()
    writable = store is not None and store.put(to_store)
    compute = partial(_cell_ceiling, samples=samples, pairs_only=pairs_only)
    for cell, ceiling in (executor or SerialExecutor()).map_unordered(compute, list(missing)):
        if ceiling is not None:
            key, path = missing[cell]
            _write(key, path, ceiling)
            if writable:  # each as it comes: an interrupted run keeps what it computed
                store.put({key_digest(key): _entry(key, ceiling)})
            out[cell] = ceiling
        tick()
    return out


def curve_cells(task_id: str, params: TaskOverrides | dict[str, Any], label: str,
                fractions: Sequence[float]) -> list[Cell]:
    """The cells whose Bayes ceilings make the ceiling curve of an online run (empty for plugin protocols).

    Online, the first ``n_observed(p, T)`` steps are what the offline prefix
    protocol of the same span observes at level ``p``, so the ceiling at each
    fraction is that protocol's, seen through the same channel. Noisy runs have no curve: the first steps of a
    noisy whole observation are not a noisy prefix (how many of them are spurious varies).
    """
    parts = parse_label(label)
    if parts.protocol not in PREFIX_OF or parts.noise:
        return []
    prefix = protocol_label(PREFIX_OF[parts.protocol], parts.rounding, channel=parts.channel)
    return [Cell(task_id, TaskOverrides.of(params), prefix, float(fraction)) for fraction in fractions]


def curve_of(cells: Sequence[Cell], ceilings: dict[Cell, Ceiling]) -> list[float] | None:
    """The accuracies of :func:`curve_cells`' cells in ``ceilings`` (from :func:`ceilings_for`), or None
    where any has no ceiling."""
    found = [ceilings.get(cell) for cell in cells]
    if not found or None in found:
        return None
    return [ceiling.accuracy for ceiling in found]


def ceiling_curve(task_id: str, params: dict[str, Any], label: str, fractions: Sequence[float],
                  samples: int = 2000, executor: Executor | None = None) -> list[float] | None:
    """The Bayes ceiling of an online run at each observed fraction (cached on disk; see :func:`curve_cells`).

    Returns:
        None where there is none (other domains, plugin protocols).
    """
    cells = curve_cells(task_id, params, label, fractions)
    return curve_of(cells, ceilings_for(cells, samples, executor=executor))
