"""A problem set in the dataset's layout as a task of its own, and its own observations.

A **problem set** is a path: one problem (an archive or a folder holding ``domain.pddl``, ``template.pddl``,
``hyps.dat``, ``obs.dat`` and ``real_hyp.dat``) or a folder of such problems (archives and problem folders, not
searched deeper). Problems that share ``domain.pddl``, ``template.pddl`` and ``hyps.dat`` differ only in their
observations and true goal: they form one task (:func:`problem_set_tasks`), whose candidate goals are *all* the
hypotheses, named ``symbolic:<name>`` after the path (``symbolic:<name>/<group>`` for each group of a folder
whose problems do not all share those files). Its default protocol is ``dataset``: each problem's own
``obs.dat`` scored against its ``real_hyp.dat`` (:func:`dataset_observations`).

Reading is bounded: at most :data:`MAX_PROBLEMS` problems per set (:mod:`grail_bench.core.bounds`), each read by
the bounded reader of :mod:`.dataset`.

A set's task is no gymnasium ID: ``gym.make("symbolic:<name>")`` reads the ID as ``module:env`` and imports a module
``symbolic``, which fails; the env is the task's own, ``task.make_env(goal)``.
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Trajectory
from grail_bench.domains.symbolic.dataset import (ARCHIVE_SUFFIXES, FILES, load_problem, parse_files,
                                                  problem_name, read_files)
from grail_bench.task.model import GRTask
from grail_bench.task.observation import DATASET, project

#: How many problems one set may hold (the published dataset's largest level folder holds a few hundred).
MAX_PROBLEMS = Range(1, 10_000)
#: The files that make problems one task (the others, ``obs.dat`` and ``real_hyp.dat``, are per problem).
SHARED = ("domain.pddl", "template.pddl", "hyps.dat")
PREFIX = "symbolic:"


@dataclass(frozen=True)
class ProblemSetTask(GRTask):
    """A :class:`~grail_bench.task.model.GRTask` made of a problem set.

    Attributes:
        problems: The set's problems (archives or folders, absolute paths), whose ``obs.dat`` and
            ``real_hyp.dat`` the ``dataset`` protocol scores; the env's ``problem`` is the first.
        digest: sha256 of every problem's files (what the results are keyed by, with the recognizer).
    """

    problems: tuple[str, ...] = ()
    digest: str = ""

    __hash__ = GRTask.__hash__


def _is_problem_folder(path: Path) -> bool:
    return path.is_dir() and any((path / name).is_file() for name in FILES)


def problem_paths(path: str | Path) -> list[Path]:
    """The problems a path holds: itself (an archive or a problem folder), or the archives and problem folders
    directly in it, sorted by name.

    Raises:
        UserError: In one line, for a missing path, a folder holding no problem, or more than
            :data:`MAX_PROBLEMS` problems.
    """
    path = Path(path)
    if not path.exists():
        raise UserError(f"problem set {path} does not exist")
    if path.is_file() or _is_problem_folder(path):
        return [path]
    found: list[Path] = []
    with os.scandir(path) as entries:
        for entry in entries:
            child = Path(entry.path)
            if child.name.endswith(ARCHIVE_SUFFIXES) or _is_problem_folder(child):
                found.append(child)
                if not MAX_PROBLEMS.contains(len(found)):
                    raise UserError(f"problem set {path} holds more than {MAX_PROBLEMS.high:,} problems; give "
                                    "a folder of fewer")
    if not found:
        raise UserError(f"problem set {path} holds no problem: expected archives ({', '.join(ARCHIVE_SUFFIXES)}) "
                        f"or folders holding {', '.join(FILES)}")
    return sorted(found, key=lambda p: p.name)


def set_name(path: str | Path) -> str:
    """A problem set's name, from its path: the archive's or folder's name, after its parent folder's when the
    name alone is a number (the dataset's level folders: ``blocks-world/10``)."""
    path = Path(path).resolve()
    name = problem_name(path)
    return f"{path.parent.name}/{name}" if name.isdigit() and path.parent.name else name


def _group_name(names: list[str]) -> str:
    """A group's name: its problems' names without the dataset's ``_hyp-<i>...`` tail (the first, and how many
    other such names the group holds)."""
    stems = list(dict.fromkeys(re.sub(r"_hyp-.*$", "", n) for n in names))
    return stems[0] if len(stems) == 1 else f"{stems[0]}+{len(stems) - 1}"


def problem_set_tasks(path: str | Path, max_steps: int = 50) -> list[GRTask]:
    """The tasks of a problem set (see the module docstring): one per group of problems sharing
    ``domain.pddl``, ``template.pddl`` and ``hyps.dat``, in the order of their first problem.

    Each task's goals are every hypothesis ``[[0], [1], ...]``; its regime ``optimal`` (demonstrations, for the
    other protocols, are optimal plans drawn uniformly); its protocol ``dataset`` at observability 1 (the whole
    of each ``obs.dat``).

    Raises:
        UserError: In one line naming the file, for a missing or malformed problem (see :func:`problem_paths`
            and :func:`~.dataset.read_files`), an ``obs.dat`` action that is no operator of the problem, or a
            ``real_hyp.dat`` that is none of the hypotheses.
    """
    name = set_name(path)
    groups: dict[tuple[str, ...], list[tuple[Path, dict[str, str]]]] = {}
    for problem in problem_paths(path):
        texts = read_files(problem)
        groups.setdefault(tuple(texts[f] for f in SHARED), []).append((problem, texts))
    tasks: list[GRTask] = []
    taken: set[str] = set()
    for members in groups.values():
        names = [problem_name(p) for p, _ in members]
        task_id = base = PREFIX + (name if len(groups) == 1 else f"{name}/{_group_name(names)}")
        for k in range(2, len(groups) + 2):  # names alike but files not: numbered, in order
            if task_id not in taken:
                break
            task_id = f"{base}#{k}"
        taken.add(task_id)
        digest = hashlib.sha256()
        for problem, texts in members:
            parsed = parse_files(texts, problem_name(problem))
            parsed.real_index  # noqa: B018 - refuses a true goal that is no hypothesis, before any work
            for f in FILES:
                digest.update(f"{f}\0{texts[f]}\0".encode())
        first = members[0][1]
        n = len(parse_files(first, names[0]).hypotheses)
        if n < 2:
            raise UserError(f"{members[0][0]}: hyps.dat lists {n} hypothesis; goal recognition needs at least two")
        tasks.append(ProblemSetTask(
            id=task_id, domain="symbolic", regime="optimal", goals=tuple((i,) for i in range(n)),
            env_params={"problem": str(members[0][0].resolve()), "max_steps": max_steps},
            observability=(1.0,), protocol=DATASET,
            description=f"{len(members)} problem(s) of {Path(path)}: {n} hypotheses, each problem's obs.dat",
            source=str(Path(path)), problems=tuple(str(p.resolve()) for p, _ in members),
            digest=digest.hexdigest()))
    return tasks


def dataset_observations(task: Any) -> list[tuple[int, Trajectory]]:
    """Each problem's ``obs.dat`` on the actions channel (states NaN) with the index of its ``real_hyp.dat``
    among the task's goals, in the order of :attr:`ProblemSetTask.problems`.

    Raises:
        UserError: For a task that is no problem set, or an observed action that is no operator of the problem.
    """
    from grail_bench.domains.symbolic.env import load

    problems = getattr(task, "problems", ())
    if not problems:
        raise UserError(f"the {DATASET} protocol scores a problem set's own obs.dat; {task.id} has none: run a "
                        "problem set as its own task (grail-bench run --task PATH)")
    model = load(task.env_params["problem"]).model  # the grounding every goal env of the task shares
    out = []
    for path in problems:
        problem = load_problem(path)  # read only: the shared grounding names its operators
        try:
            acts = np.asarray([model.operator_index(a) for a in problem.observations], dtype=np.int64)
        except UserError as err:
            raise UserError(f"{path}: obs.dat: {err}") from None
        if len(acts) == 0:
            raise UserError(f"{path}: obs.dat lists no observed action")
        states = np.zeros((len(acts) + 1, model.n_fluents), dtype=np.int64)
        observed = project(Trajectory(obs=states, acts=acts, infos=None, terminal=False), "actions")
        out.append((task.goal_index((problem.real_index,)), observed))
    return out
