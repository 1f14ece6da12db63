"""The same seed trains the same PPO agent on the lock's SB3 as on the SB3 release the published models came from."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import grail_bench
from grail_bench.core.rl import make_ppo
from grail_bench.core.torchutil import single_thread

FIXTURES = Path(__file__).parent / "fixtures" / "ppo"
CASES = {"minigrid": "GRAIL/MiniGrid-Optimal-6Goals-v0", "point_maze": "GRAIL/PointMaze-Optimal-v0"}


def train_ppo(case: str) -> dict[str, np.ndarray]:
    """DRACO's PPO agent for the task's first goal, after two rounds (2 x 8 x 128 steps)."""
    task = grail_bench.make_task(CASES[case])
    with single_thread():
        model = make_ppo(lambda: task.make_env(task.goals[0]), [64, 64], seed=5)
        model.learn(2 * 8 * 128)
    return {k: v.numpy() for k, v in model.policy.state_dict().items()}


@pytest.mark.parametrize("case", CASES)
def test_ppo_trains_the_weights_recorded_on_sb3_2_2(case):
    recorded = np.load(FIXTURES / f"{case}.npz")
    assert str(recorded["sb3"]) == "2.2.1"
    got = train_ppo(case)
    assert {f"weight/{k}" for k in got} == {k for k in recorded.files if k.startswith("weight/")}
    for key, value in got.items():
        np.testing.assert_array_equal(value, recorded[f"weight/{key}"], err_msg=key)
