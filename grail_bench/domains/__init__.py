"""GR domains: one package each, found by looking in this folder.

A domain package ``grail_bench/domains/<name>/`` holds its env, its
demonstrators and the validation of its parameters, and its ``__init__``
exposes ``DOMAIN``, an object satisfying :class:`Domain`. That ``__init__``
must stay light (plain data and validation): task cards are parsed on
``import gymnasium``, and only building an env or a demonstration imports the
domain's simulator. Adding a domain means one package here and one task card
in ``tasks/``.
"""

from __future__ import annotations

import importlib
import pkgutil
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Mapping, Protocol, Sequence, runtime_checkable

from grail_bench.errors import UserError

if TYPE_CHECKING:
    import gymnasium as gym
    import numpy as np
    from imitation.data.types import Trajectory

    from grail_bench.evaluation.ceiling import GoalModel
    from grail_bench.task import GRTask
    from grail_bench.trajectory import Goal


@runtime_checkable
class Domain(Protocol):
    """What the task needs from a domain.

    Attributes:
        name: Short name used in task cards (``domain = "minigrid"``).
        goal_dim: Number of coordinates in a goal.
        env_defaults: Keyword arguments of the env and their defaults.
        regimes: Behaviour regime name -> its parameters and their defaults.
        ceiling_regimes: Regimes whose demonstrator has a known likelihood, so
            that the Bayes ceiling can be computed (see :meth:`demonstrator`).
    """

    name: str
    goal_dim: int
    env_defaults: Mapping[str, Any]
    regimes: Mapping[str, Mapping[str, Any]]
    ceiling_regimes: frozenset[str]

    def check(self, regime: str, params: Mapping[str, Any], env_params: Mapping[str, Any],
              goals: Sequence[Goal]) -> None:
        """Validate a task's regime parameters, env parameters and goals (cheaply, without the simulator).

        Raises:
            grail_bench.errors.UserError: Naming the parameter and what is wrong.
        """
        ...

    def make_env(self, goal: Goal, **env_params: Any) -> gym.Env:
        """The env pursuing ``goal``."""
        ...

    def generate_demos(self, task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
        """``n`` demonstrations of ``goal`` under the task's regime, drawn from ``rng``."""
        ...

    def demonstrator(self, task: GRTask, goal: Goal) -> GoalModel:
        """The likelihood model of ``goal``'s demonstrator, for a regime in :attr:`ceiling_regimes`."""
        ...


@lru_cache(maxsize=1)
def _domains() -> dict[str, Domain]:
    found: dict[str, Domain] = {}
    for module in pkgutil.iter_modules(__path__):
        if module.ispkg:
            domain = importlib.import_module(f"{__name__}.{module.name}").DOMAIN
            found[domain.name] = domain
    return found


def available_domains() -> list[str]:
    """Names of every domain, sorted."""
    return sorted(_domains())


def get_domain(name: str) -> Domain:
    """The domain called ``name``.

    Raises:
        UserError: For unknown names, listing the known ones.
    """
    try:
        return _domains()[name]
    except KeyError:
        raise UserError(f"unknown domain {name!r}; known domains: {', '.join(available_domains())}") from None
