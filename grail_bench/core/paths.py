"""Where grail-bench keeps files (results, caches), and whether an output path can be written."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from grail_bench.core.errors import UserError


def data_dir() -> Path:
    """``$XDG_DATA_HOME/grail-bench`` (``~/.local/share/grail-bench``)."""
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "grail-bench"


def cache_dir() -> Path:
    """``$GRAIL_BENCH_CACHE``, else ``$XDG_CACHE_HOME/grail-bench`` (``~/.cache/grail-bench``)."""
    if os.environ.get("GRAIL_BENCH_CACHE"):
        return Path(os.environ["GRAIL_BENCH_CACHE"]).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "grail-bench"


def check_writable(path: str | Path, folder: bool = False) -> Path:
    """``path``, once checked to be writable as a file (or, with ``folder``, as a folder); nothing is created.

    A probe file is written and removed in the nearest folder that exists
    on the way to ``path`` (its own folder, or the folder that would hold the
    folders a write creates), so even a process running as root learns now,
    not after a run, that it cannot be written. Folders are created only by
    the write itself (:mod:`grail_bench.core.atomic`), so a command refused
    later leaves no empty folder behind. An existing file at ``path`` is left
    untouched.

    Raises:
        UserError: Naming the path and why it cannot be written.
    """
    path = Path(path).expanduser()
    what = "folder" if folder else "file"
    if path.exists() and path.is_dir() != folder:
        raise UserError(f"cannot write the {what} {path}: it is a {'file' if folder else 'folder'}")
    home = path if folder else path.parent
    while not home.exists() and home != home.parent:
        home = home.parent
    if not home.is_dir():
        raise UserError(f"cannot write the {what} {path}: {home} is a file")
    try:
        with tempfile.TemporaryFile(dir=home):
            pass
    except OSError as exc:
        raise UserError(f"cannot write the {what} {path}: {exc.strerror or exc}") from None
    if path.exists() and not os.access(path, os.W_OK):
        raise UserError(f"cannot write the {what} {path}: permission denied")
    return path
