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
fitted), one :class:`ZeroShotRow` per the same key; and ``outputs`` (schema
10), the per-instance outputs of offline rows, one
:class:`~grail_bench.harness.outputs.OutputRow` per offline row run since. Rows
are written in one transaction per fitted seed, in WAL mode with a busy timeout, so an
interrupted run keeps what it finished and concurrent writers lose nothing; a
row already stored is kept (the first write wins), unless it is stale.

Stale rows. Rows of every mode record how ties between goals of equal best
score were broken (``ties``: ``"uniform"``, the expectation under uniform
tie-breaking, :data:`grail_bench.stats.metrics.TIE_RULE`) and how many
observations (online: prefixes) tied (``n_ties``). Rows stored before schema 8
have ``ties`` NULL: they gave the prediction to the lowest-index tied goal. One
that counted no tie (``n_ties = 0``, offline rows) reads the same under both
rules and stays valid. One that tied (``n_ties > 0``), or whose mode did not
count ties (online, open-set and zero-shot rows before schema 8: any of them
may have tied), is stale: :meth:`ResultsStore.completed` leaves it out, so the
next ``run`` or ``reproduce`` recomputes it, and :meth:`ResultsStore.add`
replaces it with the new row of the same key.

Shared tables (schema 10). What many rows share is stored once, keyed by the
SHA-256 of its JSON text (:func:`ref`): a row's recognizer configuration in
``configs``, its package versions in ``versions`` and its provenance in
``provenance``, and the submission a merged row came from in ``sources``
(:data:`SHARED`); the row holds the metrics and the references
(``config_ref``, ``versions_ref``, ``provenance_ref``, ``source_ref``). Rows
read and written through this module carry the JSON as before. A store of an older schema is
normalised by :func:`migrate` when a command opens it to write; a command that
only reads reads it as it is.

Commands that only read (the leaderboard, studies) open a store with
``read_only=True``: the file must already be a grail-bench store, and nothing
is created or changed beside it, so a store in a read-only folder, or one
committed to a repository, reads as it is. Commands that write learn before any
work (:func:`check_store_writable`) that the store can take their rows.

