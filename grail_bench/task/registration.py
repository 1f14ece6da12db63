"""The one place that registers GRAIL/ tasks with gymnasium, and looks them up by ID.

Registration runs on ``import gymnasium`` (through the ``gymnasium.envs``
entry-point group) and on ``import grail_bench``; both paths are idempotent
and import nothing heavier than the task cards.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from grail_bench.core.errors import UserError
from grail_bench.task.cards import load_cards
from grail_bench.task.domain import stored_params
from grail_bench.task.model import ENV_ONLY, GRTask

if TYPE_CHECKING:
    import gymnasium as gym

ENTRY_POINT = "grail_bench.task.registration:make_registered_env"


def shipped_tasks() -> dict[str, GRTask]:
    """Every task of the shipped cards, by ID (parsed once per process)."""
    return {task.id: task for task in load_cards()}


def register_envs() -> list[GRTask]:
    """Register every task card's ID with gymnasium (skipping existing ones).

    Returns:
        The tasks, registered or already present.
    """
    # Imported here: gymnasium's plugin loader imports this module while
    # gymnasium itself is initialising, and `import grail_bench` imports
    # gymnasium through this function.
    from gymnasium.envs.registration import register, registry

    tasks = load_cards()
    for task in tasks:
        if task.id not in registry:
            register(id=task.id, entry_point=ENTRY_POINT, kwargs={"task_id": task.id})
    return tasks


def task_ids() -> list[str]:
    """IDs of all registered GRAIL/ tasks, sorted."""
    from gymnasium.envs.registration import registry

    register_envs()
    return sorted(env_id for env_id in registry if env_id.startswith("GRAIL/"))


def make_registered_env(task_id: str, **kwargs: Any) -> gym.Env:
    """Gymnasium entry point of every ``GRAIL/`` ID.

    ``render_mode`` and ``goal`` shape the env; every other keyword overrides a task parameter.
    """
    env_only = {k: kwargs.pop(k) for k in ENV_ONLY if k in kwargs}
    task = shipped_tasks()[task_id].with_overrides(**kwargs)
    return task.make_env(env_only.pop("goal", None), **env_only)


def make_task(task_id: str, **overrides: Any) -> GRTask:
    """Return the :class:`GRTask` of a registered ID without building an env.

    Args:
        task_id: A ``GRAIL/`` gymnasium ID.
        **overrides: Regime or env parameters, ``n_demos`` or ``n_train``.

    Raises:
        gymnasium.error.Error: For unknown IDs (gymnasium's own message).
        UserError: For a gymnasium ID that is not a GRAIL/ task, or an override it cannot apply.
    """
    from gymnasium.envs.registration import spec as gym_spec

    tasks = shipped_tasks()
    env_spec = gym_spec(task_id)
    if env_spec.entry_point != ENTRY_POINT or task_id not in tasks:
        raise UserError(f"{task_id} is a gymnasium env but not a GRAIL/ task")
    return tasks[task_id].with_overrides(**overrides)


def find_task(task_id: str, params: dict[str, Any] | None = None) -> GRTask | None:
    """The registered task with the parameters a stored run used (parameters added since the run filled in as
    its domain declares, see :func:`~grail_bench.task.domain.stored_params`), or None when its card is gone (or
    no longer accepts those parameters): reports of old stores show such rows without the task's details."""
    from gymnasium.error import Error as GymError

    try:
        task = make_task(task_id)
        if params is None:
            return task
        return task.with_overrides(**{k: v for k, v in stored_params(task.spec, params).items()
                                      if k in task.params or k in task.env_params or k in ("n_demos", "n_train")})
    except (GymError, UserError):
        return None


def variant(task: GRTask, params: dict[str, Any]) -> str:
    """How a stored run's parameters differ from the task's defaults, e.g. ``route_choice="uniform"`` (empty when
    they do not)."""
    run = find_task(task.id, params)
    if run is None:
        return ""
    mine = {**run.params, **run.env_params, "n_demos": run.n_demos, "n_train": run.n_train}
    defaults = {**task.params, **task.env_params, "n_demos": task.n_demos, "n_train": task.n_train}
    return " ".join(f"{k}={json.dumps(v)}" for k, v in sorted(mine.items()) if defaults.get(k) != v)
