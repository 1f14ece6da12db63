"""The task layer: GR tasks, their cards and gymnasium registration, and what a recognizer observes.

* :mod:`.model`: :class:`GRTask`, validated on construction.
* :mod:`.domain`: the :class:`Domain` protocol a task needs and the domain registry.
* :mod:`.observation`: observation protocols, :class:`ObservationSpec` and :func:`observe`.
* :mod:`.cards`: the TOML task cards; :mod:`.registration`: gymnasium IDs and :func:`make_task`.

Everything here is light (no torch): it runs on ``import gymnasium``.
"""

from grail_bench.task.model import GRTask, TaskFieldError
from grail_bench.task.registration import (
    find_task,
    make_registered_env,
    make_task,
    register_envs,
    task_ids,
    variant,
)

__all__ = ["GRTask", "TaskFieldError", "find_task", "make_registered_env", "make_task", "register_envs", "task_ids", "variant"]