Default location: ``$GRAIL_BENCH_STORE``, else
``$XDG_DATA_HOME/grail-bench/results.sqlite`` (``~/.local/share/...``).
"""

from __future__ import annotations

import hashlib
import os
import sqlite3
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, Iterable

from grail_bench.core.errors import UserError
from grail_bench.core.paths import check_writable, data_dir
from grail_bench.harness import diagnostics, outputs
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES, Mode, OnlineRow, OpenSetRow, ResultRow, Row, ZeroShotRow
from grail_bench.harness.outputs import OutputRow

SCHEMA_VERSION = 10
#: The first schema whose row tables reference the shared tables (:data:`SHARED`) instead of repeating the JSON.
NORMALISED = 10
__all__ = ["NORMALISED", "SCHEMA_VERSION", "SHARED", "FitRow", "OnlineRow", "OpenSetRow", "OutputRow", "ResultRow",
           "ResultsStore", "Row", "StoreError", "ZeroShotRow", "check_store_writable", "default_store_path", "migrate",
           "ref", "stale"]
_HEADER = b"SQLite format 3\x00"  # the first 16 bytes of every SQLite database file
_SIDECARS = ("-wal", "-journal")  # present while a connection has the store open (or after a crash)


class StoreError(UserError):
    """The store cannot be opened, read or written."""


_TYPES = {"task": "TEXT", "recognizer": "TEXT", "scorer": "TEXT", "config_hash": "TEXT", "seed": "INTEGER",
          "observability": "REAL", "protocol": "TEXT", "n_observations": "INTEGER", "n_ties": "INTEGER",
          "config": "TEXT", "versions": "TEXT", "provenance": "TEXT", "n_trajectories": "INTEGER",
          "curve": "TEXT", "held_out": "TEXT", "confusion": "TEXT", "mode": "TEXT", "diagnostics": "TEXT",
          "ties": "TEXT", "posterior": "INTEGER", "data": "BLOB"}
#: Row field -> the shared table holding its JSON once; the row's column is ``{field}_ref``, the table's key its hash.
SHARED = {"config": "configs", "versions": "versions", "provenance": "provenance", "source": "sources"}
#: SQL condition of a stale row (see the module docstring): stored under the old tie rule, and it may have tied.
_STALE = "{t}.ties IS NULL AND ({t}.n_ties IS NULL OR {t}.n_ties > 0)"


def stale(row: Row) -> bool:
    """Whether a stored row is stale: computed under the old tie rule (towards the lowest index) and it may have
    tied, so it must be recomputed (see the module docstring)."""
    return row.ties is None and (row.n_ties is None or row.n_ties > 0)


def ref(text: str | None) -> str | None:
    """The key of a shared JSON text (see the module docstring): the hex SHA-256 of its UTF-8 bytes."""
    return None if text is None else hashlib.sha256(text.encode()).hexdigest()


def _column(name: str) -> str:
    """The column of a row field in a normalised table."""
    return f"{name}_ref" if name in SHARED else name


def _tables() -> dict[type, tuple[str, tuple[str, ...]]]:
    """Row type -> (table, primary key): every mode's, and the fit diagnostics'."""
    out = {mode.row: (mode.table, mode.key) for mode in MODES.values()}
    out[FitRow] = (diagnostics.TABLE, diagnostics.KEY)
    out[OutputRow] = (outputs.TABLE, outputs.KEY)
    return out


def _create(kind: type, table: str, key: tuple[str, ...]) -> str:
    """The statement creating a (normalised) row table of ``kind``."""
    return (f"CREATE TABLE IF NOT EXISTS {table} ("
            + ", ".join(f"{_column(f.name)} {_TYPES.get(f.name, 'REAL')}" + (" NOT NULL" if f.name in key else "")
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
        read_only: Read an existing store without creating or changing any
            file: a store of an older schema is upgraded in memory only, and
            :meth:`add` is refused.

    Raises:
        StoreError: If the file is not a grail-bench results database, was
            written by a newer grail-bench, or (unless ``read_only``) cannot be
            written; with ``read_only``, also if there is no file.
    """

    def __init__(self, path: str | Path = ":memory:", read_only: bool = False) -> None:
        self.path = str(path)
        self.read_only = read_only
        try:
            if self.path == ":memory:":
                self._conn = sqlite3.connect(self.path)
                self._upgrade(set(), 0)
                self._layout()
            elif read_only:
                self._conn = _connect_read_only(Path(self.path).expanduser())
                self._checked(read_only=True, fresh=False)
            else:
                file = _check_writable_path(Path(self.path).expanduser())
                fresh = not file.exists() or file.stat().st_size == 0  # an empty file is an empty database
                if not fresh:
                    _check_header(file)
                self._conn = sqlite3.connect(file, timeout=60.0)
                self._checked(read_only=False, fresh=fresh)
        except sqlite3.Error as exc:
            raise StoreError(f"cannot use results store {self.path}: {exc}") from None
        except OSError as exc:
            raise StoreError(f"cannot use results store {self.path}: {exc.strerror or exc}") from None

    def _checked(self, read_only: bool, fresh: bool) -> None:
        """:meth:`_open`, closing the connection if the file is refused."""
        try:
            self._open(read_only, fresh)
        except BaseException:
            self._conn.close()
            raise

    def _open(self, read_only: bool, fresh: bool) -> None:
        """Check the opened file (``fresh``: new or empty) is a store this version can use, then bring its schema
        up to date (in memory only when ``read_only``; a writable store that needs nothing written is probed for
        write access instead)."""
        version = self._conn.execute("PRAGMA user_version").fetchone()[0]
        tables = {r[0] for r in self._conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not fresh and "results" not in tables:
            what = "an SQLite file but " if tables else ""
            raise StoreError(f"{self.path} is {what}not a grail-bench results store")
        if version > SCHEMA_VERSION:
            raise StoreError(f"{self.path} was written by a newer grail-bench (schema {version})")
        missing = {table for table, _ in _tables().values()} - tables
        current = version >= SCHEMA_VERSION and not missing
        if read_only:
            # Schema 10 changed the layout, which reading follows as it finds it, and added a table, which reads
            # as empty where missing: a store of schema 9 is read as it is; an older one from a copy upgraded in
            # memory (not normalised). The file stays as it was.
            if version < NORMALISED - 1 or missing - {outputs.TABLE}:
                memory = sqlite3.connect(":memory:")
                self._conn.backup(memory)
                self._conn.close()
                self._conn = memory
                self._upgrade(tables, version, normalise=False)
            self._layout()
            return
        self._conn.execute("PRAGMA journal_mode=WAL")
        if current:  # nothing to write: reading leaves the file as it was, but a run must learn now if it can write
            self._conn.execute("BEGIN IMMEDIATE")
            self._conn.execute("ROLLBACK")
        else:
            self._upgrade(tables, version)
        self._layout()

    def _upgrade(self, tables: set[str], version: int, normalise: bool = True) -> None:
        """Bring the schema up to date (:func:`migrate`)."""
        migrate(self._conn, tables, version, normalise=normalise)

    def _layout(self) -> None:
        """Learn which shared fields each row table references (normalised) rather than holds."""
        self._refs: dict[str, set[str]] = {}
        self._columns: dict[str, set[str]] = {}
        for table, _ in _tables().values():
            columns = {r[1] for r in self._conn.execute(f"PRAGMA table_info({table})")}
            self._refs[table] = {name for name in SHARED if _column(name) in columns}
            self._columns[table] = columns

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def add(self, rows: Iterable[Row]) -> int:
        """Insert rows (of any kind, each into its table) in one transaction, ignoring ones already stored,
        except that a row replaces a :func:`stale` one of the same key.

        Returns:
            How many rows were new or replaced a stale one.
        """
        if self.read_only:
            raise StoreError(f"results store {self.path} was opened read-only")
        by_kind: dict[type, list[tuple]] = {}
        shared: dict[str, dict[str, str]] = {table: {} for table in SHARED.values()}
        for r in rows:
            values = asdict(r)
            for name, table in SHARED.items():
                if values.get(name) is not None:
                    key = ref(values[name])
                    shared[table][key] = values[name]
                    values[name] = key
            by_kind.setdefault(type(r), []).append(tuple(values.values()))
        try:
            with self._conn:
                for table, texts in shared.items():
                    self._conn.executemany(f"INSERT OR IGNORE INTO {table} (hash, json) VALUES (?, ?)",
                                           sorted(texts.items()))
                before = self._conn.total_changes
                tables = _tables()
                for kind, values in by_kind.items():
                    self._conn.executemany(_insert(kind, *tables[kind]), values)
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
        refs, present = self._refs[table], self._columns[table]
        if not present:  # a table added since the store was written (read as it is): no rows
            return []
        # A field the file has no column for (a store of schema 9, read as it is) reads as NULL.
        expression = {c: f"{SHARED[c]}.json" if c in refs else f"t.{c}" if c in present else "NULL" for c in columns}
        joins = "".join(f" LEFT JOIN {SHARED[c]} ON {SHARED[c]}.hash = t.{_column(c)}" for c in columns if c in refs)
        clauses, params = [], []
        for column, value in where.items():
            if column not in columns:
                raise ValueError(f"unknown column {column!r}")
            values = list(value) if isinstance(value, (list, tuple, set)) else [value]
            clauses.append(f"{expression[column]} IN ({', '.join('?' * len(values))})")
            params += values
        sql = f"SELECT {', '.join(expression[c] for c in columns)} FROM {table} AS t{joins}"
        if clauses:
            sql += " WHERE " + " AND ".join(clauses)
        order = [f"t.{c}" for c in ("task", "recognizer", "scorer", "observability", "mode", "seed") if c in columns]
        sql += " ORDER BY " + ", ".join(order)
        try:
            return [kind(*r) for r in self._conn.execute(sql, params)]
        except sqlite3.Error as exc:
            raise StoreError(f"cannot read results store {self.path}: {exc}") from None

    def completed(self, task: str, recognizer: str, scorer: str, config_hash: str, protocol: str,
                  kind: type[Row] | Mode = ResultRow) -> set[tuple[int, float | None]]:
        """``(seed, observability)`` pairs already stored for one configuration (observability ``None`` online).

        A :func:`stale` row does not count: the run recomputes it.
        """
        return {(r.seed, getattr(r, "observability", None)) for r in
                self.select(kind, task=task, recognizer=recognizer, scorer=scorer, config_hash=config_hash,
                            protocol=protocol) if not stale(r)}


def _insert(kind: type, table: str, key: tuple[str, ...]) -> str:
    """The statement storing one row of ``kind``: ignored if its key is stored, unless the stored row is stale."""
    names = [_column(f.name) for f in fields(kind)]
    head = f"INTO {table} ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})"
    if "ties" not in names:
        return f"INSERT OR IGNORE {head}"
    update = ", ".join(f"{n} = excluded.{n}" for n in names if n not in key)
    return (f"INSERT {head} ON CONFLICT ({', '.join(key)}) DO UPDATE SET {update}, created_at = datetime('now') "
            f"WHERE {_STALE.format(t=table)}")


def check_store_writable(path: str | Path) -> Path:
    """Check, before any work, that a run can store its rows at ``path``; create and change nothing there.

    Its folder must be writable (it is created if missing, as a run would),
    and an existing file must be a grail-bench store this version reads
    that can be written.

    Returns:
        The path, ``~`` expanded.

    Raises:
        StoreError: Naming the path and why a run could not write to it.
    """
    file = _check_writable_path(Path(path).expanduser())
    if file.exists() and file.stat().st_size:
        ResultsStore(file, read_only=True).close()  # a grail-bench store, not a newer one
        try:
            conn = sqlite3.connect(f"{file.resolve().as_uri()}?mode=rw", uri=True, timeout=60.0)
            try:
                conn.execute("BEGIN IMMEDIATE")  # the write lock: refused on a file opened read-only
                conn.execute("ROLLBACK")
            finally:
                conn.close()
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write to results store {file}: {exc}") from None
    return file


def _check_writable_path(file: Path) -> Path:
    """``file``, once its folder (created if missing) takes new files and the file itself, if any, is writable."""
    try:
        return check_writable(file)
    except UserError as exc:
        raise StoreError(str(exc)) from None


def _check_header(file: Path) -> None:
    """Refuse a file that is not an SQLite database (an empty one included) before SQLite opens it."""
    with open(file, "rb") as handle:
        if handle.read(len(_HEADER)) != _HEADER:
            raise StoreError(f"{file} is not a grail-bench results store")


def _connect_read_only(file: Path) -> sqlite3.Connection:
    """A connection that can only read ``file`` and creates no file beside it.

    While another connection has the store open (or after a crash) its
    ``-wal`` or ``-journal`` file is there: SQLite's read-only mode then reads
    the committed rows through it. Otherwise nobody is writing the store, and
    it is opened ``immutable``: no lock, no ``-wal`` or ``-shm`` file (which a
    read-only connection to a WAL store would leave behind), so a read-only
    folder or a committed store reads as it is.

    Raises:
        StoreError: For a missing file, a folder, or a file that is not an SQLite database.
    """
    if not file.exists():
        raise StoreError(f"no results store at {file}")
    if file.is_dir():
        raise StoreError(f"{file} is a folder, not a grail-bench results store")
    _check_header(file)
    busy = any(Path(f"{file}{suffix}").exists() for suffix in _SIDECARS)
    return sqlite3.connect(f"{file.resolve().as_uri()}?{'mode=ro' if busy else 'immutable=1'}", uri=True,
                           timeout=60.0)


def migrate(conn: sqlite3.Connection, tables: set[str], version: int, normalise: bool = True) -> bool:
    """Bring an opened store's schema up to date: migrate an older one and create the missing tables.

    The one place a store's file is changed for its schema: call it only for a
    command that will write (a reading one reads the store as it is, or a copy
    upgraded in memory with ``normalise=False``). The migration is one
    transaction; a store normalised by it (schema 9 or older -> 10, see the
    module docstring) is then vacuumed, returning the space the repeated JSON
    took.

    Args:
        conn: The store's connection (no transaction open).
        tables: The tables the store had when opened (empty: a new store).
        version: Its ``PRAGMA user_version`` when opened.
        normalise: Move the rows' shared JSON into the shared tables (schema 10).

    Returns:
        Whether rows were normalised.
    """
    normalised = False
    with conn:
        if tables and version < 2:
            _migrate_v1(conn)
        if tables and version < SCHEMA_VERSION:
            _add_missing_columns(conn)
        for table in SHARED.values():
            conn.execute(f"CREATE TABLE IF NOT EXISTS {table} (hash TEXT PRIMARY KEY, json TEXT NOT NULL) "
                         "WITHOUT ROWID")
        if normalise and tables and version < NORMALISED:
            normalised = _normalise(conn)
        for kind, (table, key) in _tables().items():
            conn.execute(_create(kind, table, key))
        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    if normalised and conn.execute("PRAGMA database_list").fetchone()[2]:  # a file, not memory
        conn.execute("VACUUM")
    return normalised


def _normalise(conn: sqlite3.Connection) -> bool:
    """Schema 9 -> 10: each row table's ``config``, ``versions`` and ``provenance`` JSON moves into the shared
    tables once, the row keeping its reference (:func:`ref`); every other column and every row is kept as it is.

    Returns:
        Whether any table was rewritten.
    """
    conn.create_function("grail_ref", 1, ref, deterministic=True)
    changed = False
    for kind, (table, key) in _tables().items():
        columns = [r[1] for r in conn.execute(f"PRAGMA table_info({table})")]
        inline = [c for c in columns if c in SHARED]
        if not inline:
            continue
        for name in inline:
            conn.execute(f"INSERT OR IGNORE INTO {SHARED[name]} (hash, json) SELECT grail_ref(v), v FROM "
                         f"(SELECT DISTINCT {name} AS v FROM {table} WHERE {name} IS NOT NULL)")
        conn.execute(f"ALTER TABLE {table} RENAME TO {table}__inline")
        conn.execute(_create(kind, table, key))
        target = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
        kept = [c for c in columns if _column(c) in target]
        conn.execute(f"INSERT INTO {table} ({', '.join(_column(c) for c in kept)}) SELECT "
                     f"{', '.join(f'grail_ref({c})' if c in SHARED else c for c in kept)} FROM {table}__inline")
        conn.execute(f"DROP TABLE {table}__inline")
        changed = True
    return changed


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
    """Schema 2 -> ... -> 10: the columns added since to the tables already there, empty (NULL) for the rows
    already stored: ``provenance``; ``top2``, ``mean_rank``; ``confusion``; the reliability and set metrics;
    schema 8 ``ties`` in every mode's table and ``n_ties`` in those that had none; schema 9 the zero-shot
    table's ``adapt_seconds_per_goal`` and ``score_us_per_observation``; schema 10 ``source`` in every mode's
    table. (Schema 5 added tables, and schema 6
    the ``fits`` table too.)"""
    for kind, (table, _) in _tables().items():
        columns = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
        if not columns:  # not there yet: created whole
            continue
        normalised = any(_column(name) in columns for name in SHARED)
        for f in fields(kind):
            column = _column(f.name) if normalised else f.name
            if column not in columns:
                conn.execute(f"ALTER TABLE {table} ADD COLUMN {column} {_TYPES.get(f.name, 'REAL')}")
