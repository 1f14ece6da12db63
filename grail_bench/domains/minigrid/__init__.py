"""The paper's MiniGrid domain: a 9x9 room with one obstacle, three behaviour regimes (and a Boltzmann-rational one,
:mod:`grail_bench.domains.boltzmann`); other rooms (size,
start, walls and lava) through the env parameters, e.g. gr_libs' crossing layouts (``tasks/minigrid_gr_libs.toml``).

* :mod:`.grid`: actions, headings, pure-Python dynamics, regime parameters (no minigrid import).
* :mod:`.env`: the goal-pinned minigrid env.
* :mod:`.demos`: the scripted demonstrators; :mod:`.likelihood`: their exact
  likelihood, for the Bayes ceiling (:mod:`.slip`: in a slipping test room); :mod:`.policy`: their action
  distributions on every state, for the ``demonstrator`` recognizer.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Sequence

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.domains.minigrid.grid import TEST_SHIFTS, check_params, check_slip, split_obstacles

#: The Boltzmann regime's default rationality (``docs/concepts/tasks.md``, "Boltzmann": where its Bayes ceiling
#: lies between chance and the optimal regime's).
BOLTZMANN_BETA = 0.15

if TYPE_CHECKING:
    import numpy as np

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask


class MiniGrid:
    """The :class:`~grail_bench.domains.Domain` of the paper's MiniGrid room."""

    name = "minigrid"
    goal_dim = 2
    env_defaults: Mapping[str, Any] = {
        "size": 9,
        "start": [1, 4],
        "start_dir": 0,
        "obstacles": [[7, 4]],
        "max_steps": 60,
        "fixed_horizon": True,
    }
    # Defaults read from the paper's text and checked against its numbers (see .demos): no preference among
    # shortest paths (a consistent preference is its "biased" regime) and turns inserted "before each action".
    regimes: Mapping[str, Mapping[str, Any]] = {
        # route_choice: "uniform" (drawn per demonstration) or "fixed" (one shortest path per goal).
        "optimal": {"route_choice": "uniform"},
        # One preferred heading order per goal, e.g. "NE" = north, then east.
        "biased": {"routes": []},
        # turn_pattern: "left-right" or "around-and-back" (see .demos).
        "suboptimal": {"route_choice": "uniform", "turn_prob": 1.0, "turn_pattern": "left-right"},
        # Actions drawn with probability proportional to exp(beta * Q) (see grail_bench.domains.boltzmann).
        "boltzmann": {"beta": BOLTZMANN_BETA},
    }
    # Far above every published room (9 and 13 cells a side, at most 200 steps): a mistyped size is refused.
    bounds: Mapping[str, Range] = {"size": Range(high=64), "max_steps": Range(1, 10_000),
                                   "test_slip": Range(0.0, 1.0)}
    ceiling_regimes = frozenset(regimes)
    # Test-time shifts of the dynamics (see .grid.TEST_SHIFTS): the test demonstrations are generated in the
    # shifted room; training demonstrations and every env a recognizer builds stay nominal.
    test_params: Mapping[str, Any] = TEST_SHIFTS
    # Shifts under which the demonstrators' likelihood stays exact (see .likelihood).
    ceiling_shifts = frozenset({"test_obstacles", "test_slip"})
    # The test room's walls replace the room's own: the same walls are no shift.
    test_replaces: Mapping[str, str] = {"test_obstacles": "obstacles"}
    # Regimes whose demonstrators take the dynamics shifts (the Boltzmann one is drawn from the nominal tables).
    shift_regimes = ("optimal", "biased", "suboptimal")
    noop_action = 3  # grid.STAY: the agent neither turns nor moves
    # Runs stored before route_choice existed drew every demonstration's path uniformly.
    implicit: Mapping[str, Any] = {"route_choice": "uniform"}

    def check(self, regime: str, params: Mapping[str, Any], env_params: Mapping[str, Any],
              goals: Sequence[Goal]) -> None:
        check_params(regime, params, len(goals))
        for goal in goals:
            if any(float(c) != int(c) for c in goal):
                raise UserError(f"goal {list(goal)} must be integer cell coordinates")
        free = _free_cells(env_params)
        for goal in goals:
            if tuple(int(c) for c in goal) not in free:
                raise UserError(f"goal {list(goal)} is not a free cell of the room (walls and lava excluded)")

    def check_test(self, test_params: Mapping[str, Any], env_params: Mapping[str, Any],
                   goals: Sequence[Goal]) -> None:
        """Validate the test shifts (``test_slip``, ``test_obstacles``) against the room and goals."""
        if "test_slip" in test_params:
            check_slip(test_params["test_slip"])
        if test_params.get("test_obstacles") is not None:
            free = _free_cells({**env_params, "obstacles": test_params["test_obstacles"]})
            for goal in goals:
                if tuple(int(c) for c in goal) not in free:
                    raise UserError(f"test_obstacles: goal {list(goal)} is not a free cell of the test room")

    def ends_early(self, env_params: Mapping[str, Any]) -> str | None:
        """Why episodes may end before ``max_steps``, or None (see :class:`~grail_bench.task.domain.Domain`)."""
        return None if env_params["fixed_horizon"] else "episodes end at the goal or in lava (fixed_horizon = false)"

    def make_env(self, goal: Goal, **env_params: Any):
        from grail_bench.domains.minigrid.env import GRMiniGridEnv

        return GRMiniGridEnv(goal, **env_params)

    def generate_demos(self, task: GRTask, goal: Goal, n: int, rng: np.random.Generator):
        if task.regime == "boltzmann":
            from grail_bench.domains.boltzmann import generate_demos as boltzmann_demos

            return boltzmann_demos(task, goal, n, rng)
        from grail_bench.domains.minigrid.demos import generate_demos

        return generate_demos(task, goal, n, rng)

    def demonstrator(self, task: GRTask, goal: Goal):
        if task.regime == "boltzmann":
            from grail_bench.domains.boltzmann import BoltzmannDemonstrator

            return BoltzmannDemonstrator(task, goal)
        if task.test_params.get("test_slip"):
            from grail_bench.domains.minigrid.slip import MarkovSlipDemonstrator, SlipDemonstrator, markov

            try:
                return SlipDemonstrator(task, goal)  # every episode enumerated: an exact ceiling
            except UserError:
                if not markov(task):
                    raise
                return MarkovSlipDemonstrator(task, goal)  # its likelihood exact still: a Monte Carlo ceiling
        from grail_bench.domains.minigrid.likelihood import GoalDemonstrator

        return GoalDemonstrator(task, goal)

    def demonstrator_policy(self, task: GRTask, goal: Goal, support: str = "everywhere") -> np.ndarray:
        """The demonstrator's action probabilities of ``goal``, ``(S, 4)``, in every regime (see
        :mod:`.policy` for what a row is per regime and support; the Boltzmann regime's is its own policy,
        :func:`grail_bench.domains.boltzmann.demonstrator_policy`)."""
        from grail_bench.domains.minigrid.policy import check_policy, demonstrator_policy

        if task.regime == "boltzmann":
            from grail_bench.domains.boltzmann import demonstrator_policy as boltzmann_policy

            check_policy(task, support)
            return boltzmann_policy(task, goal, support)
        return demonstrator_policy(task, goal, support)

    def check_demonstrator_policy(self, task: GRTask, support: str = "everywhere") -> None:
        """Refuse, in one line and without building anything, a task :meth:`demonstrator_policy` cannot serve."""
        from grail_bench.domains.minigrid.policy import check_policy

        check_policy(task, support)


