"""The GR task: a domain, a goal set, a behaviour regime and its demonstrations."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import numbers
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Demos, EnvFactory, Goal, Trajectory
from grail_bench.task.domain import Domain, get_domain
from grail_bench.task.observation import BUILTIN, ROUNDINGS, available_protocols, observe, protocol_label
from grail_bench.task.overrides import TaskOverrides, freeze

if TYPE_CHECKING:
    import gymnasium as gym
    import numpy as np

ENV_ONLY = ("render_mode", "goal")  # gym.make arguments that shape one env, not the task
#: The task's own sizes (published tasks use at most 200 demonstrations per goal and 24 goals).
FIELD_BOUNDS: Mapping[str, Range] = {"n_demos": Range(2, 10_000), "n_train": Range(1, 9_999)}
#: How many candidate goals a task may have (every goal is fitted and scored: a size of work).
GOAL_COUNT = Range(2, 1_000)
#: Test-time parameters every domain takes, with the values that mean "as in training": the regime of the test
#: demonstrations and parameters of that regime (see :meth:`GRTask.test_task`). A domain's ``test_params`` add
#: its shifts of the dynamics.
TEST_DEFAULTS: Mapping[str, Any] = {"test_regime": "", "test_regime_params": {}}


class TaskFieldError(UserError):
    """A task field is invalid.

    Attributes:
        field: The field's path, e.g. ``"params.turn_prob"``.
        why: What is wrong with it.
    """

    def __init__(self, field: str, why: str) -> None:
        super().__init__(f"{field}: {why}")
        self.field, self.why = field, why


def _check_bounds(prefix: str, values: Mapping[str, Any], bounds: Mapping[str, Range]) -> None:
    """Refuse a value outside its declared bound (see :mod:`grail_bench.core.bounds`), before any work."""
    for name, bound in bounds.items():
        if name in values and not bound.contains(values[name]):
            raise TaskFieldError(f"{prefix}{name}", f"{values[name]!r} is out of range (allowed {bound})")


def _count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _env_value_error(value: Any, default: Any) -> str | None:
    """Why an env parameter's value cannot stand for its default, or None.

    The value must have the default's JSON type (an integer, a number, a string, a boolean, a list or a
    table); an integer whose default is positive is a count (``max_steps``) and must be positive. Domains
    check what their values mean; this catches what no domain may be handed (``max_steps=-1``, ``5.5``).
    """
    if isinstance(default, bool):
        return None if isinstance(value, bool) else f"expected true or false, got {value!r}"
    if isinstance(default, numbers.Integral):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            return f"expected an integer, got {value!r}"
        if default >= 1 and value < 1:
            return f"expected a positive integer, got {value!r}"
        return None
    if isinstance(default, numbers.Real):
        ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
        return None if ok else f"expected a finite number, got {value!r}"
    for kind, name in ((str, "a string"), ((list, tuple), "a list"), (Mapping, "a table")):
        if isinstance(default, kind):
            return None if isinstance(value, kind) else f"expected {name}, got {value!r}"
    return None


@dataclass(frozen=True)
class DemoSource:
    """Where tasks take their demonstrations from, installed by :mod:`grail_bench.task.demos`.

    The model imports nothing above it, so it reaches the generator, the demonstration cache and Minari
    datasets through this: importing :mod:`grail_bench.task` installs the one source
    (:func:`install_demo_source`).

    Attributes:
        generate: ``generate(task, seed, n_demos)``: the task's demonstrations, per goal.
        with_dataset: ``with_dataset(task, source)``: the task taking its demonstrations from the dataset
            ``source`` (its counts read from it, the dataset checked against the task); ``""``: the generator.
    """

    generate: Callable[[GRTask, int, int | None], Demos]
    with_dataset: Callable[[GRTask, str], GRTask]


_demo_source: DemoSource | None = None


def install_demo_source(source: DemoSource) -> None:
    """Make ``source`` where every task's demonstrations come from (:mod:`grail_bench.task.demos` calls this)."""
    global _demo_source
    _demo_source = source


def _demos() -> DemoSource:
    if _demo_source is None:  # only when grail_bench.task's __init__ did not run to its end
        raise RuntimeError("no demonstration source is installed; import grail_bench.task")
    return _demo_source


