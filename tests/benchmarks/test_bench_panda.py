"""PandaReach against its physics floor (``make bench``): what a step and a DRACO-PPO fit cost beyond pybullet's own
``stepSimulation``.

The floor is a bare ``p.stepSimulation`` loop on the same scene, moving as the env moves it: each step's motor
targets are set (untimed) by the robot's own ``set_action`` for the same action, then the simulator steps as many
times as the env does per step (panda-gym's 20 substeps), timed alone. Rounds of env steps and of the floor
alternate, so both see the same machine load; the ``ratio`` (env / floor medians) is the number to read.
"""

from __future__ import annotations

import statistics
import time
from collections import Counter

import numpy as np
import pybullet
import pytest

import grail_bench
from grail_bench.core.torchutil import single_thread
from grail_bench.domains.panda_reach.env import GRPandaReachEnv
from grail_bench.recognizers import make_recognizer

EPISODE = 50  # the env's default horizon: one round is one episode


def test_panda_env_step_against_the_pybullet_floor(benchmark):
    """Median seconds per env step (``GRPandaReachEnv.step``) and per floor step (the same motion's
    ``stepSimulation`` calls alone), and their ratio."""
    env = GRPandaReachEnv()
    sim, robot = env._env.sim, env._env.robot
    client = sim.physics_client._client
    rng = np.random.default_rng(0)
    floor: list[float] = []

    def floor_round() -> tuple[tuple, dict]:
        """Untimed by the benchmark: one episode of the floor (timed here), then a fresh episode for the env."""
        env.reset(seed=0)
        actions = rng.uniform(-1, 1, size=(EPISODE, 3)).astype(np.float32)
        spent = 0.0
        for action in actions:
            robot.set_action(action)
            start = time.perf_counter()
            for _ in range(sim.n_substeps):
                pybullet.stepSimulation(physicsClientId=client)
            spent += time.perf_counter() - start
        floor.append(spent / EPISODE)
        env.reset(seed=0)
        return (rng.uniform(-1, 1, size=(EPISODE, 3)).astype(np.float32),), {}

    def episode(actions: np.ndarray) -> None:
        for action in actions:
            env.step(action)

    benchmark.pedantic(episode, setup=floor_round, rounds=20, iterations=1, warmup_rounds=1)
    env.close()
    step = benchmark.stats.stats.median / EPISODE
    floor_step = statistics.median(floor)
    benchmark.extra_info.update(env_step=step, floor_step=floor_step, ratio=step / floor_step)
    assert step / floor_step < 2.0  # the env adds inverse kinematics and reads; the simulator is most of a step


def test_draco_ppo_fit_against_the_physics(benchmark, monkeypatch):
    """A DRACO-PPO fit of one PandaReach goal at a small budget (2 PPO rounds of 8 x 128 steps): seconds per step,
    and the shares of it spent in the simulator's steps, in inverse kinematics, in the env's other work, in the
    rollouts' other work (policy forward, buffer), in the numpy PPO update and in the rest (building 9 envs and the
    model, which a default fit of 150 000 steps spends once)."""
    import panda_gym.pybullet as panda_pybullet
    import torch
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    from grail_bench.core.ppo_update import NumpyPPO

    spent: Counter[str] = Counter()

    def timed(owner, name: str, part: str) -> None:
        inner = getattr(owner, name)

        def wrapper(*args, **kwargs):
            start = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                spent[part] += time.perf_counter() - start

        monkeypatch.setattr(owner, name, wrapper)

    for owner, name, part in ((panda_pybullet.PyBullet, "step", "physics"),
                              (panda_pybullet.PyBullet, "inverse_kinematics", "ik"),
                              (GRPandaReachEnv, "step", "env"), (OnPolicyAlgorithm, "collect_rollouts", "rollouts"),
                              (NumpyPPO, "train", "update")):
        timed(owner, name, part)
    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", expert="scripted", n_demos=2, n_train=1)
    steps = 2 * 8 * 128
    rec = make_recognizer("draco", ppo_steps=steps)

    def fit() -> None:
        spent.clear()
        with single_thread():
            rec.train_policy(task.goals[0], [], task.make_env, seed=0)

    torch.optim.Adam([torch.zeros(1, requires_grad=True)])  # its one-time imports (seconds), outside the fit
    benchmark.pedantic(fit, rounds=1, iterations=1)
    total = benchmark.stats.stats.median
    shares = {"physics": spent["physics"], "ik": spent["ik"], "env_other": spent["env"] - spent["physics"] - spent["ik"],
              "rollouts_other": spent["rollouts"] - spent["env"], "update": spent["update"]}
    shares["rest"] = total - spent["rollouts"] - spent["update"]
    benchmark.extra_info.update(per_step=total / steps, **{f"share_{k}": v / total for k, v in shares.items()})
    assert spent["physics"] / total > 0.4  # a fit at the floor is mostly physics
