"""Trajectories: the types every module shares, where a demonstration reaches its goal, and the rollout helpers.

Demonstrations and observations are :class:`Trajectory` objects: ``T``
actions, ``T + 1`` observations (``acts[t]`` was taken in ``obs[t]``) and,
for demonstrations, one info dict per action whose ``"is_success"`` says
whether the goal has been reached by then. The fields are those of
``imitation``'s ``Trajectory``, so one of those (or any object with the same
fields) is accepted wherever a trajectory is read.

**Training demonstrations are padded to a fixed horizon.** Most domains run
every episode to the env's horizon (MiniGrid's ``max_steps``, PandaReach's
and PointMaze's time limits): a demonstration goes on after the action that
reached its goal, the agent staying there (MiniGrid's "stay" action; a
continuous controller keeps acting at the goal), with ``is_success`` true
from that action on. :func:`goal_horizon` says where the behaviour ends and
:func:`until_success` cuts a demonstration there; whether to learn from the
steps after it is each recognizer's choice (``bc`` cuts them). Domains whose
env ends the episode at the goal (parking, symbolic planning) have no such
steps.

**Observed trajectories stop at the goal.** What a recognizer scores is the
``k`` pairs an observation protocol picks from a test demonstration: from
its path up to the goal under the default protocols (``subset``,
``prefix``), from the whole padded episode only under the ``horizon-*``
ones (which leak the goal). Their ``infos`` are None and ``terminal`` is
False, so nothing about the goal leaks through them.
"""

from __future__ import annotations

import dataclasses
import hashlib
from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol, Sequence

import numpy as np

if TYPE_CHECKING:
    import gymnasium as gym


@dataclasses.dataclass(frozen=True, eq=False)
class Trajectory:
    """One episode: ``T + 1`` observations, ``T >= 1`` actions and (optionally) one info dict per action.

    A training demonstration runs to the task's fixed horizon (see the module docstring); an observed
    trajectory holds the pairs a protocol picked, without infos.

    Attributes:
        obs: Observations, ``(T + 1, *observation_shape)``: the state before every action and the last state.
            On the ``actions`` observation channel the states are NaN.
        acts: Actions, ``(T, *action_shape)``; ``acts[t]`` was taken in ``obs[t]``. On the ``states``
            channel they are NaN.
        infos: ``T`` info dicts as the env returned them (``"is_success"``: the goal has been reached by
            this action), or None (observed trajectories never carry them).
        terminal: Whether the episode ended by itself (rather than being cut).
    """

    obs: np.ndarray
    acts: np.ndarray
    infos: np.ndarray | None = None
    terminal: bool = True

    def __post_init__(self) -> None:
        if len(self.acts) == 0:
            raise ValueError("a trajectory needs at least one action")
        if len(self.obs) != len(self.acts) + 1:
            raise ValueError(f"a trajectory has one observation more than actions, got {len(self.obs)} observations"
                             f" and {len(self.acts)} actions")
        if self.infos is not None and len(self.infos) != len(self.acts):
            raise ValueError(f"a trajectory has one info per action, got {len(self.infos)} infos and "
                             f"{len(self.acts)} actions")

    def __len__(self) -> int:
        return len(self.acts)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Trajectory):
            return NotImplemented
        infos = (self.infos is None and other.infos is None) or (
            self.infos is not None and other.infos is not None and list(self.infos) == list(other.infos))
        return (self.terminal == other.terminal and infos and np.array_equal(self.obs, other.obs)
                and np.array_equal(self.acts, other.acts))

    __hash__ = None  # type: ignore[assignment]  # mutable arrays inside


def flatten(trajectories: Sequence[Trajectory]) -> tuple[np.ndarray, np.ndarray]:
    """Every trajectory's (observation, action) pairs in order, as two arrays (the last observations dropped)."""
    obs = np.concatenate([np.asarray(t.obs)[:-1] for t in trajectories])
    acts = np.concatenate([np.asarray(t.acts) for t in trajectories])
    return obs, acts


#: The reset seed :func:`rollout` starts from (and :func:`replay` replays from).
RESET_SEED = 0

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
    t = goal_horizon(traj)
    if t == len(traj.acts):
        return traj
    return Trajectory(obs=traj.obs[: t + 1], acts=traj.acts[:t], infos=traj.infos[:t], terminal=True)


def rollout(env: gym.Env, policy: Policy, *, seed: int = RESET_SEED, require_success: bool = False) -> Trajectory:
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


@dataclasses.dataclass(frozen=True)
class Emitted:
    """What an env emitted along a trajectory, one entry per action (``env.step``'s other outputs).

    Attributes:
        rewards: ``(T,)`` float rewards.
        terminations: ``(T,)`` whether the episode ended by itself at that step.
        truncations: ``(T,)`` whether it was cut there (the time limit).
    """

    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray


def replay(env: gym.Env, traj: Trajectory, *, seed: int = RESET_SEED) -> Emitted:
    """Step ``env`` from ``reset(seed=seed)`` through ``traj``'s actions and return what it emitted.

    The demonstrators record trajectories with :func:`rollout` from the same reset seed, so replaying one in
    its goal's env gives back its observations exactly; a mismatch is refused rather than guessed around.

    Raises:
        ValueError: When the env's observations are not the trajectory's, or its episode ends before the
            trajectory's last action.
    """
    obs, _ = env.reset(seed=seed)
    rewards, terminations, truncations = [], [], []
    for t, action in enumerate(traj.acts):
        if not np.array_equal(np.asarray(obs), np.asarray(traj.obs[t])):
            raise ValueError(f"replaying the trajectory gives another observation at step {t}: the env is not "
                             "the one it was recorded in, or not deterministic")
        if t and (terminations[-1] or truncations[-1]):
            raise ValueError(f"the env's episode ended after {t} of the trajectory's {len(traj.acts)} actions")
        obs, reward, terminated, truncated, _ = env.step(action)
        rewards.append(float(reward))
        terminations.append(bool(terminated))
        truncations.append(bool(truncated))
    if not np.array_equal(np.asarray(obs), np.asarray(traj.obs[-1])):
        raise ValueError("replaying the trajectory gives another last observation: the env is not the one it was "
                         "recorded in, or not deterministic")
    return Emitted(np.asarray(rewards, dtype=np.float64), np.asarray(terminations, dtype=bool),
                   np.asarray(truncations, dtype=bool))


def demos_digest(demos: Sequence[Trajectory]) -> str:
    """SHA-256 of the demonstrations' states and actions, in order (keys cached models to what they learnt from)."""
    digest = hashlib.sha256()
    for traj in demos:
        digest.update(np.ascontiguousarray(traj.obs).tobytes())
        digest.update(np.ascontiguousarray(traj.acts).tobytes())
    return digest.hexdigest()
