"""The MiniGrid workload every speed benchmark shares: the 6-goal suboptimal task, its seed-0 split, and one
30-step observation of its first goal."""

from __future__ import annotations

from grail_bench.core.trajectory import Trajectory

import grail_bench

TASK = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-6Goals-v1")
TRAIN, TEST = TASK.split(TASK.generate_demos(seed=0))
GOAL = TASK.goals[0]


def thirty_steps() -> Trajectory:
    """The first 30 pairs of the first goal's first test demonstration."""
    traj = TEST[GOAL][0]
    return Trajectory(obs=traj.obs[:31], acts=traj.acts[:30], infos=None, terminal=False)
