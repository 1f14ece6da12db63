"""The task layer: GR tasks, their cards and gymnasium registration, and what a recognizer observes.

* :mod:`.model`: :class:`GRTask`, validated on construction.
* :mod:`.domain`: the :class:`Domain` protocol a task needs and the domain registry.
* :mod:`.observation`: observation protocols, :class:`ObservationSpec` and :func:`observe`.
* :mod:`.overrides`: :class:`TaskOverrides`, a task's parameters set over its card.
* :mod:`.cards`: the TOML task cards; :mod:`.sources`: where cards from outside the package are found (paths,
  ``GRAIL_BENCH_CARDS``, entry points); :mod:`.external`: their tasks, registered (:func:`load_cards`,
  :func:`add_tasks`); :mod:`.registration`: gymnasium IDs and :func:`make_task`.
* :mod:`.demos`: where demonstrations come from (the generator, :mod:`.demo_cache`, or a Minari dataset read
  by :mod:`.datasets`); :mod:`.export`: demonstrations written as Minari datasets.
* :mod:`.versions`: each task's fingerprint, what each ID's version means, and how rows stored under an old
  version are read.

The modules form layers, each importing only those below it (``lint-imports`` checks the contract in
``pyproject.toml``): export, versions; registration, demos; external; sources; cards, datasets, demo_cache; model; domain, observation,
overrides. The model reaches demonstrations through the source :mod:`.demos` installs, which importing this
package does. Everything here is light (no torch): it runs on ``import gymnasium``.
"""

import grail_bench.task.demos  # noqa: F401 - installs the model's demonstration source
from grail_bench.task.model import GRTask, TaskFieldError
from grail_bench.task.external import add_tasks, load_cards, register_card
from grail_bench.task.registration import (
    find_task,
    make_registered_env,
    make_task,
    register_envs,
    task_ids,
    variant,
)

__all__ = ["GRTask", "TaskFieldError", "add_tasks", "find_task", "load_cards", "make_registered_env", "make_task",
           "register_card", "register_envs", "task_ids", "variant"]
