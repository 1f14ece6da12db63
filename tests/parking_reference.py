"""The parking env as highway-env itself resets and steps it: the reference ``ParkingCar`` and ``restart`` are held
to (``test_parking.py``) and timed against (``benchmarks/test_speed.py``). Import after checking for highway-env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from highway_env.vehicle.kinematics import Vehicle

from grail_bench.domains.parking.env import GRParkingEnv, features


class HighwayEnvsOwn(GRParkingEnv):
    """The same env reset by highway-env's own ``reset`` and stepped with its own ``Vehicle``."""

    def reset(self, *, seed=None, options=None):
        gym.Env.reset(self, seed=seed)
        self._env.reset(seed=seed)
        self._env.vehicle.__class__ = Vehicle
        self._steps = 0
        self._target = features(self._env.goal)
        return features(self._env.vehicle).astype(np.float32), {"is_success": False}
