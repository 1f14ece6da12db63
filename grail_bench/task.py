"""The GR task: a domain, a goal set, a behaviour regime and its demonstrations."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from grail_bench.domains import get_domain, load_object
from grail_bench.seeding import DEMOS, goal_rng

if TYPE_CHECKING:
    import gymnasium as gym
    from imitation.data.types import Trajectory

Goal = tuple[float, ...]
Demos = dict[Goal, list["Trajectory"]]


@dataclass(frozen=True)
class GRTask:
    """A goal-recognition task as registered under a ``GRAIL/`` ID.

    Attributes:
        id: The gymnasium ID, e.g. ``"GRAIL/MiniGrid-Biased-v0"``.
        domain: Domain name (see :mod:`grail_bench.domains`).
        regime: Behaviour regime of the demonstrator.
        goals: Candidate goals, in a fixed order.
        params: Regime parameters (defaults merged with overrides).
        env_params: Keyword arguments of the domain env.
        n_demos: Demonstrations generated per goal.
        n_train: How many of them form the training split.
        observability: Default observability levels of the task.
        protocol: Default observation protocol (see
            :mod:`grail_bench.evaluation.protocol`).
        description: One line for humans.
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
    description: str = ""

    def __hash__(self) -> int:
        return hash((self.id, self.regime, self.goals, repr(sorted(self.params.items()))))

    def goal_index(self, goal: Sequence[float]) -> int:
        """Position of ``goal`` in :attr:`goals`; raises ``ValueError`` if absent."""
        key = tuple(goal)
        for i, g in enumerate(self.goals):
            if tuple(g) == key:
                return i
        raise ValueError(f"{tuple(goal)} is not a goal of {self.id}; goals: {list(self.goals)}")

    def make_env(self, goal: Sequence[float] | None = None, **env_overrides: Any) -> gym.Env:
        """Build the domain env pursuing one candidate goal (default: the first).

        Args:
            goal: One of :attr:`goals`.
            **env_overrides: Domain env keyword arguments (e.g. ``render_mode``).

        Returns:
            The env; ``env.unwrapped.task`` is this task.
        """
        chosen = self.goals[0] if goal is None else self.goals[self.goal_index(goal)]
        factory = load_object(get_domain(self.domain).env_factory)
        env = factory(goal=chosen, **{**self.env_params, **env_overrides})
        env.unwrapped.task = self
        return env

    def env_factory(self) -> EnvFactory:
        """``factory(goal) -> env`` with a :attr:`EnvFactory.cache_key` naming the domain env."""
        return EnvFactory(self)

    def generate_demos(self, seed: int, n_demos: int | None = None) -> Demos:
        """Generate demonstrations for every goal.

        The same seed always gives identical demonstrations. Each goal draws
        from a stream keyed by ``(seed, goal)`` (:mod:`grail_bench.seeding`),
        so a goal's demonstrations are the same in every task that has it.

        Args:
            seed: Seed of the demonstration generator.
            n_demos: Per goal; defaults to :attr:`n_demos`.

        Returns:
            ``{goal: [Trajectory, ...]}`` in the order of :attr:`goals`.
        """
        generator = load_object(get_domain(self.domain).demo_generator)
        n = self.n_demos if n_demos is None else n_demos
        return {goal: generator(self, goal, n, goal_rng(seed, goal, DEMOS)) for goal in self.goals}

    def split(self, demos: Demos) -> tuple[Demos, Demos]:
        """Split each goal's demonstrations into the first ``n_train`` and the rest."""
        train, test = {}, {}
        for goal, trajs in demos.items():
            if len(trajs) <= self.n_train:
                raise ValueError(
                    f"goal {goal} has {len(trajs)} demonstrations; need more than n_train={self.n_train}"
                )
            train[goal], test[goal] = list(trajs[: self.n_train]), list(trajs[self.n_train :])
        return train, test


class EnvFactory:
    """Builds a task's goal envs; what the harness hands to ``Recognizer.fit``.

    Attributes:
        cache_key: JSON naming the domain and its env parameters (not the
            regime): recognizers that learn from interaction alone may use it
            to reuse trained models across the regimes of a domain.
    """

    def __init__(self, task: GRTask) -> None:
        self._task = task
        self.cache_key = json.dumps({"domain": task.domain, "env": dict(task.env_params)}, sort_keys=True)

    def __call__(self, goal: Sequence[float]) -> gym.Env:
        return self._task.make_env(goal)


def _task_from_kwargs(kwargs: Mapping[str, Any], overrides: Mapping[str, Any]) -> tuple[GRTask, dict[str, Any]]:
    """Build a task from registered kwargs plus user overrides.

    Overrides are routed by name: regime parameters (e.g. ``turn_prob``) go to
    the task, domain env parameters (and ``render_mode``) to the env.
    """
    spec = get_domain(kwargs["domain"])
    regime_names = set(spec.regimes[kwargs["regime"]])
    params, env_params, env_only = dict(kwargs["params"]), dict(kwargs["env"]), {}
    counts = {"n_demos": kwargs["n_demos"], "n_train": kwargs["n_train"]}
    for name, value in overrides.items():
        if name in counts:
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{kwargs['task_id']}: {name} must be a positive integer, got {value!r}")
            counts[name] = value
        elif name in regime_names:
            params[name] = value
        elif name in spec.env_defaults:
            env_params[name] = value
        elif name in ("render_mode", "goal"):
            env_only[name] = value
        else:
            known = sorted(regime_names | set(spec.env_defaults) | {"render_mode", "goal", *counts})
            raise TypeError(f"{kwargs['task_id']} got an unknown parameter {name!r}; known: {', '.join(known)}")
    if counts["n_train"] >= counts["n_demos"]:
        raise ValueError(f"{kwargs['task_id']}: n_train ({counts['n_train']}) must be smaller than "
                         f"n_demos ({counts['n_demos']})")
    task = GRTask(
        id=kwargs["task_id"], domain=kwargs["domain"], regime=kwargs["regime"],
        goals=tuple(tuple(g) for g in kwargs["goals"]), params=params, env_params=env_params,
        n_demos=counts["n_demos"], n_train=counts["n_train"],
        observability=tuple(kwargs["observability"]), protocol=kwargs.get("protocol", "subset"),
        description=kwargs.get("description", ""),
    )
    return task, env_only


def make_registered_env(**kwargs: Any) -> gym.Env:
    """Gymnasium entry point of every ``GRAIL/`` ID (see :mod:`grail_bench.registration`)."""
    registered = {k: kwargs.pop(k) for k in
                  ("task_id", "domain", "regime", "goals", "params", "env", "n_demos",
                   "n_train", "observability", "protocol", "description") if k in kwargs}
    task, env_only = _task_from_kwargs(registered, kwargs)
    goal = env_only.pop("goal", None)
    return task.make_env(goal, **env_only)


def make_task(task_id: str, **overrides: Any) -> GRTask:
    """Return the :class:`GRTask` of a registered ID without building an env.

    Args:
        task_id: A ``GRAIL/`` gymnasium ID.
        **overrides: Regime or env parameters, as accepted by ``gym.make``.

    Raises:
        gymnasium.error.Error: For unknown IDs (gymnasium's own message).
    """
    from gymnasium.envs.registration import spec as gym_spec

    from grail_bench.registration import register_envs

    register_envs()
    env_spec = gym_spec(task_id)
    if env_spec.entry_point != "grail_bench.task:make_registered_env":
        raise ValueError(f"{task_id} is a gymnasium env but not a GRAIL/ task")
    task, _ = _task_from_kwargs(env_spec.kwargs, overrides)
    return task
