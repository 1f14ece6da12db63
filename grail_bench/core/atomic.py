"""Every file grail-bench writes, written whole or not at all.

A file is written under a temporary name in its own folder, flushed to disk,
then moved over its final name with :func:`os.replace` (atomic on one file
system): a reader sees the old file or the new one, never half of one. A
folder (an exported dataset) is written under a temporary name beside it and
renamed when complete. If writing fails, the temporary is removed, so are the
folders the write created, and the error is one line naming the path
(:class:`WriteError`; a full disk reads ``no space left on device writing
<path>``).
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import shutil
from pathlib import Path
from typing import Callable, Iterator, Mapping, Union

from grail_bench.core.errors import UserError

__all__ = ["WriteError", "replace_folder", "temporary_folder", "write_bytes", "write_error", "write_files",
           "write_text", "write_with"]


class WriteError(UserError):
    """An output could not be written (nothing half-written was left)."""


def write_error(exc: OSError, path: str | Path) -> WriteError:
    """One line for an ``OSError`` raised writing ``path``."""
    if exc.errno == errno.ENOSPC:
        return WriteError(f"no space left on device writing {path}")
    if exc.errno == errno.EDQUOT:
        return WriteError(f"disk quota exceeded writing {path}")
    return WriteError(f"cannot write {path}: {exc.strerror or exc}")


def _missing_parents(folder: Path) -> list[Path]:
    """The folders above (and including) ``folder`` that do not exist yet, outermost first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing[::-1]


def _remove_created(folders: list[Path]) -> None:
    """Remove the folders a failed write created (innermost first), if they are still empty."""
    for folder in reversed(folders):
        with contextlib.suppress(OSError):
            folder.rmdir()


def _flush(path: Path) -> None:
    """Push a written file's bytes to the disk, so a full disk fails here rather than after the rename."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _temporary(path: Path) -> Path:
    """A new empty file beside ``path`` under a hidden temporary name (permissions as for any new file)."""
    while True:
        tmp = path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp"
        try:
            os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
            return tmp
        except FileExistsError:
            continue


Content = Union[bytes, str, Callable[[Path], None]]


def write_files(files: Mapping[str | Path, Content]) -> list[Path]:
    """Write several files as one: each to a temporary name beside it and flushed, then all moved into place.

    A content is bytes, text (UTF-8) or ``write(tmp)``, which fills the
    temporary file (``savefig``, ``torch.save``, ...). The folders are created
    if missing. If any write fails, no file is replaced: every temporary and
    every folder created is removed.

    Returns:
        The paths, in order.

    Raises:
        WriteError: Naming the path whose write failed; every earlier file at these paths is as it was.
    """
    paths = [Path(p) for p in files]
    created = list(dict.fromkeys(f for p in paths for f in _missing_parents(p.parent)))
    staged: list[tuple[Path, Path]] = []
    current: Path | None = paths[0] if paths else None
    done = False
    try:
        for path, content in zip(paths, files.values()):
            current = path
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = _temporary(path)
            staged.append((tmp, path))
            if callable(content):
                content(tmp)
            else:
                tmp.write_bytes(content.encode("utf-8") if isinstance(content, str) else content)
            _flush(tmp)
        for tmp, path in staged:
            current = path
            os.replace(tmp, path)
        done = True
    except OSError as exc:
        raise write_error(exc, current) from None
    finally:
        if not done:
            for tmp, _ in staged:
                with contextlib.suppress(OSError):
                    tmp.unlink()
            _remove_created(created)
    return paths


def write_with(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Write ``path`` atomically: ``write(tmp)`` fills a temporary file beside it, which then replaces ``path``
    (:func:`write_files`; ``write`` may raise :class:`UserError`, passed on, or ``OSError``, made one line).

    Raises:
        WriteError: Naming ``path``; the previous file at ``path``, if any, is left as it was.
    """
    return write_files({path: write})[0]


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`write_files`)."""
    return write_files({path: data})[0]


def write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (:func:`write_files`)."""
    return write_files({path: text})[0]


@contextlib.contextmanager
def temporary_folder(final: str | Path) -> Iterator[Path]:
    """A temporary folder beside ``final`` (its parent created if missing), removed with everything in it when
    the block ends, however it ends; move its contents into place with :func:`replace_folder` inside the block.

    Raises:
        WriteError: For an ``OSError`` in the block, naming ``final``.
    """
    final = Path(final)
    created = _missing_parents(final.parent)
    tmp: Path | None = None
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        while tmp is None:
            candidate = final.parent / f".{final.name}.{secrets.token_hex(4)}.tmp"
            with contextlib.suppress(FileExistsError):
                candidate.mkdir()  # permissions as for any new folder (the dataset keeps them)
                tmp = candidate
        yield tmp
    except OSError as exc:
        raise write_error(exc, final) from None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        if not final.exists():
            _remove_created(created)


def replace_folder(tmp: Path, final: str | Path) -> Path:
    """Move the complete folder (or file) ``tmp`` to ``final`` (which must not exist, or be an empty folder)."""
    final = Path(final)
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp, final)
    except OSError as exc:
        raise write_error(exc, final) from None
    return final