@dataclass(frozen=True)
class GRTask:
    """A goal-recognition task as registered under a ``GRAIL/`` ID.

    Every field is validated on construction (and so on
    :meth:`with_overrides`); errors are :class:`TaskFieldError`.

    Attributes:
        id: The gymnasium ID, e.g. ``"GRAIL/MiniGrid-Biased-v0"``.
        domain: Domain name (see :mod:`grail_bench.task.domain`).
        regime: Behaviour regime of the demonstrator.
        goals: Candidate goals, in a fixed order.
        params: Regime parameters, every one of the regime's (its defaults merged in).
        env_params: Keyword arguments of the domain env, every one of them.
        n_demos: Demonstrations generated per goal.
        n_train: How many of them form the training split.
        observability: Default observability levels of the task.
        protocol: Default observation protocol (see
            :mod:`grail_bench.task.observation`).
        rounding: How the default protocol rounds the number of observed pairs ``p * T``: ``"ceil"`` or
            ``"floor"`` (the baselines' gr_libs, ``int(p * T)``), at least one pair either way.
        description: One line for humans.
        source: The card file that defines the task.
        demos: A Minari dataset (a folder, a folder of datasets, or an ID) to take the demonstrations from
            instead of the generator (see :mod:`grail_bench.task.demos`); empty for the generator.
        test_params: How the test demonstrations differ from the training ones: only the test parameters
            set to something other than "as in training" (:data:`TEST_DEFAULTS` and the domain's
            ``test_params``, e.g. MiniGrid's ``test_slip``); empty for a task tested as it is trained.
    """

    id: str
    domain: str
    regime: str
    goals: tuple[Goal, ...]
    params: Mapping[str, Any] = field(default_factory=dict)
    env_params: Mapping[str, Any] = field(default_factory=dict)
    n_demos: int = 10
    n_train: int = 7
    observability: tuple[float, ...] = (0.1, 0.2, 0.3)
    protocol: str = "subset"
    rounding: str = "ceil"
    description: str = ""
    source: str = ""
    demos: str = ""
    test_params: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        spec = self.spec
        if self.regime not in spec.regimes:
            raise TaskFieldError("regime", f"unknown regime {self.regime!r} for domain {self.domain!r} "
                                           f"(known: {', '.join(spec.regimes)})")
        goals = self.goals
        if not isinstance(goals, (list, tuple)) or len(goals) < 2:
            raise TaskFieldError("goals", "expected a list of at least two goals")
        if not GOAL_COUNT.contains(len(goals)):
            raise TaskFieldError("goals", f"{len(goals)} goals is out of range (allowed {GOAL_COUNT})")
        for g in goals:
            if not isinstance(g, (list, tuple)) or len(g) != spec.goal_dim or not all(_number(c) for c in g):
                raise TaskFieldError("goals", f"each goal must be a list of {spec.goal_dim} numbers, got {g!r}")
        object.__setattr__(self, "goals", tuple(tuple(g) for g in goals))
        if len(set(self.goals)) != len(self.goals):
            raise TaskFieldError("goals", "goals must be distinct")
        for name, value, allowed in (("params", self.params, spec.regimes[self.regime]),
                                     ("env", self.env_params, spec.env_defaults)):
            if not isinstance(value, Mapping):
                raise TaskFieldError(name, "expected a table")
            extra = sorted(set(value) - set(allowed))
            if extra:
                raise TaskFieldError(f"{name}.{extra[0]}", f"unknown parameter (known: {', '.join(allowed) or 'none'})")
        object.__setattr__(self, "params", {**spec.regimes[self.regime], **self.params})
        object.__setattr__(self, "env_params", {**spec.env_defaults, **self.env_params})
        for name, default in spec.env_defaults.items():
            why = _env_value_error(self.env_params[name], default)
            if why:
                raise TaskFieldError(f"env.{name}", why)
        bounds = getattr(spec, "bounds", None) or {}
        _check_bounds("params.", self.params, bounds)
        _check_bounds("env.", self.env_params, bounds)
        for name in ("n_demos", "n_train"):
            if not _count(getattr(self, name)):
                raise TaskFieldError(name, f"expected a positive integer, got {getattr(self, name)!r}")
        _check_bounds("", {"n_demos": self.n_demos, "n_train": self.n_train}, FIELD_BOUNDS)
        if self.n_train >= self.n_demos:
            raise TaskFieldError("n_train", f"must be smaller than n_demos ({self.n_demos}) to leave test "
                                            "demonstrations")
        obs = self.observability
        if not isinstance(obs, (list, tuple)) or not obs or not all(_number(p) and 0 < p <= 1 for p in obs):
            raise TaskFieldError("observability", "expected a non-empty list of fractions in (0, 1]")
        object.__setattr__(self, "observability", tuple(float(p) for p in obs))
        if not isinstance(self.protocol, str) or not _known_protocol(self.protocol):
            raise TaskFieldError("protocol", f"unknown observation protocol {self.protocol!r}")
        if self.rounding not in ROUNDINGS:
            raise TaskFieldError("rounding", f"expected one of {', '.join(ROUNDINGS)}, got {self.rounding!r}")
        if not isinstance(self.description, str):
            raise TaskFieldError("description", "expected a string")
        if not isinstance(self.demos, str):
            raise TaskFieldError("demos", "expected a Minari dataset's folder or ID")
        try:
            spec.check(self.regime, self.params, self.env_params, self.goals)
        except TaskFieldError:
            raise
        except UserError as exc:  # the domain's own checks: of the goals, or else of the parameters
            raise TaskFieldError("goals" if str(exc).startswith("goal") else "params", str(exc)) from None
        self._check_test_params()

    def _check_test_params(self) -> None:
        """Validate :attr:`test_params` and keep only the values that shift something (see :meth:`test_task`)."""
        if not isinstance(self.test_params, Mapping):
            raise TaskFieldError("test", "expected a table")
        defaults = test_defaults(self.spec)
        extra = sorted(set(self.test_params) - set(defaults))
        if extra:
            raise TaskFieldError(f"test.{extra[0]}", f"unknown test parameter (known: {', '.join(defaults)})")
        own = {k: self.env_params.get(e) for k, e in (getattr(self.spec, "test_replaces", None) or {}).items()}
        shift = {k: v for k, v in self.test_params.items()
                 if freeze(v) != freeze(defaults[k]) and (k not in own or freeze(v) != freeze(own[k]))}
        if shift.get("test_regime") == self.regime and "test_regime_params" not in shift:
            del shift["test_regime"]  # the task's own regime as it is: no shift
        object.__setattr__(self, "test_params", shift)
        if not shift:
            return
        if self.demos:
            raise TaskFieldError("test", f"the demonstrations come from the dataset {self.demos}; test "
                                         "parameters shift generated ones only")
        _check_bounds("test.", shift, getattr(self.spec, "bounds", None) or {})
        regime = shift.get("test_regime", self.regime)
        if not isinstance(regime, str) or regime not in self.spec.regimes:
            raise TaskFieldError("test.test_regime", f"unknown regime {regime!r} for domain {self.domain!r} "
                                                     f"(known: {', '.join(self.spec.regimes)})")
        extra_params = shift.get("test_regime_params", {})
        if not isinstance(extra_params, Mapping):
            raise TaskFieldError("test.test_regime_params", "expected a table of the test regime's parameters")
        unknown = sorted(set(extra_params) - set(self.spec.regimes[regime]))
        if unknown:
            raise TaskFieldError("test.test_regime_params", f"{unknown[0]!r} is no parameter of the {regime} "
                                 f"regime (known: {', '.join(self.spec.regimes[regime]) or 'none'})")
        if regime != self.regime or extra_params:
            try:
                self.spec.check(regime, self._test_regime_params(), self.env_params, self.goals)
            except UserError as exc:
                raise TaskFieldError("test.test_regime_params", f"the {regime} test regime: {exc} (set its "
                                     "parameters in test_regime_params)") from None
        dynamics = sorted(k for k in shift if k not in TEST_DEFAULTS)
        if dynamics and regime not in getattr(self.spec, "shift_regimes", self.spec.regimes):
            raise TaskFieldError(f"test.{dynamics[0]}", f"the {regime} demonstrator is generated under the "
                                                        "nominal dynamics only; shifts apply to the "
                                 f"{', '.join(self.spec.shift_regimes)} regimes")
        check = getattr(self.spec, "check_test", None)
        try:
            if check is not None:
                check(shift, self.env_params, self.goals)
        except UserError as exc:
            raise TaskFieldError("test", str(exc)) from None

    def _test_regime_params(self) -> dict[str, Any]:
        """The test regime's parameters: its defaults, the task's own where the regime shares them, then
        ``test_regime_params``."""
        regime = self.test_params.get("test_regime", self.regime)
        defaults = self.spec.regimes[regime]
        own = {k: v for k, v in self.params.items() if k in defaults}
        return {**defaults, **own, **self.test_params.get("test_regime_params", {})}

    def __hash__(self) -> int:
        return hash((self.id, self.regime, self.goals, repr(sorted(self.params.items())),
                     repr(sorted(self.test_params.items()))))

    @property
    def shifted(self) -> bool:
        """Whether the test demonstrations differ from the training ones in regime or dynamics."""
        return bool(self.test_params)

    def nominal(self) -> GRTask:
        """This task with its test demonstrations as its training ones (no test parameters)."""
        return dataclasses.replace(self, test_params={}) if self.test_params else self

    def test_task(self) -> GRTask:
        """The task the test demonstrations are generated (and the Bayes ceiling computed) from.

        Its regime is ``test_regime`` (with that regime's parameters: its defaults, the task's own where they
        are shared, then ``test_regime_params``); its :attr:`test_params` keep only the dynamics shifts, which
        the domain's demonstrator applies (its env parameters stay the task's, so recognizers build nominal
        envs). Without test parameters, this task.
        """
        if not self.test_params:
            return self
        dynamics = {k: v for k, v in self.test_params.items() if k not in TEST_DEFAULTS}
        return dataclasses.replace(self, regime=self.test_params.get("test_regime", self.regime),
                                   params=self._test_regime_params(), test_params=dynamics)

    @property
    def protocol_label(self) -> str:
        """The store's label of the default protocol and rounding (``"subset"``; ``"subset+floor"`` rounds down)."""
        return protocol_label(self.protocol, self.rounding)

    @property
    def spec(self) -> Domain:
        """The task's :class:`~grail_bench.task.domain.Domain`."""
        try:
            return get_domain(self.domain)
        except UserError as exc:
            raise TaskFieldError("domain", str(exc)) from None

    def with_overrides(self, **overrides: Any) -> GRTask:
        """This task with regime parameters, env parameters, ``n_demos``, ``n_train`` or ``demos`` replaced.

        Names are routed to where they belong (``turn_prob`` to :attr:`params`,
        ``max_steps`` to :attr:`env_params`). ``demos`` names a Minari dataset
        to take the demonstrations from (``""``: the generator); its training
        and test episodes set ``n_train`` and ``n_demos``, and it is checked
        against the task with the other overrides applied.

        Raises:
            UserError: For a name the task cannot apply, an invalid value, or a dataset that does not fit.
        """
        spec = self.spec
        params, env_params, fields = dict(self.params), dict(self.env_params), {}
        tests, test_names = dict(self.test_params), test_defaults(spec)
        for name, value in overrides.items():
            if name in ("n_demos", "n_train"):
                fields[name] = value
            elif name in test_names:
                tests[name] = value
            elif name == "demos":
                continue  # applied last, to the task it is for
            elif name in spec.regimes[self.regime]:
                params[name] = value
            elif name in spec.env_defaults:
                why = (getattr(spec, "fixed", None) or {}).get(name)
                if why and freeze(value) != freeze(env_params[name]):
                    raise UserError(f"{self.id} keeps its card's {name} ({env_params[name]!r}), not {value!r}: "
                                    f"{why}")
                env_params[name] = value
            elif name == "goals":
                raise UserError(f"{self.id} cannot take goals as a parameter: a goal set defines a task, and its "
                                "results need their own ID; write a card with your ID and goals and give it with "
                                "--cards (docs/guides/tasks-and-demos.md, 'Your own task card')")
            else:
                hint = " (it applies to gym.make, not to a task)" if name in ENV_ONLY else ""
                known = sorted({*spec.regimes[self.regime], *spec.env_defaults, *test_names, "n_demos", "n_train",
                                "demos"})
                raise UserError(f"{self.id} cannot apply parameter {name!r}{hint}; known: {', '.join(known)}")
        try:
            task = dataclasses.replace(self, params=params, env_params=env_params, test_params=tests, **fields)
        except TaskFieldError as exc:
            raise UserError(f"{self.id}: {exc}") from None
        if "demos" not in overrides:
            return task
        task = _demos().with_dataset(task, overrides["demos"])
        for name, value in fields.items():
            if task.demos and value != getattr(task, name):
                raise UserError(f"{self.id}: {name}={value!r}, but the dataset {task.demos} gives "
                                f"{getattr(task, name)} per goal; leave {name} to the dataset")
        return task

    def settings(self) -> dict[str, Any]:
        """Every parameter an override can set, by name: regime and env parameters, the test parameters, the
        demonstration counts and ``demos`` (empty for the generator)."""
        return {**self.params, **self.env_params, **test_defaults(self.spec), **self.test_params,
                "n_demos": self.n_demos, "n_train": self.n_train, "demos": self.demos}

    def overrides_against(self, base: GRTask) -> TaskOverrides:
        """How this task differs from ``base`` (usually its card's task): the settings whose values differ.

        ``base.with_overrides(**task.overrides_against(base).as_dict())`` is this task again.
        """
        theirs = base.settings()
        return TaskOverrides.of({k: v for k, v in self.settings().items()
                                 if k not in theirs or freeze(theirs[k]) != freeze(v)})

    def goal_index(self, goal: Sequence[float]) -> int:
        """Position of ``goal`` in :attr:`goals`; raises :class:`UserError` if absent."""
        key = tuple(goal)
        for i, g in enumerate(self.goals):
            if tuple(g) == key:
                return i
        raise UserError(f"{tuple(goal)} is not a goal of {self.id}; goals: {list(self.goals)}")

    def make_env(self, goal: Sequence[float] | None = None, **env_overrides: Any) -> gym.Env:
        """Build the domain env pursuing one candidate goal (default: the first).

        Args:
            goal: One of :attr:`goals`.
            **env_overrides: Domain env keyword arguments (e.g. ``render_mode``).

        Returns:
            The env; ``env.unwrapped.task`` is this task.
        """
        chosen = self.goals[0] if goal is None else self.goals[self.goal_index(goal)]
        env = self.spec.make_env(chosen, **{**self.env_params, **env_overrides})
        env.unwrapped.task = self
        return env

    def action_space(self) -> gym.spaces.Space:
        """The domain env's action space (an env is built to read it, then closed, once per task object)."""
        return self._action_space

    @functools.cached_property
    def _action_space(self) -> gym.spaces.Space:
        env = self.make_env()
        try:
            return env.action_space
        finally:
            env.close()

    def env_factory(self) -> EnvFactory:
        """``factory(goal) -> env`` building this task's goal envs."""
        return functools.partial(_make_env, self)

    @property
    def env_key(self) -> str:
        """JSON naming the domain and its env parameters (not the regime).

        Recognizers that learn from interaction alone key their cached models
        by it, so one training serves every regime of a domain.
        """
        return json.dumps({"domain": self.domain, "env": dict(self.env_params)}, sort_keys=True)

    def generate_demos(self, seed: int, n_demos: int | None = None) -> Demos:
        """The task's demonstrations for every goal: from :attr:`demos`' dataset, or generated.

        Generated demonstrations are the same for the same seed. Each goal draws
        from a stream keyed by ``(seed, goal)`` (:mod:`grail_bench.core.seeding`),
        so a goal's demonstrations are the same in every task that has it
        (see :mod:`grail_bench.task.demos`).

        Args:
            seed: Seed of the demonstration generator (or of the dataset, in a folder of per-seed datasets).
            n_demos: Per goal; defaults to :attr:`n_demos` (a dataset gives what it holds).

        Returns:
            ``{goal: [Trajectory, ...]}`` in the order of :attr:`goals`.

        Raises:
            UserError: When :attr:`demos` names a dataset that does not fit the task.
        """
        return _demos().generate(self, seed, n_demos)

    def observe(self, traj: Trajectory, level: float, rng: np.random.Generator | None = None) -> Trajectory:
        """What a recognizer sees of one of the task's test demonstrations at ``level``, under the task's own
        protocol and rounding (:func:`~grail_bench.task.observation.observe`; random subsets need ``rng``)."""
        return observe(traj, level, rng=rng, task=self)

    def split(self, demos: Demos) -> tuple[Demos, Demos]:
        """Split each goal's demonstrations into the first ``n_train`` and the rest."""
        train, test = {}, {}
        for goal, trajs in demos.items():
            if len(trajs) <= self.n_train:
                raise UserError(f"goal {goal} has {len(trajs)} demonstrations; need more than "
                                f"n_train={self.n_train}")
            train[goal], test[goal] = list(trajs[: self.n_train]), list(trajs[self.n_train :])
        return train, test


def test_defaults(spec: Domain) -> dict[str, Any]:
    """The test parameters a domain's tasks take, each with its "as in training" value: :data:`TEST_DEFAULTS`
    and the domain's own ``test_params`` (shifts of its dynamics)."""
    return {**TEST_DEFAULTS, **(getattr(spec, "test_params", None) or {})}


def _make_env(task: GRTask, goal: Goal) -> gym.Env:
    return task.make_env(goal)


def _known_protocol(name: str) -> bool:
    """Built in, or registered by a plugin (entry points are read only for unknown names)."""
    return name in BUILTIN or name in available_protocols()
