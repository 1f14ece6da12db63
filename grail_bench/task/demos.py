"""Where a task's demonstrations come from: a Minari dataset, the demonstration cache, or the domain's generator.

* A task whose ``demos`` names a Minari dataset takes them from it
  (:mod:`grail_bench.task.datasets` reads and checks it).
* Otherwise the domain generates them, each goal from its own stream keyed by
  ``(seed, goal)`` (:mod:`grail_bench.core.seeding`), so a goal's
  demonstrations are the same in every task that has it; a domain that sets
  ``cache_demos`` has them kept on disk (:mod:`grail_bench.task.demo_cache`).
* A task with test parameters (a test regime or shifted dynamics, :meth:`GRTask.test_task`) takes its
  training demonstrations from the task without them (the very same ones, from the same cache entries), and
  its test demonstrations from :meth:`GRTask.test_task`, generated from the same stream: the same draws as
  the unshifted task's up to where the shift makes them differ.

The model (:mod:`grail_bench.task.model`) imports nothing above it: importing
this module (which ``import grail_bench.task`` does) installs it as the model's
:class:`~grail_bench.task.model.DemoSource`, so ``task.generate_demos(seed)``
and ``task.with_overrides(demos=...)`` arrive here. Datasets and the cache are
imported on first use: task cards load on ``import gymnasium``.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from grail_bench.core.errors import UserError
from grail_bench.core.seeding import DEMOS, goal_rng
from grail_bench.core.trajectory import Demos, Goal
from grail_bench.task.model import DemoSource, GRTask, TaskFieldError, install_demo_source

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory


def generate_demos(task: GRTask, seed: int, n_demos: int | None = None) -> Demos:
    """``task``'s demonstrations for every goal (see :meth:`GRTask.generate_demos`).

    Raises:
        UserError: When the task's dataset does not fit it, or holds another number of training
            demonstrations per goal than the task splits off.
    """
    if task.demos:
        from grail_bench.task.datasets import load_demos

        loaded = load_demos(task, task.demos, seed)
        if loaded.n_train != task.n_train:
            raise UserError(f"{task.demos}: {loaded.n_train} training demonstrations per goal for seed {seed}, "
                            f"the task expects {task.n_train}")
        return loaded.demos
    n = task.n_demos if n_demos is None else n_demos
    if not task.shifted:
        return {goal: _goal_demos(task, goal, n, seed) for goal in task.goals}
    nominal, shifted = task.nominal(), task.test_task()
    return {goal: _goal_demos(nominal, goal, n, seed)[:task.n_train]
            + _goal_demos(shifted, goal, n, seed, keep_from=task.n_train) for goal in task.goals}


def with_dataset(task: GRTask, source: Any) -> GRTask:
    """``task`` taking its demonstrations from the Minari dataset ``source`` (``""``: from the generator).

    The dataset is read and checked against the task (see :func:`grail_bench.task.datasets.load_demos`);
    its training and test episodes per goal set ``n_train`` and ``n_demos``.

    Raises:
        UserError: For a source that is not a string, or a dataset that does not fit the task.
    """
    if not isinstance(source, str):
        raise UserError(f"{task.id}: demos must name a Minari dataset (a folder or an ID), got {source!r}")
    if not source:
        return dataclasses.replace(task, demos="")
    from grail_bench.task.datasets import load_demos

    loaded = load_demos(task, source, seed=None)
    try:
        return dataclasses.replace(task, demos=source, n_train=loaded.n_train, n_demos=loaded.n_demos)
    except TaskFieldError as exc:
        raise UserError(f"{task.id}: {source}: {exc}") from None


def _goal_demos(task: GRTask, goal: Goal, n: int, seed: int, keep_from: int = 0) -> list[Trajectory]:
    """One goal's demonstrations from its own stream, those from ``keep_from`` on (the test split of a shifted
    task); through the disk cache where the domain asks for it."""
    domain = task.spec

    def generate() -> list[Trajectory]:
        return domain.generate_demos(task, goal, n, goal_rng(seed, goal, DEMOS))[keep_from:]

    if not getattr(domain, "cache_demos", False):
        return generate()
    from grail_bench.task.demo_cache import goal_demos

    return goal_demos(task, domain, goal, n, seed, generate, keep_from)


install_demo_source(DemoSource(generate=generate_demos, with_dataset=with_dataset))
