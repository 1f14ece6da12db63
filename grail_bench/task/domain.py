"""What a task needs from its domain, and where domains are found.

A domain is an object satisfying :class:`Domain`, registered under a name in
the entry-point group ``grail_bench.domains`` (the built-in ones are declared
in grail-bench's own ``pyproject.toml``, so a third-party package adds a
domain the same way). The task layer knows domains only through this protocol
and the registry, as gymnasium's registration knows its envs only by their
entry points; the domain packages (:mod:`grail_bench.domains`) sit above it.

A domain's module must stay light (plain data and validation): task cards are
parsed on ``import gymnasium``, and only building an env or a demonstration
may import the domain's simulator.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Protocol, Sequence, runtime_checkable

from grail_bench.core.errors import UserError
from grail_bench.core.registry import Registry
from grail_bench.core.trajectory import Goal

if TYPE_CHECKING:
    import gymnasium as gym
    import numpy as np
    from grail_bench.core.trajectory import Trajectory

GROUP = "grail_bench.domains"


class TaskView(Protocol):
    """What a domain may read of a task (a :class:`~grail_bench.task.model.GRTask` is one)."""

    id: str
    regime: str
    goals: tuple[Goal, ...]
    params: Mapping[str, Any]
    env_params: Mapping[str, Any]

    def goal_index(self, goal: Sequence[float]) -> int:
        """Position of ``goal`` among :attr:`goals`."""
        ...

    def make_env(self, goal: Sequence[float] | None = None, **env_overrides: Any) -> gym.Env:
        """The domain env pursuing ``goal``, with the task's env parameters."""
        ...


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

    A domain may also declare ``implicit``: per regime parameter added after
    runs were stored, the value those runs used (so that a stored run is read
    with the parameters it really had; see :func:`stored_params`); and
    ``cache_demos = True`` to have its demonstrations generated once per goal,
    regime, parameters and seed and kept on disk (for slow demonstrators; see
    :mod:`grail_bench.task.demo_cache`), and ``packages``: the distributions
    its simulator comes from beyond the suite's own, whose versions key those
    cached demonstrations too.

    A domain may also declare ``path_params``: the env parameters that name a file (a symbolic problem's
    archive). A card's relative value that exists beside the card is read from there, as its ``demos`` folder
    is, and a task's fingerprint keeps only the file's name (the same on every machine).

    A domain may also declare ``bounds``: per regime or env parameter that sizes work (a grid's side, a step
    count), the :class:`~grail_bench.core.bounds.Range` its values must lie in. A task refuses a value outside
    it when it is built (from a card, ``--param``, ``make_task`` or ``gym.make``), before any work, naming the
    parameter, the value and the range.

    A domain may also declare ``test_params``: its test-time shifts of the dynamics, each with the value that
    means "as in training" (MiniGrid's ``test_slip``; see :meth:`~grail_bench.task.model.GRTask.test_task`),
    which its ``generate_demos`` and ``demonstrator`` apply when a task's ``test_params`` set them (they are
    handed the task's ``test_task()``), never its ``make_env`` for recognizers; with them
    ``check_test(test_params, env_params, goals)``, validating them cheaply, and ``ceiling_shifts``: the shifts
    under which its ``demonstrator`` likelihood stays exact (the Bayes ceiling is refused under the others),
    and ``shift_regimes``: the regimes whose demonstrators take them (default: every regime; the others are
    refused with the shifts), and ``test_replaces``: the test parameters that replace an env parameter at test
    time, mapped to it (MiniGrid's ``test_obstacles`` -> ``obstacles``), so one equal to the task's own value
    shifts nothing.
    ``test_regime`` and ``test_regime_params`` (another regime for the test demonstrations) need nothing of
    a domain.

    A domain may also declare ``ends_early(env_params)``: why its episodes may end before ``max_steps`` (a
    goal reached, lava), or None when every episode runs to it. Recognizers that train on episodes of one
    length (GAIL, AIRL) refuse such a task where a run is planned.

    A domain may also declare ``noop_action``: the action that leaves the agent
    where it is (an action of its env's action space: an integer for discrete
    actions, a sequence of the action box's shape for continuous ones; MiniGrid
    declares "stay", PandaReach and PointMaze the zero action). Recognizer
    settings that need one (``off_support="stay"``, BC's ``augment="stay"``) are
    refused where a run is planned on a domain that declares none.

    A domain may also declare ``fixed``: per env parameter a task keeps from its card, why (a one-line pointer
    shown when an override would change it); and, for tasks carrying observations of their own (a symbolic problem
    set), ``check_dataset(task)`` (raising a one-line :class:`~grail_bench.core.errors.UserError` for a task with
    none), ``dataset_observations(task)`` (``[(true goal's index, observed Trajectory), ...]``, what the ``dataset``
    protocol scores) and ``content_digest(task)`` (a digest of the files the task is made of, which keys its
    results; None for none).

    A domain may also state its demonstrator's action distribution, which the
    reference recognizer ``demonstrator`` (perfect imitation) scores with:
    ``demonstrator_policy(task, goal, support)``, ``support`` being
    ``"everywhere"`` (goal-directed from every state: on a state the
    demonstrator from the task's start never visits, its distribution as if it
    started there) or ``"demonstrated"`` (the demonstrator's distribution on the
    states it visits from the task's start, no preference elsewhere). It returns,
    for discrete observations and actions, an ``(S, A)`` array of action
    probabilities whose row ``i`` is the state of
    :func:`~grail_bench.core.spaces.state_index` ``i``; for continuous actions, a
    callable from ``(T, ...)`` states to ``(mean, std)``, each ``(T, D)``. Where
    the demonstrator is not Markov in the observed state, a row is its marginal
    there (the expected times it takes each action at the state over the expected
    times it is there). It raises :class:`~grail_bench.core.errors.UserError` for
    a regime whose action distribution it does not state; with it comes
    ``check_demonstrator_policy(task, support)``, raising the same refusals
    without building anything (the recognizer calls it where a run is planned).
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
            grail_bench.core.errors.UserError: Naming the parameter and what is wrong.
        """
        ...

    def make_env(self, goal: Goal, **env_params: Any) -> gym.Env:
        """The env pursuing ``goal``."""
        ...

    def generate_demos(self, task: TaskView, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
        """``n`` demonstrations of ``goal`` under the task's regime, drawn from ``rng``.

        Each is played in ``task.make_env(goal)`` from ``reset(seed=RESET_SEED)``, as
        :func:`grail_bench.core.trajectory.rollout` plays it: ``grail-bench export`` replays it there to record
        the env's rewards, terminations and truncations, and refuses a demonstration that does not replay.
        """
        ...

    def demonstrator(self, task: TaskView, goal: Goal) -> Any:
        """The likelihood model of ``goal``'s demonstrator (a :class:`grail_bench.domains.base.GoalModel`),
        for a regime in :attr:`ceiling_regimes`."""
        ...


def _checked(domain: object, target: str) -> Domain:
    if not isinstance(domain, Domain):
        raise UserError(f"domain entry point {target} does not satisfy grail_bench.task.domain.Domain")
    return domain


#: Every domain, the built-in ones included, through the ``grail_bench.domains`` entry points.
DOMAINS: Registry[Domain] = Registry("domain", GROUP, check=_checked)


def available_domains() -> list[str]:
    """Names of every registered domain, sorted (nothing is imported)."""
    return DOMAINS.names()


def get_domain(name: str) -> Domain:
    """The domain registered as ``name`` (imported on first use).

    Raises:
        UserError: For unknown names, listing the known ones, or an entry point that is not a :class:`Domain`.
    """
    return DOMAINS.get(name)


def stored_params(domain: Domain, params: Mapping[str, Any], regime: Any = None) -> dict[str, Any]:
    """The parameters a stored run (or an exported dataset) used: the recorded ones, plus the domain's
    ``implicit`` values of parameters it declares were added since (those runs predate them); given the run's
    ``regime``, only of parameters that regime has (a biased MiniGrid run has no ``route_choice``)."""
    implicit = getattr(domain, "implicit", None) or {}
    if isinstance(regime, str):
        implicit = {k: v for k, v in implicit.items() if k in domain.regimes.get(regime, {})}
    return {**implicit, **params}
