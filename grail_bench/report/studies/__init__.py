"""Studies: analyses behind the leaderboard's README that print one Markdown table (``grail-bench study NAME``).

Each study is a module with a ``run`` function taking keyword arguments (a
study that reads results takes ``store``, an open
:class:`~grail_bench.harness.store.ResultsStore`) and returning Markdown.
:data:`STUDIES` names them; a module is imported only when its study runs.
"""

from __future__ import annotations

import importlib
import inspect
from typing import Callable, Sequence

from grail_bench.core.errors import UserError

#: name -> (module, one-line description).
STUDIES: dict[str, tuple[str, str]] = {
    "causes": ("grail_bench.report.studies.causes",
               "Each MiniGrid cell significantly below the paper, with the evidence its store holds (no training)."),
    "off-route": ("grail_bench.report.studies.off_route",
                  "F1 of hand-built per-goal policies that differ only off their goal's route (no training)."),
    "readings": ("grail_bench.report.studies.readings",
                 "Pairs-only ceilings of each MiniGrid route reading and rounding against the paper's cells."),
}


def check_tasks(study: str, tasks: Sequence[str], known: Sequence[str]) -> None:
    """Refuse a task a study does not cover.

    Raises:
        UserError: Naming the first such task and the ones the study covers.
    """
    unknown = [t for t in tasks if t not in known]
    if unknown:
        raise UserError(f"study {study} covers the paper's optimal and suboptimal MiniGrid tasks "
                        f"({', '.join(known)}), not {unknown[0]!r}")


def get_study(name: str) -> Callable[..., str]:
    """The ``run`` function of a study.

    Raises:
        UserError: For an unknown name.
    """
    if name not in STUDIES:
        raise UserError(f"unknown study {name!r}; choose one of {', '.join(STUDIES)} (`grail-bench study --list`)")
    return importlib.import_module(STUDIES[name][0]).run


def study_options(name: str) -> dict[str, bool]:
    """The keyword arguments a study takes, each with whether it is required.

    Raises:
        UserError: For an unknown name.
    """
    params = inspect.signature(get_study(name)).parameters.values()
    return {p.name: p.default is inspect.Parameter.empty for p in params}

