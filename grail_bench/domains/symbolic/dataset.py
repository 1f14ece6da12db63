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

import bz2
import gzip
import io
import lzma
import tarfile
import zlib
from pathlib import Path
from typing import Any, BinaryIO

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.pddl_text import Atom, atom_text, parse_atoms
from grail_bench.domains.symbolic.problem import GRProblem

FILES = ("domain.pddl", "template.pddl", "hyps.dat", "obs.dat", "real_hyp.dat")
ARCHIVE_SUFFIXES = (".tar.bz2", ".tbz2", ".tar")
#: Members of one problem archive read at most (the dataset's hold five files, maybe in a folder).
MAX_MEMBERS = 1_000
#: Bytes of one problem's files together at most (the dataset's are kilobytes; a 30x30 grid's are 150 KB).
MAX_BYTES = 64 * 2**20
_OPENERS: dict[bytes, Any] = {b"BZh": bz2.open, b"\x1f\x8b": gzip.open, b"\xfd7zXZ": lzma.open}


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

    Reading is bounded before and while unpacking: at most :data:`MAX_MEMBERS` members, and at most
    :data:`MAX_BYTES` of files together, whether the archive declares more or its stream unpacks to more.

    Raises:
        UserError: In one line naming the file: a missing path, an archive that is not a readable tar archive
            (garbage, truncated, a zip), one past the limits, a missing file or a file that is not UTF-8 text.
    """
    path = Path(path)
    if not path.exists():
        raise UserError(f"problem {path} does not exist")
    if path.is_dir():
        return _checked_texts(path, _folder_files(path))
    try:
        with _decompressed(path) as stream, tarfile.open(fileobj=stream, mode="r|") as tar:
            return _checked_texts(path, _archive_files(path, tar))
    except (tarfile.TarError, OSError, EOFError, lzma.LZMAError, zlib.error) as err:
        raise UserError(f"problem {path} is not a readable tar archive (.tar, .tar.bz2, .tar.gz or .tar.xz): "
                        f"{err or type(err).__name__}") from None


def _folder_files(path: Path) -> dict[str, bytes]:
    found = {name: path / name for name in FILES if (path / name).is_file()}
    total = sum(file.stat().st_size for file in found.values())
    if total > MAX_BYTES:
        raise UserError(f"problem {path}: its files hold {total:,} bytes, more than the {MAX_BYTES:,} a problem "
                        "may")
    return {name: file.read_bytes() for name, file in found.items()}


def _archive_files(path: Path, tar: tarfile.TarFile) -> dict[str, bytes]:
    found: dict[str, bytes] = {}
    total = 0
    for count, member in enumerate(tar, 1):
        total += max(member.size, 0)
        if count > MAX_MEMBERS:
            raise UserError(f"problem {path} holds more than {MAX_MEMBERS:,} members; a problem archive holds "
                            f"{len(FILES)} files")
        if total > MAX_BYTES:
            raise UserError(f"problem {path} unpacks to more than {MAX_BYTES:,} bytes, more than a problem may")
        base = Path(member.name).name
        if member.isfile() and base in FILES:
            found[base] = tar.extractfile(member).read(member.size)  # type: ignore[union-attr]
    return found


def _checked_texts(path: Path, files: dict[str, bytes]) -> dict[str, str]:
    missing = [name for name in FILES if name not in files]
    if missing:
        raise UserError(f"problem {path} lacks {', '.join(missing)} (the dataset's layout: {', '.join(FILES)})")
    texts = {}
    for name, data in files.items():
        try:
            texts[name] = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise UserError(f"problem {path}: {name} is not UTF-8 text (byte {exc.start}); save it as UTF-8 "
                            "(or ASCII, as the dataset's files are)") from None
    return texts


class _Capped(io.RawIOBase):
    """A readable stream that refuses to yield more than ``limit`` bytes (an archive's unpacked size)."""

    def __init__(self, raw: BinaryIO, limit: int, path: Path) -> None:
        super().__init__()
        self._raw, self._left, self._path = raw, limit, path

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        n = self._raw.readinto(buffer)  # type: ignore[attr-defined]
        self._left -= n
        if self._left < 0:
            raise UserError(f"problem {self._path} unpacks to more than {MAX_BYTES:,} bytes, more than a problem "
                            "may")
        return n

    def close(self) -> None:
        self._raw.close()
        super().close()


def _decompressed(path: Path) -> _Capped:
    """The archive's tar stream, unpacked as it is read (by its magic bytes: bzip2, gzip, xz or none) and cut
    off past :data:`MAX_BYTES` plus the tar headers of :data:`MAX_MEMBERS` members."""
    with path.open("rb") as file:
        magic = file.read(6)
    opener = next((o for m, o in _OPENERS.items() if magic.startswith(m)), None)
    raw = opener(path, "rb") if opener is not None else path.open("rb")
    return _Capped(raw, MAX_BYTES + (MAX_MEMBERS + 32) * 1024, path)


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
