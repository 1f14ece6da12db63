"""highway-env's parking lot with the goal pinned to one spot and a flat, goal-free observation.

The settings are gr_envs' (``gr_envs/env_registration/highway_register.py``,
``make_parking_wrapped``; ``gr_envs/wrappers/parking_wrapper.py``,
``ParkingWrapper``): highway-env's ``parking-v0`` with ``n_spots`` spots per
row (14 in gr_libs' ``Parking-S-14-PC-``), no parked cars, the ego car at the
lot's centre at rest with heading ``heading`` (pi: facing -x), and the goal
landmark at the centre of lane ``goal`` of ``road.network.lanes_list()``,
with that lane's heading. Everything else is highway-env's default config:
kinematic bicycle model, action ``(acceleration, steering)`` in [-1, 1]
mapped to +-5 m/s^2 and +-45 degrees, 15 Hz simulation, 5 Hz policy.

The recognizers see the ego car's kinematics as highway-env scales them:
``(x / 100, y / 100, vx / 5, vy / 5, cos h, sin h)``; the goal is hidden.
Reward and success are highway-env's: minus the weighted distance
``sqrt(|d| . [1, 0.3, 0, 0, 0.02, 0.02])`` between these features and the
goal's, success when it is below 0.12: ``|dx| + 0.3 |dy| + 2 (|d cos h| + |d sin h|)``
under 1.44 m, i.e. nose in, lined up with the spot, its centre within a few metres
of the spot's along the spot (the car enters the spot; speed does not count). As
in highway-env, the episode ends on success or on a crash (into a wall), and is
truncated after ``max_steps`` steps.

highway-env's ``step`` builds each observation through pandas four times
(about 25 ms a step); this env steps the same simulation (``_simulate``) and
computes the same features, reward and success test from the ego vehicle
directly, and its ``reset`` rebuilds the scene without those observations.
The ego car (``ParkingCar``) skips two costs of highway-env's vehicle that
this env never reads or that cannot change the outcome: the scan of every
lane for the nearest one after each move, and the polygon collision test
against an object it is visibly clear of. A step then takes about 0.15 ms, and
its results are highway-env's bit for bit (``tests/test_parking.py``).
Nothing is rendered: pygame never opens a window.
"""

from __future__ import annotations

import math
import os
from typing import Any, Sequence

import numpy as np
from gymnasium import Env, spaces

from grail_bench.core.errors import UserError
from grail_bench.domains.parking import check_spot
from grail_bench.domains.parking.path import spot_pose

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # pygame, imported by highway-env, opens no window
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
from highway_env.envs.parking_env import ParkingEnv  # noqa: E402
from highway_env.vehicle.kinematics import Vehicle  # noqa: E402
from highway_env.vehicle.objects import Landmark, RoadObject  # noqa: E402

SCALES = np.array([100.0, 100.0, 5.0, 5.0, 1.0, 1.0])  # highway-env's KinematicsGoal scales
CLEARANCE = 1e-6  # metres: a gap this wide is far above highway-env's float error (~1e-13 m on a 70 m lot)


def _clear_of(car: Vehicle, other: RoadObject, dt: float) -> bool:
    """Whether ``car``, swept over ``dt``, is apart from ``other`` by ``CLEARANCE`` along one of ``other``'s axes.

    highway-env's separating-axis test (``utils.are_polygons_intersecting``) projects both rectangles on each
    of their edges' normals, ``other``'s axes among them, with the car's interval stretched by the relative
    displacement; any axis that separates them makes it report neither a collision nor an imminent one. So
    where this returns True, the full test would find nothing, and ``handle_collisions`` would do nothing.
    """
    c, s = math.cos(car.heading), math.sin(car.heading)
    dx = (car.speed * c - other.speed * math.cos(other.heading)) * dt
    dy = (car.speed * s - other.speed * math.sin(other.heading)) * dt
    offset_x, offset_y = car.position[0] - other.position[0], car.position[1] - other.position[1]
    co, so = math.cos(other.heading), math.sin(other.heading)
    for (ax, ay), half in (((co, so), other.LENGTH / 2), ((-so, co), other.WIDTH / 2)):
        centre = offset_x * ax + offset_y * ay
        extent = car.LENGTH / 2 * abs(c * ax + s * ay) + car.WIDTH / 2 * abs(c * ay - s * ax)
        sweep = dx * ax + dy * ay
        low, high = centre - extent + min(sweep, 0.0), centre + extent + max(sweep, 0.0)
        if low > half + CLEARANCE or high < -half - CLEARANCE:
            return True
    return False


