"""The results store: an embedded SQLite database, the only code that touches it.

One table per mode (:data:`grail_bench.harness.modes.MODES`), named and keyed
by the mode, and one of fit diagnostics (``fits``, one
:class:`~grail_bench.harness.diagnostics.FitRow` per task, recognizer, config
hash, seed and mode): ``results`` (offline, the paper's protocol), one
:class:`ResultRow` per (task, recognizer, scorer, config hash, seed,
observability, observation protocol); ``online`` (every prefix scored), one
:class:`OnlineRow` per (task, recognizer, scorer, config hash, seed, protocol);
``open_set`` (a goal held out), one :class:`OpenSetRow` per (task, recognizer,
scorer, config hash, seed, observability, protocol); ``zero_shot`` (goals never
fitted), one :class:`ZeroShotRow` per the same key. Rows are written in one
transaction per fitted seed with ``INSERT OR IGNORE``, in WAL mode with a busy
timeout, so an interrupted run keeps what it finished and concurrent writers
lose nothing.

Default location: ``$GRAIL_BENCH_STORE``, else
``$XDG_DATA_HOME/grail-bench/results.sqlite`` (``~/.local/share/...``).
"""

from __future__ import annotations

import os
import sqlite3
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, Iterable

from grail_bench.core.errors import UserError
from grail_bench.core.paths import data_dir
from grail_bench.harness import diagnostics
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES, Mode, OnlineRow, OpenSetRow, ResultRow, Row, ZeroShotRow

SCHEMA_VERSION = 7
__all__ = ["SCHEMA_VERSION", "FitRow", "OnlineRow", "OpenSetRow", "ResultRow", "ResultsStore", "Row", "StoreError",
           "ZeroShotRow", "default_store_path"]


class StoreError(UserError):
    """The store cannot be opened, read or written."""


_COLUMNS = [f.name for f in fields(ResultRow)]
_TYPES = {"task": "TEXT", "recognizer": "TEXT", "scorer": "TEXT", "config_hash": "TEXT", "seed": "INTEGER",
          "observability": "REAL", "protocol": "TEXT", "n_observations": "INTEGER", "n_ties": "INTEGER",
          "config": "TEXT", "versions": "TEXT", "provenance": "TEXT", "n_trajectories": "INTEGER",
          "curve": "TEXT", "held_out": "TEXT", "confusion": "TEXT", "mode": "TEXT", "diagnostics": "TEXT"}


def _tables() -> dict[type, tuple[str, tuple[str, ...]]]:
    """Row type -> (table, primary key): every mode's, and the fit diagnostics'."""
    out = {mode.row: (mode.table, mode.key) for mode in MODES.values()}
    out[FitRow] = (diagnostics.TABLE, diagnostics.KEY)
    return out


def _create(kind: type, table: str, key: tuple[str, ...]) -> str:
    return (f"CREATE TABLE IF NOT EXISTS {table} ("
            + ", ".join(f"{f.name} {_TYPES.get(f.name, 'REAL')}" + (" NOT NULL" if f.name in key else "")
                        for f in fields(kind))
            + ", created_at TEXT NOT NULL DEFAULT (datetime('now'))"
            + f", PRIMARY KEY ({', '.join(key)}))")


def default_store_path() -> Path:
    """Where results go unless ``--store`` or ``GRAIL_BENCH_STORE`` says otherwise."""
    if os.environ.get("GRAIL_BENCH_STORE"):
        return Path(os.environ["GRAIL_BENCH_STORE"]).expanduser()
    return data_dir() / "results.sqlite"


