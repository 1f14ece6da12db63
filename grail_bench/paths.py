"""Where grail-bench keeps files: results (data) and caches."""

from __future__ import annotations

import os
from pathlib import Path


def data_dir() -> Path:
    """``$XDG_DATA_HOME/grail-bench`` (``~/.local/share/grail-bench``)."""
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "grail-bench"


def cache_dir() -> Path:
    """``$GRAIL_BENCH_CACHE``, else ``$XDG_CACHE_HOME/grail-bench`` (``~/.cache/grail-bench``)."""
    if os.environ.get("GRAIL_BENCH_CACHE"):
        return Path(os.environ["GRAIL_BENCH_CACHE"]).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "grail-bench"
