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
from imitation.data.types import Trajectory

from grail_bench.domains.panda_reach import GRPandaReachEnv
from grail_bench.seeding import EXPERT, goal_seed

if TYPE_CHECKING:
    from grail_bench.task import Goal, GRTask

Policy = Callable[[np.ndarray], np.ndarray]
SAC_NET = [64, 64]


def scripted_expert(goal: Goal, gain: float = 10.0, limit: float = 1.0) -> Policy:
    """Move the end effector straight at the goal: ``clip(gain * (goal - ee), -limit, limit)``."""
    target = np.asarray(goal, dtype=np.float64)
    return lambda obs: np.clip(gain * (target - obs[:3]), -limit, limit).astype(np.float32)


def sac_expert(task: GRTask, goal: Goal, seed: int) -> Policy:
    """The goal's SAC expert, trained once per goal, expert seed, env and budget, then read from the cache."""
    from importlib.metadata import version

    from grail_bench.cache import cached_state_dict
    from grail_bench.rl import learn, make_sac

    steps = int(task.params["expert_steps"])
    env = task.make_env(goal)
    key = {"goal": list(goal), "env": dict(task.env_params), "seed": seed, "steps": steps, "net": SAC_NET,
           "versions": [version("stable-baselines3"), version("torch"), version("panda-gym")]}
    train_seed = goal_seed(seed, goal, EXPERT)
    state, _ = cached_state_dict("panda-sac-expert", key,
                                 lambda: learn(make_sac(env, SAC_NET, train_seed), steps))
    model = make_sac(env, SAC_NET)
    model.policy.load_state_dict(state)
    env.close()
    return lambda obs: model.policy.predict(obs, deterministic=True)[0]


def noise_sampler(task: GRTask, rng: np.random.Generator) -> Callable[[], np.ndarray]:
    """Per-step action noise of the task's regime (zeros for ``optimal``)."""
    if task.regime == "optimal":
        return lambda: np.zeros(3)
    if task.regime == "gaussian":
        sigma = float(task.params["sigma"])
        if sigma < 0:
            raise ValueError(f"{task.id}: sigma must be >= 0, got {sigma}")
        return lambda: rng.normal(0.0, sigma, size=3)
    if task.regime == "uniform":
        w = float(task.params["half_width"])
        if w < 0:
            raise ValueError(f"{task.id}: half_width must be >= 0, got {w}")
        return lambda: rng.uniform(-w, w, size=3)
    raise ValueError(f"{task.id}: panda_reach has no regime {task.regime!r}")


def rollout(env: GRPandaReachEnv, policy: Policy, noise: Callable[[], np.ndarray]) -> Trajectory:
    """One full-horizon demonstration."""
    obs, _ = env.reset(seed=0)
    observations, acts, infos = [obs], [], []
    for _ in range(env.max_steps):
        action = np.clip(policy(obs) + noise(), -env.max_action, env.max_action).astype(np.float32)
        obs, _, _, truncated, info = env.step(action)
        observations.append(obs)
        acts.append(action)
        infos.append(info)
        if truncated:
            break
    return Trajectory(obs=np.stack(observations), acts=np.stack(acts), infos=np.array(infos, dtype=object),
                      terminal=True)


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal under the task's regime (see module docstring)."""
    if task.params["expert"] == "scripted":
        policy = scripted_expert(goal, limit=float(task.env_params["max_action"]))
    elif task.params["expert"] == "sac":
        policy = sac_expert(task, goal, int(task.params["expert_seed"]))
    else:
        raise ValueError(f"{task.id}: expert must be 'sac' or 'scripted', got {task.params['expert']!r}")
    noise = noise_sampler(task, rng)
    env = task.make_env(goal)
    try:
        return [rollout(env.unwrapped, policy, noise) for _ in range(n)]
    finally:
        env.close()
