"""Parking demonstrators: the scripted expert on its path to the spot, plus the regimes' action noise.

* ``optimal``: the expert's action. The simulator and the expert are deterministic, so every
  demonstration of a goal is the same trajectory.
* ``noisy`` (``sigma``): the expert's action plus N(0, sigma^2) on each dimension at every step, clipped to
  [-1, 1]; the clipped action is what the demonstration records. The expert is closed-loop, so noisy
  demonstrations still park (all 50 of 50 per goal of gr_libs' set at sigma 0.3); a noisy rollout that
  crashes or runs out of steps is drawn again, up to :data:`ATTEMPTS` times.

The expert follows :func:`~grail_bench.domains.parking.path.expert_path` (the shortest bounded-curvature
path to a pre-spot pose, then straight in) with a pure-pursuit steering law inverted through highway-env's
kinematic bicycle model, at a speed that falls with the distance left to the spot's centre.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable

import numpy as np

from grail_bench.core.trajectory import rollout
from grail_bench.domains.parking.path import Pose, expert_path

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

    from grail_bench.core.trajectory import Goal
    from grail_bench.task.model import GRTask

Controller = Callable[[np.ndarray], np.ndarray]
LENGTH = 5.0  # highway-env's vehicle length; its kinematic model turns about the car's centre
MAX_STEER, MAX_ACCEL = math.pi / 4, 5.0  # highway-env's ContinuousAction ranges
LOOKAHEAD = 4.0  # metres along the path
CRUISE, APPROACH, SPEED_GAIN = 5.0, 1.5, 2.0  # top speed and speed into the spot (m/s); speed error gain (1/s)
ATTEMPTS = 20  # noisy rollouts tried per demonstration before giving up


def pure_pursuit(path: np.ndarray) -> Controller:
    """A controller tracking ``path`` (``(N, 3)`` points, the spot's centre last); stateful: one per episode.

    Observations are highway-env's scaled features ``(x/100, y/100, vx/5, vy/5, cos h, sin h)``.
    """
    xy = path[:, :2]
    remaining = np.concatenate([np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1)[::-1])[::-1], [0.0]])
    state = {"i": 0}

    def act(obs: np.ndarray) -> np.ndarray:
        position = obs[:2].astype(np.float64) * 100.0
        speed = float(np.hypot(obs[2], obs[3]) * 5.0)
        heading = math.atan2(obs[5], obs[4])
        # Progress only forwards along the path, within a window, so that a loop never short-cuts.
        window = slice(state["i"], min(len(xy), state["i"] + 40))
        state["i"] += int(np.argmin(np.linalg.norm(xy[window] - position, axis=1)))
        ahead = state["i"] + int(np.searchsorted(-remaining[state["i"]:], -(remaining[state["i"]] - LOOKAHEAD)))
        target = xy[min(ahead, len(xy) - 1)]
        if ahead >= len(xy):  # past the path's end: aim beyond the spot's centre along its heading
            over = LOOKAHEAD - remaining[state["i"]]
            target = xy[-1] + over * np.array([math.cos(path[-1, 2]), math.sin(path[-1, 2])])
        alpha = math.atan2(target[1] - position[1], target[0] - position[0]) - heading
        curvature = 2.0 * math.sin(alpha) / LOOKAHEAD
        beta = math.asin(float(np.clip(curvature * LENGTH / 2, -1.0, 1.0)))
        steer = math.atan(2.0 * math.tan(beta))
        wanted = min(CRUISE, max(APPROACH, remaining[state["i"]]))
        accel = SPEED_GAIN * (wanted - speed)
        return np.clip([accel / MAX_ACCEL, steer / MAX_STEER], -1.0, 1.0).astype(np.float32)

    return act


def expert(goal: Goal, n_spots: int, heading: float) -> Controller:
    """The scripted expert parking in spot ``goal[0]`` from the lot's centre (a new controller per episode)."""
    start: Pose = (0.0, 0.0, heading)
    return pure_pursuit(expert_path(start, int(goal[0]), n_spots))


def generate_demos(task: GRTask, goal: Goal, n: int, rng: np.random.Generator) -> list[Trajectory]:
    """Demonstrations of one goal under the task's regime (see module docstring).

    Raises:
        RuntimeError: If a demonstration fails to park :data:`ATTEMPTS` times in a row (with noise so large
            that the car crashes or runs out of time).
    """
    n_spots, heading = int(task.env_params["n_spots"]), float(task.env_params["heading"])
    sigma = float(task.params.get("sigma", 0.0))
    env = task.make_env(goal)
    demos = []
    try:
        for _ in range(n):
            for attempt in range(ATTEMPTS):
                controller = expert(goal, n_spots, heading)

                def policy(obs: np.ndarray, t: int, act: Controller = controller) -> np.ndarray:
                    noise = rng.normal(0.0, sigma, size=2) if sigma > 0 else 0.0
                    return np.clip(act(obs) + noise, -1.0, 1.0).astype(np.float32)

                try:
                    demos.append(rollout(env, policy, require_success=True))
                    break
                except RuntimeError:
                    if sigma == 0 or attempt == ATTEMPTS - 1:
                        raise
    finally:
        env.close()
    return demos
