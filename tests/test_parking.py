"""Parking (highway-env, the optional extra `parking`): the env, the scripted expert and an end-to-end run."""

from __future__ import annotations

import math
import sys

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("highway_env")

import grail_bench  # noqa: E402
from grail_bench.core.errors import UserError  # noqa: E402
from grail_bench.core.trajectory import rollout  # noqa: E402
from grail_bench.domains.parking.demos import expert  # noqa: E402
from grail_bench.domains.parking.env import SCALES, GRParkingEnv  # noqa: E402
from grail_bench.domains.parking.path import spot_pose  # noqa: E402
from grail_bench.harness.api import evaluate  # noqa: E402
from highway_env import utils  # noqa: E402
from parking_reference import HighwayEnvsOwn  # noqa: E402

IDS = ["GRAIL/Parking-Optimal-v0", "GRAIL/Parking-Noisy-0.1-v0", "GRAIL/Parking-Noisy-0.3-v0"]
GR_LIBS_L5 = ((1,), (4,), (8,), (11,), (14,), (18,), (21,))


def parked(obs: np.ndarray, spot: int, n_spots: int = 14) -> bool:
    """highway-env's success test, restated: |dx| + 0.3 |dy| + 2 (|d cos| + |d sin|) < 1.44 m, nose in."""
    x, y, heading = spot_pose(spot, n_spots)
    state = obs.astype(np.float64) * SCALES
    return abs(state[0] - x) + 0.3 * abs(state[1] - y) + 2 * (abs(state[4] - math.cos(heading))
                                                              + abs(state[5] - math.sin(heading))) < 1.44


@pytest.mark.parametrize("task_id", IDS)
def test_every_id_passes_the_env_checker(task_id):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(task_id)
    assert env.unwrapped.task.goals == GR_LIBS_L5
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (6,) and np.allclose(obs, [0, 0, 0, 0, -1, 0], atol=1e-6)  # at rest, facing -x


def test_the_pinned_goal_decides_reward_and_success():
    task = grail_bench.make_task(IDS[0])
    for spot in (1, 21):
        env = task.make_env((spot,))
        traj = rollout(env, lambda obs, t, act=expert((spot,), 14, math.pi): act(obs), require_success=True)
        assert parked(traj.obs[-1], spot) and not any(parked(o, s) for o in traj.obs for s in (4, 14))
        # The same path scored against another spot's env is never a success there.
        other = task.make_env((4,))
        other.reset(seed=0)
        assert not any(other.step(a)[4]["is_success"] for a in traj.acts)


def test_the_expert_parks_in_every_spot_of_the_lot():
    from grail_bench.domains.parking import DOMAIN

    task = grail_bench.make_task(IDS[0])
    lengths = []
    for spot in range(28):
        act = expert((spot,), 14, math.pi)
        traj = rollout(DOMAIN.make_env((spot,), **task.env_params), lambda obs, t: act(obs), require_success=True)
        assert parked(traj.obs[-1], spot)
        lengths.append(len(traj.acts))
    assert max(lengths) < task.env_params["max_steps"]


@pytest.mark.parametrize("task_id", IDS)
def test_demonstrations_are_seeded_and_park(task_id):
    from grail_bench.domains.parking import DOMAIN

    task = grail_bench.make_task(task_id)
    for goal, trajs in task.generate_demos(seed=3, n_demos=2).items():
        for traj in trajs:
            assert traj.infos[-1]["is_success"] and parked(traj.obs[-1], goal[0])
            assert not any(info["is_success"] for info in traj.infos[:-1])
    # Generated afresh (not read from the demonstration cache), the same seed gives the same demonstrations.
    first, again = (DOMAIN.generate_demos(task, (18,), 2, np.random.default_rng(3)) for _ in range(2))
    for a, b in zip(first, again):
        assert np.array_equal(a.obs, b.obs) and np.array_equal(a.acts, b.acts)


