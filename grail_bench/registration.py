"""The one place that registers GRAIL/ tasks with gymnasium.

It runs on ``import gymnasium`` (through the ``gymnasium.envs`` entry-point
group) and on ``import grail_bench``; both paths are idempotent and import
nothing heavier than the task cards.
"""

from __future__ import annotations

from grail_bench.cards import TaskCard, load_cards

ENTRY_POINT = "grail_bench.task:make_registered_env"


def register_envs() -> list[TaskCard]:
    """Register every task card's ID with gymnasium (skipping existing ones).

    Returns:
        The cards, registered or already present.
    """
    # Imported here: gymnasium's plugin loader imports this module while
    # gymnasium itself is initialising, and `import grail_bench` imports
    # gymnasium through this function.
    from gymnasium.envs.registration import register, registry

    cards = load_cards()
    for card in cards:
        if card.id not in registry:
            register(id=card.id, entry_point=ENTRY_POINT, kwargs=card.kwargs())
    return cards


def task_ids() -> list[str]:
    """IDs of all registered GRAIL/ tasks, sorted."""
    from gymnasium.envs.registration import registry

    register_envs()
    return sorted(env_id for env_id in registry if env_id.startswith("GRAIL/"))
