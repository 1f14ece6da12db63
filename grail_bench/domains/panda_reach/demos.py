"""PandaReach demonstrators: a SAC expert or a scripted controller, plus action noise.

* ``optimal``: the expert's action.
* ``gaussian`` (``sigma``): the expert's action plus N(0, sigma^2) per dimension and step.
* ``uniform`` (``half_width``): the expert's action plus U(-w, w) per dimension and step.

Noisy actions are clipped to the action box, and the clipped action is what the
demonstration records. The expert (``expert`` parameter) is ``"sac"``, a SAC
agent trained on the goal's dense reward, or ``"scripted"``, a proportional
controller towards the goal, fast enough for tests. The SAC expert is part of
the demonstrator: it is trained once per goal with ``expert_seed`` and cached
on disk; the run seed varies only the demonstrations sampled from it (through
the action noise). Each demonstration runs the full horizon.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

from grail_bench.core.seeding import EXPERT, goal_seed
from grail_bench.core.trajectory import rollout
from grail_bench.domains.shifts import action_scale_overrides

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

Policy = Callable[[np.ndarray], np.ndarray]
SAC_NET = [64, 64]


def scripted_expert(goal: Goal, gain: float = 10.0, limit: float = 1.0) -> Policy:
    """Move the end effector straight at the goal: ``clip(gain * (goal - ee), -limit, limit)``."""
    target = np.asarray(goal, dtype=np.float64)
    return lambda obs: np.clip(gain * (target - obs[:3]), -limit, limit).astype(np.float32)


def sac_expert(task: GRTask, goal: Goal, seed: int) -> Policy:
    """The goal's SAC expert, trained once per goal, expert seed, env and budget, then read from the cache."""
    from importlib.metadata import version

    from grail_bench.core import experts

    env = task.make_env(goal)
    try:
        key = {"goal": list(goal), "env": dict(task.env_params), "panda-gym": version("panda-gym")}
        return experts.sac_expert("panda-sac-expert", env, key, int(task.params["expert_steps"]),
                             goal_seed(seed, goal, EXPERT), SAC_NET)
    finally:
        env.close()


def noise_sampler(task: GRTask, rng: np.random.Generator) -> Callable[[], np.ndarray]:
    """Per-step action noise of the task's regime (zeros for ``optimal``)."""
    if task.regime == "gaussian":
        sigma = float(task.params["sigma"])
        return lambda: rng.normal(0.0, sigma, size=3)
    if task.regime == "uniform":
        w = float(task.params["half_width"])
        return lambda: rng.uniform(-w, w, size=3)
    return lambda: np.zeros(3)


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal under the task's regime (see module docstring)."""
    limit = float(task.env_params["max_action"])
    if task.params["expert"] == "scripted":
        expert = scripted_expert(goal, limit=limit)
    else:
        expert = sac_expert(task, goal, int(task.params["expert_seed"]))
    noise = noise_sampler(task, rng)
    env = task.make_env(goal, **action_scale_overrides(task.test_params))  # a test split's shifted dynamics
    try:
        return [rollout(env, lambda obs, t: np.clip(expert(obs) + noise(), -limit, limit).astype(np.float32))
                for _ in range(n)]
    finally:
        env.close()
