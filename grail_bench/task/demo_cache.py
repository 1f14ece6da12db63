"""Demonstrations kept on disk, for domains whose demonstrators are slow to run.

A PandaReach seed is 800 rollouts of a SAC expert in pybullet (70-140 s), and
every process of a parallel sweep that runs a unit of the task needed them
again. A domain that sets ``cache_demos = True`` has each goal's
demonstrations generated once per regime, parameters, seed and count, and read
back from grail-bench's cache (:mod:`grail_bench.core.cache`: ``.npz`` with a
checksummed sidecar, never unpickled; a second process waits for the first; an
entry whose arrays do not fit together is regenerated, see :func:`check`).
The key also holds a digest of the domain's source and of the rollout and
expert code, so editing a demonstrator regenerates its demonstrations.
Trajectories come back identical: the same arrays, and infos holding
``is_success`` only (a domain whose infos say more cannot opt in).
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from importlib.util import find_spec
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from grail_bench.core.cache import cached
from grail_bench.core.errors import UserError
from grail_bench.core.provenance import package_versions
from grail_bench.core.trajectory import Goal

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

    from grail_bench.task.domain import Domain, TaskView

KIND = "demos"
#: Packages whose versions key the entries: the numerics, the learners and the simulators (and a domain's own
#: ``packages``).
_PACKAGES = ("numpy", "torch", "stable-baselines3", "gymnasium", "panda-gym", "pybullet", "mujoco",
             "gymnasium-robotics")
#: Core modules every demonstrator runs through (rollouts, seeded streams, RL experts' actors).
_CORE = ("grail_bench.core.trajectory", "grail_bench.core.seeding", "grail_bench.core.experts")


@lru_cache(maxsize=None)
def source_digest(domain_module: str) -> str:
    """SHA-256 of the Python files beside the domain's module and of the core modules demonstrators run through
    (found, not imported)."""
    folder = Path(find_spec(domain_module).origin).parent
    files = sorted(folder.glob("*.py")) + [Path(find_spec(name).origin) for name in _CORE]
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.read_bytes())
    return digest.hexdigest()[:20]


def goal_demos(task: TaskView, domain: Domain, goal: Goal, n: int, seed: int,
               generate: Callable[[], list[Trajectory]], keep_from: int = 0) -> list[Trajectory]:
    """``generate()``'s demonstrations of ``goal``, from the cache where they were generated before.

    Args:
        task: The task (its regime, parameters and env parameters key the entry, and its test parameters
            when it has any: the test split of a shifted task, see :mod:`grail_bench.task.demos`).
        domain: The task's domain.
        goal: The goal.
        n: Demonstrations of the goal.
        seed: The task's demonstration seed.
        generate: Generates them (the domain's ``generate_demos`` on the goal's own stream), those from
            ``keep_from`` on.
        keep_from: How many of the ``n`` ``generate`` leaves out (0: all of them are kept).
    """
    key = {"domain": domain.name, "regime": task.regime, "params": dict(task.params),
           "env": dict(task.env_params), "goal": list(goal), "seed": seed, "n": n,
           "source": source_digest(type(domain).__module__),
           "versions": package_versions(_PACKAGES + tuple(getattr(domain, "packages", ())))}
    shift = dict(getattr(task, "test_params", None) or {})
    if shift or keep_from:  # unshifted entries keep their keys
        key |= {"test": shift, "from": keep_from}
    entry = cached(KIND, key, lambda: pack(generate(), domain.name), arrays=True,
                   check=lambda a: check(a, n - keep_from))
    return unpack(entry.state)


def check(arrays: dict[str, np.ndarray], n: int | None = None) -> None:
    """Refuse arrays :func:`pack` did not write (of ``n`` demonstrations, if given).

    Raises:
        ValueError: Naming what is wrong (the cache then regenerates the entry).
    """
    if set(arrays) != {"obs", "acts", "lengths", "success"}:
        raise ValueError(f"it holds {sorted(arrays)}, not obs, acts, lengths and success")
    lengths, acts, obs, success = arrays["lengths"], arrays["acts"], arrays["obs"], arrays["success"]
    if lengths.ndim != 1 or lengths.dtype.kind not in "iu" or (n is not None and len(lengths) != n):
        raise ValueError(f"its lengths have shape {lengths.shape} and type {lengths.dtype}, not {n} counts")
    if (lengths < 0).any():
        raise ValueError("it holds a negative length")
    steps = int(lengths.sum())
    if obs.ndim < 1 or len(obs) != steps + len(lengths) or len(acts) != steps or success.shape != (steps,):
        raise ValueError(f"its arrays ({len(obs)} observations, {len(acts)} actions, {len(success)} flags) do "
                         f"not match its lengths ({steps} steps in {len(lengths)} demonstrations)")
    for name in ("obs", "acts"):
        if arrays[name].dtype.kind not in "iufb" or (arrays[name].dtype.kind == "f"
                                                     and not np.isfinite(arrays[name]).all()):
            raise ValueError(f"its {name} are not finite numbers")
    if success.dtype.kind != "b":
        raise ValueError("its success flags are not booleans")


def pack(demos: Sequence[Trajectory], domain: str = "the domain") -> dict[str, np.ndarray]:
    """Trajectories as named arrays: observations and actions end to end, lengths and success flags.

    Raises:
        UserError: When an info holds more than ``is_success`` (it could not come back as it was).
    """
    for traj in demos:
        if traj.infos is None or any(set(info) != {"is_success"} for info in traj.infos) or not traj.terminal:
            raise UserError(f"{domain} caches its demonstrations (cache_demos), but they carry infos other than "
                            "is_success or end unterminated; they would not come back as they were")
    return {"obs": np.concatenate([t.obs for t in demos]), "acts": np.concatenate([t.acts for t in demos]),
            "lengths": np.array([len(t.acts) for t in demos], dtype=np.int64),
            "success": np.array([bool(i["is_success"]) for t in demos for i in t.infos], dtype=bool)}


def unpack(arrays: dict[str, np.ndarray]) -> list[Trajectory]:
    """The trajectories :func:`pack` packed."""
    from grail_bench.core.trajectory import Trajectory

    out, obs_at, act_at = [], 0, 0
    for length in arrays["lengths"].tolist():
        infos = np.array([{"is_success": bool(s)} for s in arrays["success"][act_at:act_at + length]], dtype=object)
        out.append(Trajectory(obs=arrays["obs"][obs_at:obs_at + length + 1], acts=arrays["acts"][act_at:act_at + length],
                              infos=infos, terminal=True))
        obs_at, act_at = obs_at + length + 1, act_at + length
    return out