def test_noise_changes_the_actions_by_about_sigma():
    optimal = grail_bench.make_task(IDS[0]).generate_demos(seed=0, n_demos=2)
    noisy = grail_bench.make_task(IDS[2]).generate_demos(seed=0, n_demos=2)
    for goal, trajs in optimal.items():
        assert np.array_equal(trajs[0].acts, trajs[1].acts)  # the expert alone is deterministic
        assert not np.array_equal(trajs[0].acts, noisy[goal][0].acts)
    # Replay the expert on a noisy demonstration's states: the residual is the noise (clipped at +-1).
    traj = noisy[(8,)][0]
    act = expert((8,), 14, math.pi)
    clean = np.array([act(o) for o in traj.obs[:-1]])
    inside = np.abs(traj.acts) < 0.999
    assert 0.2 < (traj.acts - clean)[inside].std() < 0.4


def test_parameters_are_checked_when_the_task_is_built():
    with pytest.raises(ValueError, match=r"goal \[28\] must be \[spot\], a spot index in 0..27"):
        grail_bench.make_task(IDS[0]).__class__(id="GRAIL/T-v0", domain="parking", regime="optimal",
                                                goals=((1,), (28,)))
    with pytest.raises(ValueError, match="sigma must be a number >= 0"):
        grail_bench.make_task(IDS[1], sigma=-0.1)
    with pytest.raises(ValueError, match="n_spots must be an integer in 2..16"):
        grail_bench.make_task(IDS[0], n_spots=20)


def test_a_missing_extra_is_one_line_naming_it(monkeypatch):
    for name in ["highway_env", *(m for m in sys.modules if m.startswith("highway_env."))]:
        monkeypatch.setitem(sys.modules, name, None)  # importing highway-env now fails
    monkeypatch.delitem(sys.modules, "grail_bench.domains.parking.env", raising=False)
    with pytest.raises(UserError, match=r"^the parking domain needs highway-env, an optional extra: "
                                        r"pip install 'grail-bench\[parking\]'$"):
        gym.make(IDS[0])
    with pytest.raises(UserError, match=r"grail-bench\[parking\]"):
        grail_bench.make_task(IDS[1]).generate_demos(seed=12345, n_demos=1)


def test_bc_fits_and_scores_end_to_end():
    (record,) = evaluate(IDS[1], [("bc", {"n_epochs": 5})], seeds=1, observability=[0.5],
                         task_params={"n_demos": 4, "n_train": 3})
    assert record.n_seeds == 1 and record.accuracy_mean > 2 / 7  # 7 goals: chance is 1/7


def test_the_fast_car_steps_as_highway_envs_own_bit_for_bit(monkeypatch):
    """Random driving (into the walls too) and the expert's paths give the same observations, rewards, ends and
    crash impacts with ``ParkingCar``'s shortcuts and ``restart`` as with highway-env's vehicle and reset."""
    calls = {"fast": 0}
    full_test = utils.are_polygons_intersecting

    def counted(*args):
        calls["fast"] += stepping_fast
        return full_test(*args)

    monkeypatch.setattr(utils, "are_polygons_intersecting", counted)
    rng = np.random.default_rng(0)
    crashes, stepping_fast = 0, False
    for episode in range(24):
        if episode % 4 == 0:  # new envs, then three unseeded resets that continue their generators
            spot = int(rng.integers(28))
            fast, ref = GRParkingEnv((spot,), max_steps=80), HighwayEnvsOwn((spot,), max_steps=80)
        seed = episode if episode % 4 == 0 else None
        obs, first = fast.reset(seed=seed)[0], ref.reset(seed=seed)[0]
        assert np.array_equal(obs, first)
        act = expert((spot,), 14, math.pi) if episode % 3 == 0 else None
        throttle = rng.uniform(0.05, 1.0)
        for _ in range(80):
            a = act(obs) if act else np.array([throttle, rng.uniform(-1, 1)], np.float32)
            stepping_fast = True
            out_fast = fast.step(a)
            stepping_fast = False
            out_ref = ref.step(a)
            assert np.array_equal(out_fast[0], out_ref[0]) and out_fast[1:] == out_ref[1:]
            assert fast._env.vehicle.crashed == ref._env.vehicle.crashed
            obs = out_fast[0]
            if out_fast[2] or out_fast[3]:
                crashes += fast._env.vehicle.crashed
                break
    assert crashes >= 3  # the walls were hit, so the shortcut's fallback to the full test was exercised
    assert calls["fast"] > 0
