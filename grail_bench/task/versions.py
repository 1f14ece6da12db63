"""Task versions that mean one thing: each task's fingerprint, the shipped table of what each ID means, and how
rows stored before an ID's meaning moved are read.

A task's **fingerprint** (:func:`fingerprint`) is a short sha256 of the canonical JSON (sorted keys, no spaces) of
what defines it: its card entry (domain, regime, goals, observability levels, protocol, rounding, demonstration
counts and dataset), every regime and env parameter (defaults merged in), the test parameters that shift
its test demonstrations (only when it has any) and the version of its domain's
demonstration generator (a domain's ``generator_version``, 1 when it declares none; a domain bumps it when its
demonstrations change for the same parameters). A file's absolute path (a dataset's, a symbolic problem's) counts
by its name, so that a task fingerprints the same on every machine. The ID and the description are names, not
definitions.

``tasks/versions.toml`` (shipped beside the cards) records, per shipped ID, the fingerprint that ID means
(``[fingerprints]``); a test fails when a card's task no longer has its recorded fingerprint, so that a change
of meaning comes with a new version suffix, as Gymnasium's IDs do (``-v0`` to ``-v1``).

Its ``[[moved]]`` entries say how rows stored under an old version are read after its meaning moved to a new
one: a row stored under ``from`` whose recorded regime parameters (those it predates filled in as its domain
declares, :func:`~grail_bench.task.domain.stored_params`) match every value of ``when`` was run with the new
version's definition and is read as ``to`` (:func:`resolve_id`); the others stay under ``from``, the old
meaning, which stays makeable. The published store is never rewritten: rows are resolved as they are read.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import dataclass
from functools import lru_cache
from importlib.resources import files
from pathlib import Path
from typing import Any, Iterable, Mapping

from grail_bench.task.cards import VERSIONS_FILE
from grail_bench.task.domain import stored_params
from grail_bench.task.model import GRTask
from grail_bench.task.registration import shipped_tasks

#: Characters of the sha256 hex digest a fingerprint keeps.
LENGTH = 12


def definition(task: GRTask) -> dict[str, Any]:
    """What defines ``task`` (the fingerprint's input): every field but its ID, description and card file."""
    return {
        "domain": task.domain, "regime": task.regime, "goals": [list(g) for g in task.goals],
        "params": dict(task.params), "env": _env(task), "n_demos": task.n_demos,
        "n_train": task.n_train, "observability": list(task.observability), "protocol": task.protocol,
        "rounding": task.rounding, "demos": Path(task.demos).name if task.demos else "",
        "generator": int(getattr(task.spec, "generator_version", 1)),
    } | ({"test": dict(task.test_params)} if task.test_params else {})  # unshifted tasks keep their fingerprints


def _env(task: GRTask) -> dict[str, Any]:
    """The task's env parameters, a file's absolute path (a domain's ``path_params``) by its name only."""
    names = set(getattr(task.spec, "path_params", ()))
    return {k: Path(v).name if k in names and isinstance(v, str) and Path(v).is_absolute() else v
            for k, v in task.env_params.items()}


def fingerprint(task: GRTask) -> str:
    """Short sha256 of the canonical JSON of :func:`definition` (the same on every machine and run)."""
    text = json.dumps(definition(task), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:LENGTH]


@dataclass(frozen=True)
class Moved:
    """Rows stored under ``source`` whose regime parameters match ``when`` are read as ``target``."""

    source: str
    target: str
    when: Mapping[str, Any]
    since: str = ""


@dataclass(frozen=True)
class VersionTable:
    """The shipped ``tasks/versions.toml``: per ID the fingerprint it means, and the moved meanings."""

    fingerprints: Mapping[str, str]
    moved: tuple[Moved, ...]

    def sources(self) -> dict[str, list[Moved]]:
        """The moved entries by the ID rows were stored under."""
        out: dict[str, list[Moved]] = {}
        for m in self.moved:
            out.setdefault(m.source, []).append(m)
        return out


def parse_table(text: str) -> VersionTable:
    """Parse the text of a versions table (see the module docstring)."""
    data = tomllib.loads(text)
    moved = tuple(Moved(m["from"], m["to"], dict(m.get("when", {})), str(m.get("since", "")))
                  for m in data.get("moved", []))
    return VersionTable(dict(data.get("fingerprints", {})), moved)


@lru_cache(maxsize=1)
def shipped_table() -> VersionTable:
    """The shipped table (read once per process)."""
    return parse_table(files("grail_bench.tasks").joinpath(VERSIONS_FILE).read_text(encoding="utf-8"))


def resolve_id(task_id: str, params: Mapping[str, Any] | None, table: VersionTable | None = None) -> str:
    """The version a stored row's task really is: ``task_id`` unless a ``[[moved]]`` entry says its recorded
    regime parameters (``params``, as the row's config records them) are the newer version's."""
    moves = (table or shipped_table()).sources().get(task_id)
    if not moves or params is None:
        return task_id
    task = shipped_tasks().get(task_id)
    recorded = stored_params(task.spec, params) if task is not None else dict(params)
    for m in moves:
        if all(k in recorded and _same(recorded[k], v) for k, v in m.when.items()):
            return m.target
    return task_id


def aliases(task_ids: Iterable[str], table: VersionTable | None = None) -> set[str]:
    """The IDs rows of ``task_ids`` may be stored under: each ID and those moved to it."""
    wanted = set(task_ids)
    return wanted | {m.source for m in (table or shipped_table()).moved if m.target in wanted}


def changed(tasks: Iterable[GRTask], table: VersionTable | None = None) -> list[str]:
    """One line per task whose fingerprint is not the one its ID's version is recorded to mean (or none is)."""
    recorded = (table or shipped_table()).fingerprints
    out = []
    for task in tasks:
        now, then = fingerprint(task), recorded.get(task.id)
        if then is None:
            out.append(f"{task.id} has no recorded fingerprint: record {task.id} = {now!r} in tasks/{VERSIONS_FILE}")
        elif now != then:
            out.append(f"{task.id}'s definition changed (fingerprint {then} -> {now}) but its version did not: "
                       f"bump the ID's version (keep the old one makeable with its old parameters if rows were "
                       f"stored under it, with a [[moved]] entry), and record the new ID = {now!r} in "
                       f"tasks/{VERSIONS_FILE}")
    return out


def table_text(tasks: Iterable[GRTask]) -> str:
    """The ``[fingerprints]`` section for ``tasks`` (to paste into ``tasks/versions.toml`` after a bump)."""
    return "[fingerprints]\n" + "".join(f'"{t.id}" = "{fingerprint(t)}"\n' for t in sorted(tasks, key=lambda t: t.id))


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return float(a) == float(b)
    return a == b


if __name__ == "__main__":  # print the current table: python -m grail_bench.task.versions
    print(table_text(shipped_tasks().values()), end="")
