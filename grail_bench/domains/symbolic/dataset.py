"""Pereira et al.'s goal-recognition dataset format, both ways.

One problem is a ``.tar.bz2`` archive (or a folder) holding ``domain.pddl``,
``template.pddl`` (the problem with ``<HYPOTHESIS>`` in place of the goal),
``hyps.dat`` (one candidate goal per line: comma-separated ground atoms),
``obs.dat`` (one observed ground action per line, ``(action arg1 arg2)``) and
``real_hyp.dat`` (the true goal). :func:`load_problem` reads one into a
:class:`~.problem.GRProblem` and :func:`write_problem` writes one (the
generator's writer); what one writes the other reads back equal.
"""

from __future__ import annotations

import io
import tarfile
from pathlib import Path

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.pddl_text import Atom, atom_text, parse_atoms
from grail_bench.domains.symbolic.problem import GRProblem

FILES = ("domain.pddl", "template.pddl", "hyps.dat", "obs.dat", "real_hyp.dat")
ARCHIVE_SUFFIXES = (".tar.bz2", ".tbz2", ".tar")


def _is_archive(path: Path) -> bool:
    return path.name.endswith(ARCHIVE_SUFFIXES)


def problem_name(path: Path) -> str:
    """The archive's or folder's name without its suffix."""
    name = path.name
    for suffix in ARCHIVE_SUFFIXES:
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def read_files(path: str | Path) -> dict[str, str]:
    """The five files' texts of an archive or folder (members may sit in one subfolder).

    Raises:
        UserError: For a missing path, an unreadable archive or a missing file.
    """
    path = Path(path)
    if not path.exists():
        raise UserError(f"problem {path} does not exist")
    texts: dict[str, str] = {}
    if path.is_dir():
        for name in FILES:
            if (path / name).is_file():
                texts[name] = (path / name).read_text()
    else:
        try:
            with tarfile.open(path) as tar:
                for member in tar.getmembers():
                    base = Path(member.name).name
                    if member.isfile() and base in FILES:
                        texts[base] = tar.extractfile(member).read().decode()  # type: ignore[union-attr]
        except (tarfile.TarError, OSError, EOFError) as err:
            raise UserError(f"problem {path} is not a readable tar archive: {err}") from None
    missing = [name for name in FILES if name not in texts]
    if missing:
        raise UserError(f"problem {path} lacks {', '.join(missing)} (the dataset's layout: {', '.join(FILES)})")
    return texts


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def parse_files(texts: dict[str, str], name: str) -> GRProblem:
    """A :class:`GRProblem` from the five files' texts."""
    hyps = tuple(parse_atoms(line, f"{name}: hyps.dat line {i + 1}")
                 for i, line in enumerate(_lines(texts["hyps.dat"])))
    real = _lines(texts["real_hyp.dat"])
    if len(real) != 1:
        raise UserError(f"{name}: real_hyp.dat must hold one line of atoms, it has {len(real)}")
    obs: list[Atom] = []
    for i, line in enumerate(_lines(texts["obs.dat"])):
        action = parse_atoms(line, f"{name}: obs.dat line {i + 1}")
        if len(action) != 1:
            raise UserError(f"{name}: obs.dat line {i + 1} must hold one action, got {line.strip()!r}")
        obs.append(action[0])
    return GRProblem(name=name, domain_pddl=texts["domain.pddl"], template_pddl=texts["template.pddl"],
                     hypotheses=hyps, real_hyp=parse_atoms(real[0], f"{name}: real_hyp.dat"),
                     observations=tuple(obs))


def load_problem(path: str | Path) -> GRProblem:
    """Read one problem of the dataset (archive or folder).

    Raises:
        UserError: In one line, for a missing file or malformed atoms (PDDL is checked when grounded).
    """
    path = Path(path)
    return parse_files(read_files(path), problem_name(path))


def file_texts(problem: GRProblem) -> dict[str, str]:
    """The five files' texts of a problem."""
    def goal_line(atoms: tuple[Atom, ...]) -> str:
        return ",".join(atom_text(a) for a in atoms)

    return {
        "domain.pddl": problem.domain_pddl,
        "template.pddl": problem.template_pddl,
        "hyps.dat": "".join(goal_line(h) + "\n" for h in problem.hypotheses),
        "obs.dat": "".join(atom_text(a) + "\n" for a in problem.observations),
        "real_hyp.dat": goal_line(problem.real_hyp) + "\n",
    }


def write_problem(problem: GRProblem, path: str | Path) -> Path:
    """Write a problem as a ``.tar.bz2`` archive (files at its root, as the dataset's) or, for any other
    name, as a folder; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    texts = file_texts(problem)
    if _is_archive(path):
        mode = "w:bz2" if path.name.endswith((".tar.bz2", ".tbz2")) else "w"
        with tarfile.open(path, mode) as tar:
            for name in FILES:
                data = texts[name].encode()
                info = tarfile.TarInfo(name)
                info.size, info.mode, info.mtime = len(data), 0o644, 0  # same bytes for the same problem
                tar.addfile(info, io.BytesIO(data))
    else:
        path.mkdir(exist_ok=True)
        for name in FILES:
            (path / name).write_text(texts[name])
    return path
