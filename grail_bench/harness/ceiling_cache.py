"""The Bayes ceilings a results store's rows need, cached in the store file (:class:`CeilingCache`, read and
written by :func:`grail_bench.harness.ceiling.ceilings_for`)."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Iterable

from grail_bench.harness.store import StoreError, connect_read_only

__all__ = ["CeilingCache"]


class CeilingCache:
    """Bayes ceilings kept in the store's ``ceilings`` table (key digest -> key and ceiling, as JSON), so the
    ceilings a store's rows need are computed once per store wherever it is read.

    The key holds everything that determines a ceiling (:func:`grail_bench.harness.ceiling.ceilings_for`); a
    changed task or method gives a new key, so a stale entry is never read. The table sits beside the rows' tables
    and is not part of their schema: it is created on the first write, and a store that cannot be written (read
    only, or in use) is simply not written to; nothing else in the file is touched.
    """

    def __init__(self, path: str | Path, read_only: bool = False) -> None:
        self.path = Path(path).expanduser()
        self.read_only = read_only  # read the table, never write it (``leaderboard --read-only``)

    def get(self, digests: Iterable[str]) -> dict[str, str]:
        """The stored ``{digest: JSON}`` of those of ``digests`` that are cached."""
        wanted = list(digests)
        if not wanted or not self.path.is_file():
            return {}
        try:
            conn = connect_read_only(self.path)
            try:
                if not conn.execute("SELECT 1 FROM sqlite_master WHERE name = 'ceilings'").fetchone():
                    return {}
                out = {}
                for start in range(0, len(wanted), 500):
                    chunk = wanted[start:start + 500]
                    out |= dict(conn.execute(f"SELECT digest, entry FROM ceilings WHERE digest IN "
                                             f"({', '.join('?' * len(chunk))})", chunk))
                return out
            finally:
                conn.close()
        except (sqlite3.Error, StoreError, OSError):
            return {}

    def put(self, entries: dict[str, str]) -> bool:
        """Store ``{digest: JSON}``; False when the store cannot be written, or is read only (nothing is then
        changed)."""
        if self.read_only:
            return False
        if not entries:
            return True
        try:
            conn = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=rw", uri=True, timeout=5.0)
            try:
                with conn:
                    conn.execute("CREATE TABLE IF NOT EXISTS ceilings (digest TEXT PRIMARY KEY, entry TEXT NOT NULL, "
                                 "created_at TEXT NOT NULL DEFAULT (datetime('now')))")
                    conn.executemany("INSERT OR REPLACE INTO ceilings (digest, entry) VALUES (?, ?)", entries.items())
            finally:
                conn.close()
            return True
        except (sqlite3.Error, OSError):
            return False
