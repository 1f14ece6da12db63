"""The one place that registers GRAIL/ tasks with gymnasium.

It runs on ``import gymnasium`` (through the ``gymnasium.envs`` entry-point
group) and on ``import grail_bench``; both paths are idempotent and import
nothing heavier than the task cards.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from grail_bench.cards import load_cards

if TYPE_CHECKING:
    from grail_bench.task import GRTask

ENTRY_POINT = "grail_bench.task:make_registered_env"


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