class ResultsStore:
    """Append-only results database.

    Args:
        path: Database file (created with its folder if missing), or ``":memory:"``.

    Raises:
        StoreError: If the file is not a grail-bench results database.
    """

    def __init__(self, path: str | Path = ":memory:") -> None:
        self.path = str(path)
        try:
            if self.path != ":memory:":
                Path(self.path).expanduser().parent.mkdir(parents=True, exist_ok=True)
            self._conn = sqlite3.connect(self.path, timeout=60.0)
            version = self._conn.execute("PRAGMA user_version").fetchone()[0]
            tables = {r[0] for r in self._conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
            if tables and "results" not in tables:
                raise StoreError(f"{self.path} is an SQLite file but not a grail-bench results store")
            if version > SCHEMA_VERSION:
                raise StoreError(f"{self.path} was written by a newer grail-bench (schema {version})")
            if self.path != ":memory:":
                self._conn.execute("PRAGMA journal_mode=WAL")
            missing = {table for table, _ in _tables().values()} - tables
            if version < SCHEMA_VERSION or missing:  # else nothing to write: reading leaves the file as it was
                with self._conn:
                    if tables and version < 2:
                        _migrate_v1(self._conn)
                    if tables and version < SCHEMA_VERSION:
                        _add_missing_columns(self._conn)
                    for kind, (table, key) in _tables().items():
                        self._conn.execute(_create(kind, table, key))
                    self._conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        except sqlite3.Error as exc:
            raise StoreError(f"cannot use results store {self.path}: {exc}") from None
        except OSError as exc:
            raise StoreError(f"cannot create results store {self.path}: {exc.strerror}") from None

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def add(self, rows: Iterable[Row]) -> int:
        """Insert rows (of any kind, each into its table) in one transaction, ignoring ones already stored.

        Returns:
            How many rows were new.
        """
        by_kind: dict[type, list[tuple]] = {}
        for r in rows:
            by_kind.setdefault(type(r), []).append(tuple(asdict(r).values()))
        try:
            with self._conn:
                before = self._conn.total_changes
                tables = _tables()
                for kind, values in by_kind.items():
                    names = [f.name for f in fields(kind)]
                    self._conn.executemany(f"INSERT OR IGNORE INTO {tables[kind][0]} ({', '.join(names)}) "
                                           f"VALUES ({', '.join('?' * len(names))})", values)
                return self._conn.total_changes - before
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write to results store {self.path}: {exc}") from None

    def rows(self, **where: Any) -> list[ResultRow]:
        """Stored :class:`ResultRow` rows, optionally filtered by column equality (a list means any of)."""
        return self.select(ResultRow, **where)

    def select(self, kind: type | Mode, **where: Any) -> list[Any]:
        """Stored rows of one mode (or of a row type, :class:`FitRow` included), optionally filtered by column
        equality (a list means any of)."""
        kind = kind.row if isinstance(kind, Mode) else kind
        table = _tables()[kind][0]
        columns = [f.name for f in fields(kind)]
        clauses, params = [], []
        for column, value in where.items():
            if column not in columns:
                raise ValueError(f"unknown column {column!r}")
            values = list(value) if isinstance(value, (list, tuple, set)) else [value]
            clauses.append(f"{column} IN ({', '.join('?' * len(values))})")
            params += values
        sql = f"SELECT {', '.join(columns)} FROM {table}"
        if clauses:
            sql += " WHERE " + " AND ".join(clauses)
        order = [c for c in ("task", "recognizer", "scorer", "observability", "mode", "seed") if c in columns]
        sql += " ORDER BY " + ", ".join(order)
        try:
            return [kind(*r) for r in self._conn.execute(sql, params)]
        except sqlite3.Error as exc:
            raise StoreError(f"cannot read results store {self.path}: {exc}") from None

    def completed(self, task: str, recognizer: str, scorer: str, config_hash: str, protocol: str,
                  kind: type[Row] | Mode = ResultRow) -> set[tuple[int, float | None]]:
        """``(seed, observability)`` pairs already stored for one configuration (observability ``None`` online)."""
        return {(r.seed, getattr(r, "observability", None)) for r in
                self.select(kind, task=task, recognizer=recognizer, scorer=scorer, config_hash=config_hash,
                            protocol=protocol)}


def _migrate_v1(conn: sqlite3.Connection) -> None:
    """Schema 1 -> 2: the ``sampling`` column becomes ``protocol``; every row is kept.

    ``prefix`` rows keep their name (the prefix is drawn without randomness).
    ``random`` rows keep theirs too, as a legacy protocol: they drew from a
    stream shared across levels, so they must not count as finished ``subset``
    cells of a resumed run.
    """
    columns = {r[1] for r in conn.execute("PRAGMA table_info(results)")}
    if "sampling" in columns and "protocol" not in columns:
        conn.execute("ALTER TABLE results RENAME COLUMN sampling TO protocol")


def _add_missing_columns(conn: sqlite3.Connection) -> None:
    """Schema 2 -> 3 -> 4 -> 6: the columns added since (``provenance``; ``top2``, ``mean_rank``; ``confusion``),
    empty for the rows already stored. (Schema 5 added tables, and schema 6 the ``fits`` table too.)"""
    columns = {r[1] for r in conn.execute("PRAGMA table_info(results)")}
    for name in _COLUMNS:
        if name not in columns:
            conn.execute(f"ALTER TABLE results ADD COLUMN {name} {_TYPES.get(name, 'REAL')}")