def _cell(name: str, value: Any) -> tuple[int, int]:
    if (not isinstance(value, (list, tuple)) or len(value) != 2
            or not all(isinstance(c, int) and not isinstance(c, bool) for c in value)):
        raise UserError(f"{name} must be a cell [x, y] of two integers, got {value!r}")
    return value[0], value[1]


def _free_cells(env_params: Mapping[str, Any]) -> set[tuple[int, int]]:
    """The room's safe cells (neither wall nor lava), after checking its env parameters (a wall runs round the
    ``size`` x ``size`` grid).

    Raises:
        UserError: For a size below 3, obstacles or a start outside the room, the start on an obstacle, or a
            start direction other than 0-3.
    """
    size = env_params["size"]
    if isinstance(size, bool) or not isinstance(size, int) or size < 3:
        raise UserError(f"size must be an integer >= 3 (the room and its walls), got {size!r}")
    inside = {(x, y) for x in range(1, size - 1) for y in range(1, size - 1)}
    walls, lava = split_obstacles(env_params["obstacles"])
    outside = sorted((walls | lava) - inside)
    if outside:
        raise UserError(f"obstacle {list(outside[0])} lies outside the room's free cells 1..{size - 2}")
    start = _cell("start", env_params["start"])
    if start not in inside - walls - lava:
        raise UserError(f"start {list(start)} must be a free cell of the room (1..{size - 2}, not an obstacle)")
    start_dir = env_params["start_dir"]
    if isinstance(start_dir, bool) or start_dir not in (0, 1, 2, 3):
        raise UserError(f"start_dir must be 0 (east), 1 (south), 2 (west) or 3 (north), got {start_dir!r}")
    return inside - walls - lava


DOMAIN = MiniGrid()
