"""Symbolic (PDDL/STRIPS) goal recognition, in the layout of Pereira et al.'s dataset.

A task's problem comes from its env parameter ``problem``: a built-in name
(``"blocks"``, ``"grid"``, ``"logistics"``: :mod:`.generator`) or the path of
one archive (or folder) in the dataset's layout (:mod:`.dataset`). Its
candidate goals are the problem's hypotheses (``hyps.dat``), named in a task
card by their index: ``goals = [[0], [1], ...]``.

Modules, one job each:

* :mod:`.pddl_text`: PDDL text -> lifted domain and problem (the ``pddl`` package parses);
* :mod:`.grounding`: lifted -> :class:`~.strips.StripsModel`, only reachable, relevant operators;
* :mod:`.strips`: the grounded model (fluents in a fixed order, operators with pre/add/del index sets,
  states as ``int`` bit sets);
* :mod:`.planner`: optimal planning (A* with h_max) and the DAG of every optimal plan (:class:`~.planner.PlanGraph`);
* :mod:`.problem`: :class:`~.problem.GRProblem`, one recognition problem and its grounded model;
* :mod:`.dataset`: the dataset's archives, read and written; :mod:`.generator`: the built-in problems;
* :mod:`.problem_set`: a problem set (an archive, a folder, or a folder of them) as a task of its own, with all
  of its hypotheses, and its own observations for the ``dataset`` protocol (``grail-bench run --task PATH``);
* :mod:`.env`: the gymnasium env; :mod:`.demos`: the demonstrators; :mod:`.likelihood`: their exact
  likelihood (Bayes ceiling); :mod:`.policy`: their action distributions on every state.

For recognizers built on planning (plan recognition as planning, landmarks):

* ``env = env_factory(goal)``; ``env.unwrapped.problem`` is the :class:`~.problem.GRProblem`,
  ``env.unwrapped.model`` its :class:`~.strips.StripsModel` (the same object for every goal of a task),
  ``env.unwrapped.goal_index`` the goal's index among ``problem.hypotheses`` and ``env.unwrapped.goal_mask``
  (``problem.goal_masks[goal_index]``) the state bits the goal requires; the initial state is ``model.init``.
* An observation is ``model.vector(state)``: ``obs[i] == 1`` iff fluent ``model.fluents[i]`` (an atom such as
  ``("on", "a", "b")``) holds; ``model.state(obs)`` is the state back (an ``int``, which is also
  :func:`grail_bench.core.spaces.state_index` of ``obs``). Action ``a`` is ground operator
  ``model.operators[a]`` (``.name`` its atom, ``.text`` ``"(stack a b)"``, ``.pre``/``.pre_neg``/``.add``/
  ``.delete`` fluent indices); ``model.operator_index("(stack a b)")`` maps an ``obs.dat`` line back.
* ``planner.astar(model, goal_mask, start)`` is an optimal plan (operator indices);
  ``planner.optimal_plan_graph(model, goal_mask, start)`` every optimal plan; ``planner.hmax`` the heuristic.
  A goal for a planner is any state mask (e.g. ``model.goal_mask(atoms)``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.domains.boltzmann import check_beta

if TYPE_CHECKING:
    import numpy as np

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

SUPPORTS = ("everywhere", "demonstrated")
#: The Boltzmann regime's default rationality (``docs/concepts/tasks.md``, "Boltzmann").
BOLTZMANN_BETA = 0.15


def goal_count(problem: str) -> int:
    """How many candidate goals a problem has (built-in name or path), read without grounding it.

    Raises:
        UserError: For an unknown name, a missing path or an archive lacking a file.
    """
    from grail_bench.domains.symbolic.generator import BUILTIN, N_GOALS

    if problem in BUILTIN:
        return N_GOALS[problem]
    if not Path(problem).exists():
        raise UserError(f"problem {problem!r} is neither a built-in problem ({', '.join(BUILTIN)}) nor an "
                        "existing archive or folder")
    from grail_bench.domains.symbolic.dataset import read_files

    return sum(1 for line in read_files(problem)["hyps.dat"].splitlines() if line.strip())


class Symbolic:
    """The :class:`~grail_bench.task.domain.Domain` of symbolic (PDDL/STRIPS) goal recognition."""

    name = "symbolic"
    goal_dim = 1
    env_defaults: Mapping[str, Any] = {"problem": "blocks", "max_steps": 50}
    path_params = ("problem",)  # a card's relative problem archive beside the card is read from there
    regimes: Mapping[str, Mapping[str, Any]] = {
        # An optimal plan drawn uniformly among all optimal plans.
        "optimal": {},
        # The lexicographically first optimal plan (by operator index): one consistent preference.
        "biased": {},
        # An optimal plan drawn uniformly; before each of its actions, with probability detour_prob, a detour
        # of two actions that undo each other.
        "suboptimal": {"detour_prob": 0.3},
        # Operators drawn with probability proportional to exp(beta * Q), Q from optimal plan costs
        # (grail_bench.domains.boltzmann).
        "boltzmann": {"beta": BOLTZMANN_BETA},
    }
    bounds: Mapping[str, Range] = {"max_steps": Range(1, 10_000)}  # published: 50
    #: Env parameters a task keeps from its card: another problem has other hypotheses, so it is a task of its own.
    fixed: Mapping[str, str] = {"problem": "run a problem set as a task of its own, with every one of its "
                                           "hypotheses: grail-bench run --task PATH"}
    ceiling_regimes = frozenset({"optimal", "biased", "boltzmann"})

    def check(self, regime: str, params: Mapping[str, Any], env_params: Mapping[str, Any],
              goals: Sequence[Goal]) -> None:
        if regime == "suboptimal":
            p = params["detour_prob"]
            if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0.0 <= p <= 1.0:
                raise UserError(f"detour_prob must be in [0, 1], got {p!r}")
        if regime == "boltzmann":
            check_beta(params["beta"])
        n = goal_count(env_params["problem"])
        for goal in goals:
            if len(goal) != 1 or float(goal[0]) != int(goal[0]) or not 0 <= int(goal[0]) < n:
                raise UserError(f"goal {list(goal)} must be [i], the index of one of the problem's {n} hypotheses")

    def ends_early(self, env_params: Mapping[str, Any]) -> str | None:
        """Why episodes may end before ``max_steps`` (see :class:`~grail_bench.task.domain.Domain`)."""
        return "episodes end when the goal holds"

    def check_dataset(self, task: Any) -> None:
        """Refuse, in one line, a task with no observations of its own for the ``dataset`` protocol (only a problem
        set run as a task has them: :mod:`.problem_set`)."""
        if not getattr(task, "problems", ()):
            raise UserError(f"the dataset protocol scores a problem set's own obs.dat; {task.id} is no problem set: "
                            "run one as its own task (grail-bench run --task PATH)")

    def dataset_observations(self, task: Any) -> list[tuple[int, Any]]:
        """A problem set's own observations and their true goals' indices (:func:`.problem_set.dataset_observations`)."""
        from grail_bench.domains.symbolic.problem_set import dataset_observations

        return dataset_observations(task)

    def content_digest(self, task: Any) -> str | None:
        """sha256 of a problem set's files (None for other tasks): the results of a problem set are keyed by it,
        so an edited set runs again."""
        return getattr(task, "digest", "") or None

    def make_env(self, goal: Goal, **env_params: Any):
        from grail_bench.domains.symbolic.env import SymbolicEnv

        return SymbolicEnv(goal, **env_params)

    def generate_demos(self, task: GRTask, goal: Goal, n: int, rng: np.random.Generator):
        if task.regime == "boltzmann":
            from grail_bench.domains.boltzmann import generate_demos as boltzmann_demos

            return boltzmann_demos(task, goal, n, rng)
        from grail_bench.domains.symbolic.demos import generate_demos

        return generate_demos(task, goal, n, rng)

    def demonstrator(self, task: GRTask, goal: Goal):
        if task.regime == "boltzmann":
            from grail_bench.domains.boltzmann import BoltzmannDemonstrator

            return BoltzmannDemonstrator(task, goal)
        from grail_bench.domains.symbolic.likelihood import GoalDemonstrator

        return GoalDemonstrator(task, goal)

    def demonstrator_policy(self, task: GRTask, goal: Goal, support: str = "everywhere") -> np.ndarray:
        """The demonstrator's action probabilities of ``goal``, ``(2 ** n_fluents, n_operators)`` (see
        :mod:`.policy`; the Boltzmann regime's is its own policy,
        :func:`grail_bench.domains.boltzmann.demonstrator_policy`)."""
        if task.regime == "boltzmann":
            from grail_bench.domains.boltzmann import demonstrator_policy as boltzmann_policy

            self.check_demonstrator_policy(task, support)
            return boltzmann_policy(task, goal, support)
        from grail_bench.domains.symbolic.policy import demonstrator_policy

        return demonstrator_policy(task, goal, support)

    def check_demonstrator_policy(self, task: GRTask, support: str = "everywhere") -> None:
        """Refuse, in one line and without building anything, a task :meth:`demonstrator_policy` cannot serve."""
        if support not in SUPPORTS:
            raise UserError(f"unknown support {support!r}; choose one of {', '.join(SUPPORTS)}")
        if task.regime not in self.ceiling_regimes:
            raise UserError(f"{task.id}: the symbolic demonstrator's action distribution is stated for the "
                            f"{' and '.join(sorted(self.ceiling_regimes))} regimes, not {task.regime!r}")


DOMAIN = Symbolic()
