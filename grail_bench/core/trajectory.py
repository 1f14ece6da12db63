"""Trajectories: the types every module shares, where a demonstration reaches its goal, and one rollout helper.

Demonstrations are ``imitation`` :class:`~imitation.data.types.Trajectory`
objects: ``T`` actions, ``T + 1`` observations and one ``info`` dict per action
whose ``"is_success"`` says whether the goal has been reached. Domains run a
fixed horizon, so a demonstration goes on after its goal (the agent stays
there); :func:`goal_horizon` says where the behaviour ends.
"""

from __future__ import annotations

import hashlib

from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol, Sequence

import numpy as np

if TYPE_CHECKING:
    import gymnasium as gym
    from imitation.data.types import Trajectory

Goal = tuple[float, ...]
Demos = Mapping[Goal, Sequence["Trajectory"]]
Policy = Callable[[np.ndarray, int], Any]  # (observation, step) -> action


class EnvFactory(Protocol):
    """Builds the domain env pursuing one candidate goal (what ``Recognizer.fit`` receives)."""

    def __call__(self, goal: Goal) -> gym.Env: ...


def goal_horizon(traj: Trajectory) -> int:
    """Number of actions up to and including the one that reached the goal.

    Uses ``info["is_success"]``; a demonstration without it counts in full.
    """
    if traj.infos is not None:
        for t, info in enumerate(traj.infos):
            if info.get("is_success"):
                return t + 1
    return len(traj.acts)


def until_success(traj: Trajectory) -> Trajectory:
    """The demonstration cut after the action that reached the goal (unchanged if it never says so)."""
    from imitation.data.types import Trajectory

    t = goal_horizon(traj)
    if t == len(traj.acts):
        return traj
    return Trajectory(obs=traj.obs[: t + 1], acts=traj.acts[:t], infos=traj.infos[:t], terminal=True)


def rollout(env: gym.Env, policy: Policy, *, seed: int = 0, require_success: bool = False) -> Trajectory:
    """Play ``policy`` in ``env`` from ``reset(seed=seed)`` until the episode ends.

    Args:
        env: A goal env (episodes end at its fixed horizon).
        policy: ``policy(observation, step) -> action``; the action returned is
            the one recorded.
        seed: Reset seed.
        require_success: Raise if the goal was not reached by the end.

    Returns:
        The trajectory, infos included.

    Raises:
        RuntimeError: With ``require_success``, if the goal was not reached.
    """
    from imitation.data.types import Trajectory

    obs, _ = env.reset(seed=seed)
    observations, acts, infos = [obs], [], []
    done = False
    while not done:
        action = policy(obs, len(acts))
        obs, _, terminated, truncated, info = env.step(action)
        observations.append(obs)
        acts.append(action)
        infos.append(info)
        done = terminated or truncated
    if require_success and not infos[-1].get("is_success"):
        raise RuntimeError(f"the demonstration did not reach goal {getattr(env.unwrapped, 'goal', '?')}")
    return Trajectory(obs=np.stack(observations), acts=np.stack(acts), infos=np.array(infos, dtype=object),
                      terminal=True)


def demos_digest(demos: Sequence[Trajectory]) -> str:
    """SHA-256 of the demonstrations' states and actions, in order (keys cached models to what they learnt from)."""
    digest = hashlib.sha256()
    for traj in demos:
        digest.update(np.ascontiguousarray(traj.obs).tobytes())
        digest.update(np.ascontiguousarray(traj.acts).tobytes())
    return digest.hexdigest()
