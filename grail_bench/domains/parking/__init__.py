"""Parking (highway-env): a car parking nose-in in one of the lot's spots, as gr_libs' Parking problems.

* :mod:`.path`: the lot's layout and the expert's path (plain numpy).
* :mod:`.env`: the goal-pinned env with a goal-free observation (imports highway-env).
* :mod:`.demos`: the scripted expert plus the regimes' action noise.

highway-env needs pygame (LGPL), so it is an optional extra: ``pip install 'grail-bench[parking]'``.
Without it, cards naming this domain still parse and list; building an env or a demonstration raises a
one-line :class:`~grail_bench.core.errors.UserError` naming the extra.
"""

from __future__ import annotations

import importlib
import math
from types import ModuleType
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError

if TYPE_CHECKING:
    import numpy as np

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

MAX_SPOTS = 16  # highway-env's walls (70 m wide) leave room for 16 spots a row; gr_envs registers 10 to 16
EXTRA = "pip install 'grail-bench[parking]'"


def simulator(module: str) -> ModuleType:
    """Import ``grail_bench.domains.parking.<module>``, which needs highway-env.

    Raises:
        UserError: If highway-env (or its pygame) is not installed, naming the extra that installs it.
    """
    try:
        return importlib.import_module(f"{__name__}.{module}")
    except ImportError as exc:
        if (exc.name or "").split(".")[0] in ("highway_env", "pygame"):
            raise UserError(f"the parking domain needs highway-env, an optional extra: {EXTRA}") from None
        raise


def check_spot(goal: Sequence[float], n_spots: int) -> int:
    """``goal``'s spot, ``[spot]`` being an index among the lot's ``2 * n_spots`` lanes.

    Raises:
        UserError: For any other goal.
    """
    if len(goal) != 1 or float(goal[0]) != int(goal[0]) or not 0 <= int(goal[0]) < 2 * n_spots:
        raise UserError(f"goal {list(goal)} must be [spot], a spot index in 0..{2 * n_spots - 1}")
    return int(goal[0])


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{name} must be a finite number, got {value!r}")
    return float(value)


class Parking:
    """The :class:`~grail_bench.task.domain.Domain` of highway-env's parking lot (gr_envs' settings)."""

    name = "parking"
    goal_dim = 1  # [spot]: the goal lane's index in highway-env's road.network.lanes_list(), as gr_envs'
    env_defaults: Mapping[str, Any] = {"n_spots": 14, "heading": math.pi, "max_steps": 100}
    regimes: Mapping[str, Mapping[str, Any]] = {
        "optimal": {},
        "noisy": {"sigma": 0.1},
    }
    bounds: Mapping[str, Range] = {"max_steps": Range(1, 10_000)}  # published: 100
    # The scripted expert in a deterministic simulator, plus continuous noise: no likelihood is stated.
    ceiling_regimes: frozenset[str] = frozenset()
    cache_demos = True  # about 1 s per goal and seed: generated once, kept on disk
    packages = ("highway-env",)  # its simulator: its version keys the cached demonstrations

    def check(self, regime: str, params: Mapping[str, Any], env_params: Mapping[str, Any],
              goals: Sequence[Goal]) -> None:
        if "sigma" in params and _number("sigma", params["sigma"]) < 0:
            raise UserError(f"sigma must be a number >= 0, got {params['sigma']!r}")
        n = env_params["n_spots"]
        if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= MAX_SPOTS:
            raise UserError(f"n_spots must be an integer in 2..{MAX_SPOTS}, got {n!r}")
        _number("heading", env_params["heading"])
        for goal in goals:
            check_spot(goal, n)

    def make_env(self, goal: Goal, **env_params: Any):
        return simulator("env").GRParkingEnv(goal, **env_params)

    def generate_demos(self, task: GRTask, goal: Goal, n: int, rng: np.random.Generator):
        from grail_bench.domains.parking.demos import generate_demos

        return generate_demos(task, goal, n, rng)

    def demonstrator(self, task: GRTask, goal: Goal):
        raise UserError(f"{task.id}: parking demonstrators have no known likelihood")


DOMAIN = Parking()
