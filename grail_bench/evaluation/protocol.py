"""What a recognizer observes: observability levels, prefixes and random subsets."""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np
from imitation.data.types import Trajectory

SAMPLINGS = ("prefix", "random")


def parse_observability(values: Iterable[float] | str) -> tuple[float, ...]:
    """Validate observability fractions (accepts ``"0.1,0.2"``).

    Raises:
        ValueError: Unless every value is a number in (0, 1].
    """
    items = values.split(",") if isinstance(values, str) else list(values)
    out = []
    for item in items:
        try:
            p = float(item)
        except (TypeError, ValueError):
            raise ValueError(f"observability {item!r} is not a number") from None
        if not 0.0 < p <= 1.0 or math.isnan(p):
            raise ValueError(f"observability {p:g} must be a fraction in (0, 1]")
        out.append(round(p, 6))
    if not out:
        raise ValueError("at least one observability level is needed")
    return tuple(dict.fromkeys(out))


def goal_horizon(traj: Trajectory) -> int:
    """Number of actions up to and including the one that reached the goal.

    Uses ``info["is_success"]``; a demonstration without it counts in full.
    """
    if traj.infos is not None:
        for t, info in enumerate(traj.infos):
            if info.get("is_success"):
                return t + 1
    return len(traj.acts)


def observe(traj: Trajectory, fraction: float, sampling: str = "prefix",
            rng: np.random.Generator | None = None) -> Trajectory:
    """The part of a test demonstration a recognizer gets to see.

    ``k = max(1, ceil(fraction * T))`` state-action pairs, where ``T`` is
    :func:`goal_horizon`: the first ``k`` (``"prefix"``) or ``k`` drawn
    without replacement and kept in order (``"random"``). Infos are dropped,
    so nothing about the goal leaks.

    Returns:
        A trajectory with ``k`` actions and ``k + 1`` states; ``acts[i]`` was
        taken in ``obs[i]`` (for random subsets ``obs[k]`` follows the last pair).
    """
    if sampling not in SAMPLINGS:
        raise ValueError(f"unknown sampling {sampling!r}; choose one of {', '.join(SAMPLINGS)}")
    horizon = goal_horizon(traj)
    k = max(1, math.ceil(round(fraction * horizon, 9)))
    if sampling == "prefix":
        idx = np.arange(k)
    else:
        if rng is None:
            raise ValueError("random sampling needs an rng")
        idx = np.sort(rng.choice(horizon, size=k, replace=False))
    states = np.concatenate([traj.obs[idx], traj.obs[idx[-1] + 1][None]])
    return Trajectory(obs=states, acts=traj.acts[idx], infos=None, terminal=False)


def seed_list(seeds: int | Sequence[int]) -> list[int]:
    """``n`` means seeds ``0..n-1``; a sequence is used as given."""
    if isinstance(seeds, int):
        if seeds < 1:
            raise ValueError(f"need at least one seed, got {seeds}")
        return list(range(seeds))
    out = [int(s) for s in seeds]
    if not out:
        raise ValueError("need at least one seed")
    return out
