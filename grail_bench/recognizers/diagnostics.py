"""Fit diagnostics of recognizers with one policy per goal: did each policy learn to imitate its goal?

Computed once after fitting from the policies' outputs (no training, no
randomness), per goal:

* **agreement** of the policy with its own goal's demonstrations, on the
  training and on the held-out split: discrete actions, the share of steps
  whose greedy action is the demonstrated one; continuous actions, the share
  whose demonstrated action lies within the policy's central 95 % in every
  dimension (``|a - mean| <= 1.96 std``);
* the goal x goal **imitation matrix**: entry ``[i, j]`` is the mean
  probability (discrete) or the per-step likelihood, the geometric mean of the
  density (continuous), of goal ``i``'s demonstrated actions under goal
  ``j``'s policy, on the held-out demonstrations (the training ones where there
  are none);
* a **greedy rollout** from the task's start in the goal's env: whether it
  reaches the goal and in how many steps, beside the demonstrations' mean;
* the **training curves** the learner logged (kept short).

Demonstrations are read up to the step that reached the goal (the absorbed
tail of a fixed-horizon episode says nothing about imitation).
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

import numpy as np

from grail_bench.core.trajectory import Demos, EnvFactory, Goal, goal_horizon, until_success
from grail_bench.recognizers.contract import FitDiagnostics
from grail_bench.recognizers.scoring import PolicyOutput

OutputsAt = Callable[[np.ndarray], PolicyOutput]  # states (T, ...) -> outputs of every goal's policy (K, T, ...)
Z95 = 1.959963984540054  # the central 95 % of a Gaussian


def _pairs(trajs: Sequence[Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """States and actions of demonstrations, each cut after the goal (None without any)."""
    cut = [until_success(t) for t in trajs]
    cut = [t for t in cut if len(t.acts)]
    if not cut:
        return None
    return np.concatenate([np.asarray(t.obs[:-1]) for t in cut]), np.concatenate([np.asarray(t.acts) for t in cut])


def _agreement(out: PolicyOutput, k: int, actions: np.ndarray) -> float:
    if out.probs is not None:
        return float(np.mean(out.probs[k].argmax(axis=-1) == actions.astype(np.int64)))
    std = np.broadcast_to(out.std[k], out.mean[k].shape)
    acts = actions.reshape(len(actions), -1)
    return float(np.mean(np.all(np.abs(acts - out.mean[k]) <= Z95 * std, axis=-1)))


def _imitation(out: PolicyOutput, actions: np.ndarray) -> list[float]:
    """Per policy, the mean probability (or per-step likelihood) of ``actions``."""
    if out.probs is not None:
        picked = out.probs[:, np.arange(len(actions)), actions.astype(np.int64)]
        return picked.mean(axis=1).tolist()
    std = np.broadcast_to(out.std, out.mean.shape)
    z = (actions.reshape(len(actions), -1)[None] - out.mean) / std
    logpdf = np.sum(-0.5 * z * z - np.log(std) - 0.5 * np.log(2 * np.pi), axis=-1)
    return np.exp(logpdf.mean(axis=1)).tolist()


def _greedy(out: PolicyOutput, k: int, space: Any) -> Any:
    if out.probs is not None:
        return int(out.probs[k, 0].argmax())
    return np.clip(out.mean[k, 0], space.low, space.high).astype(space.dtype)


def rollout(outputs_at: OutputsAt, k: int, goal: Goal, env_factory: EnvFactory) -> tuple[bool, int]:
    """Goal ``k``'s policy played greedily from the start: ``(reached the goal, steps to it or the whole length)``."""
    env = env_factory(goal)
    try:
        obs, _ = env.reset(seed=0)
        steps, done = 0, False
        while not done:
            obs, _, terminated, truncated, info = env.step(_greedy(outputs_at(np.asarray(obs)[None]), k,
                                                                   env.action_space))
            steps += 1
            if info.get("is_success"):
                return True, steps
            done = terminated or truncated
        return False, steps
    finally:
        env.close()


def policy_diagnostics(outputs_at: OutputsAt, goals: Sequence[Goal], train: Demos, held_out: Demos,
                       env_factory: EnvFactory | None,
                       curves: Mapping[Goal, Mapping[str, Sequence[float]]] | None = None) -> FitDiagnostics:
    """The :class:`FitDiagnostics` of K goal policies (see the module docstring).

    Args:
        outputs_at: Every goal's policy outputs on raw states.
        goals: The goals, in the policies' order.
        train: The demonstrations the policies were fitted on.
        held_out: Other demonstrations of the same goals (may be empty).
        env_factory: Builds a goal's env for the greedy rollout (None: no rollout).
        curves: Per goal, the training curves the learner logged.
    """
    agreement_train, agreement_held, imitation, reached, lengths, demo_lengths = [], [], [], [], [], []
    for k, goal in enumerate(goals):
        own = _pairs(train.get(goal, ()))
        held = _pairs(held_out.get(goal, ()))
        agreement_train.append(_agreement(outputs_at(own[0]), k, own[1]) if own else float("nan"))
        agreement_held.append(_agreement(outputs_at(held[0]), k, held[1]) if held else None)
        probe = held or own
        imitation.append(_imitation(outputs_at(probe[0]), probe[1]) if probe else [float("nan")] * len(goals))
        ok, steps = rollout(outputs_at, k, goal, env_factory) if env_factory is not None else (None, None)
        reached.append(ok)
        lengths.append(steps)
        demo_lengths.append(float(np.mean([goal_horizon(t) for t in train.get(goal, ())])) if train.get(goal) else 0.0)
    return FitDiagnostics(
        goals=tuple(tuple(g) for g in goals), agreement_train=tuple(agreement_train),
        agreement_held_out=tuple(agreement_held), imitation=tuple(tuple(float(v) for v in row) for row in imitation),
        reached=tuple(reached), rollout_length=tuple(lengths), demo_length=tuple(demo_lengths),
        curves={k: dict(curves[g]) for k, g in enumerate(goals) if curves and g in curves},
    )
