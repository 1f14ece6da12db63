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
    """``path``, once checked to be writable as a file (or, with ``folder``, as a folder).

    The folder that will hold it is created (as writing the output would)
    and a probe file is written in it and removed, so even a process
    running as root learns now, not after a run, that a folder cannot be
    written. An existing file at ``path`` is left untouched.

    Raises:
        UserError: Naming the path and why it cannot be written.
    """
    path = Path(path).expanduser()
    what = "folder" if folder else "file"
    if path.exists() and path.is_dir() != folder:
        raise UserError(f"cannot write the {what} {path}: it is a {'file' if folder else 'folder'}")
    home = path if folder else path.parent
    try:
        home.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=home):
            pass
    except OSError as exc:
        raise UserError(f"cannot write the {what} {path}: {exc.strerror or exc}") from None
    if path.exists() and not os.access(path, os.W_OK):
        raise UserError(f"cannot write the {what} {path}: permission denied")
    return path
