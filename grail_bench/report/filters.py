"""What the reading commands (``leaderboard``, ``tasks``, ``list``) narrow to: tasks by ID or glob, domains, methods.

* ``--task``: full IDs or shell globs over them (``'GRAIL/MiniGrid-*'``); a pattern without the ``GRAIL/`` prefix
  also matches the IDs it names once the prefix is added (``MiniGrid-*``).
* ``--domain``: a domain as cards name it (``point_maze``) or as task IDs begin (``PointMaze``), any case.
* ``--method``: a recognizer's registered name (``bc``), its published name (``BC-GRAIL``), or
  ``recognizer/scorer`` (``bc/mse``); globs too, any case.

A row, task or recognizer passes when it matches one value of every filter given. Apart from these, the leaderboard
leaves out the rows of tasks under test-time shifts (:func:`shifted`; docs/concepts/shifts.md) unless asked: they
share their base task's ID, and ``reproduce --profile open-questions`` reports them (SHIFTS.md, REGIMES.md).
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

from grail_bench.core.errors import UserError
from grail_bench.harness.planning import shift_params
from grail_bench.report.boards import domain_of
from grail_bench.report.configs import method_of
from grail_bench.task import find_task

PREFIX = "GRAIL/"


def _norm(name: str) -> str:
    return name.lower().replace("_", "").replace("-", "")


@lru_cache(maxsize=None)
def task_domain(task_id: str) -> str:
    """The domain of a task: its card's, or (a task no longer shipped) the first word of its ID."""
    task = find_task(task_id)
    return task.domain if task is not None else domain_of(task_id)


@lru_cache(maxsize=None)
def _shifted(config_json: str) -> bool:
    return bool(shift_params(config_json))


def shifted(row: object) -> bool:
    """Whether a stored row is of a task under test-time shifts: its configuration sets test parameters
    (``test_slip``, ``test_regime``...), which only a shifted task's does (read once per configuration)."""
    return _shifted(row.config)  # type: ignore[attr-defined]


@dataclass(frozen=True)
class Filters:
    """The values of ``--task``, ``--domain`` and ``--method`` (empty: no filter)."""

    tasks: tuple[str, ...] = ()
    domains: tuple[str, ...] = ()
    methods: tuple[str, ...] = ()

    @classmethod
    def of(cls, tasks: Sequence[str] | None = None, domains: Sequence[str] | None = None,
           methods: Sequence[str] | None = None) -> Filters:
        """Filters from the options' values (None: not given)."""
        return cls(tuple(tasks or ()), tuple(domains or ()), tuple(methods or ()))

    def __bool__(self) -> bool:
        return bool(self.tasks or self.domains or self.methods)

    def task(self, task_id: str) -> bool:
        """Whether a task passes ``--task`` and ``--domain``."""
        if self.tasks and not any(fnmatch.fnmatchcase(task_id, p) or
                                  (not p.startswith(PREFIX) and fnmatch.fnmatchcase(task_id, PREFIX + p))
                                  for p in self.tasks):
            return False
        if self.domains:
            names = {_norm(task_domain(task_id)), _norm(domain_of(task_id))}
            return any(_norm(d) in names for d in self.domains)
        return True

    def method(self, recognizer: str, scorer: str | None = None) -> bool:
        """Whether a recognizer (with a scorer, a row's) passes ``--method``."""
        if not self.methods:
            return True
        names = [recognizer, method_of(recognizer)[0]] + ([f"{recognizer}/{scorer}"] if scorer else [])
        return any(fnmatch.fnmatchcase(n.lower(), m.lower()) for m in self.methods for n in names)

    def row(self, row: object) -> bool:
        """Whether a stored row passes every filter."""
        return self.task(row.task) and self.method(row.recognizer, getattr(row, "scorer", None))  # type: ignore[attr-defined]

    def check_tasks(self, known: Sequence[str]) -> None:
        """Refuse a ``--task`` or ``--domain`` value that matches none of ``known`` (so a typo is not an empty
        board).

        Raises:
            UserError: In one line, naming the value and how task IDs look.
        """
        for p in self.tasks:
            if not any(Filters(tasks=(p,)).task(t) for t in known):
                raise UserError(f"--task {p!r} matches no task here; give full IDs or globs, e.g. "
                                f"'GRAIL/MiniGrid-*' (`grail-bench tasks` lists them)")
        for d in self.domains:
            if not any(Filters(domains=(d,)).task(t) for t in known):
                domains = sorted({task_domain(t) for t in known})
                raise UserError(f"--domain {d!r} matches no task here (domains: {', '.join(domains) or 'none'})")
