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
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator

from grail_bench.core.errors import UserError

__all__ = ["WriteError", "replace_folder", "temporary_folder", "write_bytes", "write_json", "write_text",
           "write_with", "write_error"]


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


def write_with(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Write ``path`` atomically: ``write(tmp)`` fills a temporary file beside it, which then replaces ``path``.

    The folder holding ``path`` is created if missing (and removed again if
    the write fails). ``write`` may raise :class:`UserError` (passed on) or
    ``OSError`` (turned into one line).

    Returns:
        ``path``.

    Raises:
        WriteError: Naming ``path``; the previous file at ``path``, if any, is left as it was.
    """
    path = Path(path)
    created = _missing_parents(path.parent)
    tmp: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        os.close(fd)
        tmp = Path(name)
        write(tmp)
        _flush(tmp)
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        raise write_error(exc, path) from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()
        if tmp is not None or not path.exists():
            _remove_created(created)
    return path


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`write_with`)."""
    return write_with(path, lambda tmp: tmp.write_bytes(data))


def write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (:func:`write_with`)."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path: str | Path, data: object, **dumps: object) -> Path:
    """Write ``data`` as JSON (``json.dumps`` keywords ``dumps``) to ``path`` atomically."""
    import json

    return write_text(path, json.dumps(data, **dumps))  # type: ignore[arg-type]


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
        tmp = Path(tempfile.mkdtemp(dir=final.parent, prefix=f".{final.name}.", suffix=".tmp"))
        yield tmp
    except OSError as exc:
        raise write_error(exc, final) from None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        if not final.exists():
            _remove_created(created)


def replace_folder(tmp: Path, final: str | Path) -> Path:
    """Move the complete folder ``tmp`` to ``final`` (which must not exist, or be an empty folder)."""
    final = Path(final)
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp, final)
    except OSError as exc:
        raise write_error(exc, final) from None
    return final