class ParkingCar(Vehicle):
    """highway-env's kinematic car, as the ego, stepped the same with two costs skipped (module docstring).

    The lane it is nearest to (``lane_index``, ``lane``) stays the one at its creation: highway-env scans every
    lane of the lot after each move to update it (about a third of a step), and nothing in a parking step reads it.
    """

    def on_state_update(self) -> None:
        if self.road is not None and self.road.record_history:
            self.history.appendleft(self.create_from(self))

    def _is_colliding(self, other: RoadObject, dt: float) -> tuple[bool, bool, np.ndarray | None]:
        if _clear_of(self, other, dt):
            return False, False, np.zeros(2)
        return super()._is_colliding(other, dt)


class PinnedParkingEnv(ParkingEnv):
    """highway-env's ``ParkingEnv`` with gr_envs' scene: ``n_spots`` spots, a fixed start heading, the goal pinned.

    gr_envs (written against a later highway-env, whose goal lives on the vehicle) replaces the landmark after
    ``reset``; here the scene is built that way in ``_reset``, and the goal is ``self.goal`` as highway-env
    1.8's observation reads it.
    """

    def __init__(self, spot: int, n_spots: int, heading: float) -> None:
        self.spot, self.n_spots, self.start_heading = spot, n_spots, heading
        super().__init__()

    def restart(self, seed: int | None = None) -> None:
        """The scene rebuilt as highway-env's ``reset`` rebuilds it, from the same random draws, without the
        observations and info it then computes through pandas (about 40 ms; ``GRParkingEnv`` computes its own)."""
        Env.reset(self, seed=seed)
        self.time = self.steps = 0
        self.done = False
        self._reset()

    def _reset(self) -> None:
        self._create_road(self.n_spots)
        self._create_vehicles()
        self.vehicle.__class__ = ParkingCar  # same state, highway-env's Vehicle subclassed (see ParkingCar)
        self.road.objects = [o for o in self.road.objects if not isinstance(o, Landmark)]
        self.vehicle.heading = self.start_heading
        lane = self.road.network.lanes_list()[self.spot]
        self.goal = Landmark(self.road, lane.position(lane.length / 2, 0), heading=lane.heading)
        self.vehicle.goal = self.goal
        self.road.objects.append(self.goal)


def features(obj: Any) -> np.ndarray:
    """highway-env's scaled ``(x, y, vx, vy, cos h, sin h)`` of a vehicle or landmark."""
    x, y = obj.position
    vx, vy = obj.velocity
    return np.array([x, y, vx, vy, math.cos(obj.heading), math.sin(obj.heading)]) / SCALES


class GRParkingEnv(Env):
    """Goal-pinned parking (see the module docstring).

    Args:
        goal: ``(spot,)``, the index of the goal spot among the lot's ``2 * n_spots`` lanes.
        n_spots: Spots per row.
        heading: The ego car's heading at the start (radians).
        max_steps: Steps before the episode is truncated.
        render_mode: Only ``None``: nothing is rendered.
    """

    metadata = {"render_modes": []}

    def __init__(self, goal: Sequence[float], *, n_spots: int = 14, heading: float = math.pi, max_steps: int = 100,
                 render_mode: str | None = None) -> None:
        if render_mode is not None:
            raise UserError(f"parking envs are not rendered; render_mode must be None, got {render_mode!r}")
        self.goal = (check_spot(goal, n_spots),)
        self.n_spots, self.heading, self.max_steps = int(n_spots), float(heading), int(max_steps)
        self.render_mode = None
        self.task = None  # set by GRTask.make_env
        self._env = PinnedParkingEnv(self.goal[0], self.n_spots, self.heading)
        # Positions stay inside the walls (0.35, 0.21 scaled); speed is capped at 40 m/s (8 scaled).
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(6,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._steps = 0
        self._target = np.zeros(6)  # the goal landmark's features, set at every reset

    @property
    def goal_in_state(self) -> np.ndarray:
        """The goal spot's centre in the state's coordinates (the state begins with the car's scaled ``(x, y)``;
        goal-conditioned recognizers read it)."""
        x, y, _ = spot_pose(self.goal[0], self.n_spots)
        return np.array([x, y]) / SCALES[:2]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._env.restart(seed=seed)
        self._steps = 0
        self._target = features(self._env.goal)
        return features(self._env.vehicle).astype(np.float32), {"is_success": False}

    def step(self, action: Any):
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (2,) or not np.all(np.isfinite(action)):
            raise ValueError(f"invalid action {action!r}; expected 2 finite numbers")
        env = self._env
        env.time += 1 / env.config["policy_frequency"]
        env._simulate(np.clip(action, -1.0, 1.0))
        self._steps += 1
        achieved = features(env.vehicle)
        crashed = bool(env.vehicle.crashed)
        reward = float(env.compute_reward(achieved, self._target, {}))
        success = bool(env._is_success(achieved, self._target))
        reward += env.config["collision_reward"] * crashed
        return (achieved.astype(np.float32), reward, success or crashed, self._steps >= self.max_steps,
                {"is_success": success})

    def close(self) -> None:
        self._env.close()
