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
fitted), one :class:`ZeroShotRow` per the same key; and the per-instance outputs
of the rows (:mod:`grail_bench.harness.outputs`), one output row per row run
since, keyed like it: ``outputs`` (offline, schema 11), ``online_outputs``,
``open_set_outputs`` and ``zero_shot_outputs`` (schema 12, :data:`MODE_OUTPUTS`). Rows
are written in one transaction per fitted seed, in WAL mode with a busy timeout, so an
interrupted run keeps what it finished and concurrent writers lose nothing; a
row already stored is kept (the first write wins), unless it is stale or the run recomputes it on purpose
(``run --rerun``: its new rows replace the stored ones of their keys in one transaction).

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

Shared tables (schema 11). What many rows share is stored once, keyed by the
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
work (:func:`check_store_writable`) that the store can take their rows, but
change the disk only when they write rows: the file is created (whole, under a
temporary name first) or an older schema migrated by the first
:meth:`ResultsStore.add`. A full disk is one line (``no space left on device
writing <path>``); SQLite's transactions keep the rows stored before.

Task versions. Rows record the fingerprint of the task they ran (``task_fingerprint``, schema 10; NULL before).
Rows stored under a task version whose meaning has since moved to a newer one (``tasks/versions.toml``,
``[[moved]]``) are read as the version their recorded parameters say they ran
(:func:`grail_bench.task.versions.resolve_id`); the file is not rewritten, and selecting a task selects the rows
stored under its older IDs that resolve to it.

Default location: ``$GRAIL_BENCH_STORE``, else
``$XDG_DATA_HOME/grail-bench/results.sqlite`` (``~/.local/share/...``).
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import sqlite3
from dataclasses import asdict, fields, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Iterable, get_args, get_type_hints

from grail_bench.core.atomic import WriteError, temporary_folder, write_error
from grail_bench.core.errors import UserError
from grail_bench.core.paths import check_writable, data_dir
from grail_bench.harness import diagnostics, outputs
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES, Mode, OnlineRow, OpenSetRow, ResultRow, Row, ZeroShotRow
from grail_bench.harness.outputs import KINDS as OUTPUT_KINDS
from grail_bench.harness.outputs import OutputRow
from grail_bench.harness.planning import task_params
from grail_bench.task import versions

SCHEMA_VERSION = 12
#: The first schema whose row tables reference the shared tables (:data:`SHARED`) instead of repeating the JSON.
NORMALISED = 11
#: The first schema keeping the per-instance outputs of the online, open-set and zero-shot rows (their tables).
MODE_OUTPUTS = 12
__all__ = ["MODE_OUTPUTS", "NORMALISED", "SCHEMA_VERSION", "SHARED", "CeilingCache", "FitRow", "OnlineRow", "OpenSetRow", "OutputRow",
           "ResultRow", "ResultsStore", "Row", "StoreError", "ZeroShotRow", "check_store_writable",
           "default_store_path", "migrate", "ref", "stale"]
_HEADER = b"SQLite format 3\x00"  # the first 16 bytes of every SQLite database file
_SIDECARS = ("-wal", "-journal")  # present while a connection has the store open (or after a crash)


class StoreError(UserError):
    """The store cannot be opened, read or written."""


_TYPES = {"task": "TEXT", "recognizer": "TEXT", "scorer": "TEXT", "config_hash": "TEXT", "seed": "INTEGER",
          "observability": "REAL", "protocol": "TEXT", "n_observations": "INTEGER", "n_ties": "INTEGER",
          "config": "TEXT", "versions": "TEXT", "provenance": "TEXT", "n_trajectories": "INTEGER",
          "curve": "TEXT", "held_out": "TEXT", "confusion": "TEXT", "mode": "TEXT", "diagnostics": "TEXT",
          "ties": "TEXT", "task_fingerprint": "TEXT", "posterior": "INTEGER", "data": "BLOB"}
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
    out |= {kind.row: (kind.name, kind.key) for kind in OUTPUT_KINDS.values()}
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
        path: Database file, or ``":memory:"``. A missing (or empty) file is
            created, with its folder, by the first :meth:`add` that has rows,
            whole (built under a temporary name and moved into place); a store
            of an older schema is read upgraded in memory and migrated in place
            by that first :meth:`add` too, so a command refused before it
            writes leaves the disk as it was.
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
        self._pending: str | None = None  # "create", "migrate" or "wal": what the first add does to the file first
        try:
            if self.path == ":memory:":
                self._conn = sqlite3.connect(self.path)
                migrate(self._conn, set(), 0)
                self._layout()
            elif read_only:
                self._conn = _connect_read_only(Path(self.path).expanduser())
                self._checked(read_only=True, fresh=False)
            else:
                file = _check_writable_path(Path(self.path).expanduser())
                if not file.exists() or file.stat().st_size == 0:  # an empty file is an empty database
                    self._pending = "create"  # created (whole) by the first add
                    self._conn = sqlite3.connect(":memory:")
                    migrate(self._conn, set(), 0)
                    self._layout()
                else:
                    _check_header(file)
                    self._conn = sqlite3.connect(file, timeout=60.0)
                    self._checked(read_only=False, fresh=False)
        except sqlite3.Error as exc:
            raise StoreError(_sqlite_message("use", self.path, exc)) from None
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
        if not tables and not version:  # an SQLite file with nothing in it (made by another tool): empty
            fresh = True
        if not fresh and "results" not in tables:
            what = "an SQLite file but " if tables else ""
            raise StoreError(f"{self.path} is {what}not a grail-bench results store")
        if version > SCHEMA_VERSION:
            raise StoreError(f"{self.path} was written by a newer grail-bench (schema {version})")
        missing = {table for table, _ in _tables().values()} - tables
        current = version >= SCHEMA_VERSION and not missing
        if not read_only:  # a run must learn now if it can write, though the file is changed only by add
            self._conn.execute("BEGIN IMMEDIATE")
            self._conn.execute("ROLLBACK")
        # Reading follows the layout it finds (inline or shared JSON; a column added since reads as NULL, a table
        # added since as empty), so a store of schema 2 or newer with every table of its time is read as it is.
        # An older one is read from a copy upgraded in memory (not normalised). The file stays as it was.
        if not current and (version < 2 or missing - set(OUTPUT_KINDS)):
            memory = sqlite3.connect(":memory:")
            self._conn.backup(memory)
            self._conn.close()
            self._conn = memory
            migrate(self._conn, tables, version, normalise=False)
        self._layout()
        if not read_only:
            # The first add migrates the file in its transaction, or puts it in WAL mode (a reading command
            # leaves it as it was).
            self._pending = "wal" if current else "migrate"

    def create(self) -> None:
        """Write the store file now, as the first :meth:`add` would: an empty store is created, an older one
        migrated.

        Raises:
            StoreError: If it is read-only, or the file cannot be written (a full disk: one line; no file left).
        """
        if self.read_only:
            raise StoreError(f"results store {self.path} was opened read-only")
        try:
            self._write_ready()
        except sqlite3.Error as exc:
            raise StoreError(_sqlite_message("write to", self.path, exc)) from None

    def _write_ready(self) -> None:
        """What must happen to the file before rows are written to it (see ``_pending``)."""
        if self._pending == "wal":
            self._conn.execute("PRAGMA journal_mode=WAL")
            self._pending = None
        elif self._pending is not None:
            self._materialize()

    def _materialize(self) -> None:
        """Before the first rows are written: create the store file (whole, through a temporary name) or
        migrate the older store in place (in one transaction, normalising it), then write through the file."""
        file = Path(self.path).expanduser()
        if self._pending == "create":
            _create_store(file)
        conn = sqlite3.connect(file, timeout=60.0)
        try:
            version = conn.execute("PRAGMA user_version").fetchone()[0]
            tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
            if (tables or version) and "results" not in tables:
                raise StoreError(f"{self.path} is not a grail-bench results store")
            if version > SCHEMA_VERSION:
                raise StoreError(f"{self.path} was written by a newer grail-bench (schema {version})")
            if version < SCHEMA_VERSION or {table for table, _ in _tables().values()} - tables:
                migrate(conn, tables, version)
            conn.execute("PRAGMA journal_mode=WAL")
        except BaseException:
            conn.close()
            raise
        self._conn.close()
        self._conn, self._pending = conn, None
        self._layout()

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

    def add(self, rows: Iterable[Row], replace: bool = False) -> int:
        """Insert rows (of any kind, each into its table) in one transaction, ignoring ones already stored,
        except that a row replaces a :func:`stale` one of the same key.

        Args:
            replace: Each row replaces the stored one of its key, stale or not (a rerun's rows: the stored ones
                are deleted and the new ones inserted in the same transaction, so an error keeps the old).

        Returns:
            How many rows were new or replaced one.
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
        if not by_kind:
            return 0
        try:
            self._write_ready()
            with self._conn:
                for table, texts in shared.items():
                    self._conn.executemany(f"INSERT OR IGNORE INTO {table} (hash, json) VALUES (?, ?)",
                                           sorted(texts.items()))
                before = self._conn.total_changes
                tables = _tables()
                for kind, values in by_kind.items():
                    self._conn.executemany(_insert(kind, *tables[kind], replace=replace), values)
                return self._conn.total_changes - before
        except sqlite3.Error as exc:
            raise StoreError(_sqlite_message("write to", self.path, exc)) from None
        except OSError as exc:
            raise StoreError(write_error(exc, self.path).args[0]) from None

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
        # A field the file has no column for (a store of an older schema, read as it is) reads as NULL.
        expression = {c: f"{SHARED[c]}.json" if c in refs else f"t.{c}" if c in present else "NULL" for c in columns}
        joins = "".join(f" LEFT JOIN {SHARED[c]} ON {SHARED[c]}.hash = t.{_column(c)}" for c in columns if c in refs)
        versioned = "config" in columns  # rows whose task ID is read through grail_bench.task.versions
        wanted = None
        clauses, params = [], []
        for column, value in where.items():
            if column not in columns:
                raise ValueError(f"unknown column {column!r}")
            values = list(value) if isinstance(value, (list, tuple, set)) else [value]
            if column == "task" and versioned:
                wanted, values = set(values), sorted(versions.aliases(values))
            clauses.append(f"{expression[column]} IN ({', '.join('?' * len(values))})")
            params += values
        sql = f"SELECT {', '.join(expression[c] for c in columns)} FROM {table} AS t{joins}"
        if clauses:
            sql += " WHERE " + " AND ".join(clauses)
        order = [f"t.{c}" for c in ("task", "recognizer", "scorer", "observability", "mode", "seed") if c in columns]
        sql += " ORDER BY " + ", ".join(order)
        try:
            found = self._conn.execute(sql, params).fetchall()
        except sqlite3.Error as exc:
            raise StoreError(f"cannot read results store {self.path}: {exc}") from None
        check = _row_checker(kind)
        out = []
        for values in found:
            problem = check(values)
            if problem is not None:
                named = dict(zip(columns, values))
                raise StoreError(f"results store {self.path}, table {table}, row (task {named['task']!r}, recognizer "
                                 f"{named['recognizer']!r}, seed {named['seed']!r}): {problem}; fix or delete that "
                                 "row (every other row is kept)")
            out.append(kind(*values))
        if not versioned:
            return out
        out = _resolved(out)
        return out if wanted is None else [r for r in out if r.task in wanted]

    def completed(self, task: str, recognizer: str, scorer: str, config_hash: str, protocol: str,
                  kind: type[Row] | Mode = ResultRow) -> set[tuple[int, float | None]]:
        """``(seed, observability)`` pairs already stored for one configuration (observability ``None`` online).

        A :func:`stale` row does not count: the run recomputes it.
        """
        return {(r.seed, getattr(r, "observability", None)) for r in
                self.select(kind, task=task, recognizer=recognizer, scorer=scorer, config_hash=config_hash,
                            protocol=protocol) if not stale(r)}

    def with_outputs(self, task: str, recognizer: str, scorer: str, config_hash: str, protocol: str,
                     kind: type[Row] | Mode = ResultRow) -> set[tuple[int, float | None]]:
        """``(seed, observability)`` pairs of one configuration whose per-instance outputs are stored (rows run
        before the store kept them have none; observability ``None`` online)."""
        row = kind.row if isinstance(kind, Mode) else kind
        table = next(k.name for k in OUTPUT_KINDS.values() if k.of is row)
        columns = self._columns[table]
        if not columns:
            return set()
        tasks = sorted(versions.aliases([task]))
        sql = (f"SELECT seed, {'observability' if 'observability' in columns else 'NULL'} FROM {table} WHERE "
               f"task IN ({', '.join('?' * len(tasks))}) AND recognizer = ? AND scorer = ? AND config_hash = ? "
               "AND protocol = ?")
        try:
            found = self._conn.execute(sql, [*tasks, recognizer, scorer, config_hash, protocol]).fetchall()
        except sqlite3.Error as exc:
            raise StoreError(f"cannot read results store {self.path}: {exc}") from None
        return {(int(seed), level) for seed, level in found}


def _resolved(rows: list[Any]) -> list[Any]:
    """Rows stored under a task version whose meaning has since moved, read as the version they were run with
    (:func:`grail_bench.task.versions.resolve_id`, from the parameters each row records)."""
    moved = versions.shipped_table().sources()
    memo: dict[tuple[str, str], str] = {}
    out = []
    for r in rows:
        if r.task in moved:
            key = (r.task, r.config)
            if key not in memo:
                memo[key] = versions.resolve_id(r.task, task_params(r.config))
            r = replace(r, task=memo[key]) if memo[key] != r.task else r
        out.append(r)
    return out


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
            conn = _connect_read_only(self.path)
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


#: Columns holding JSON text: parsed when read (their readers index into them), or only checked to be whole
#: (bracketed: a truncated text is not) where parsing every row would slow reading a large store.
_JSON = frozenset({"curve", "held_out", "confusion"})
_JSON_WHOLE = frozenset({"config", "versions", "provenance", "reliability", "diagnostics"})


@lru_cache(maxsize=None)
def _row_checker(kind: type) -> Callable[[tuple], str | None]:
    """A check of one stored row of ``kind`` as read (a tuple in field order): None, or what is wrong with it
    (a value of the wrong type, a NULL where a value is required, malformed JSON, a
    confusion matrix that is not square). Rows are written by grail-bench; this finds hand-edited ones."""
    hints = get_type_hints(kind)
    checks = []
    for f in fields(kind):
        hint = hints[f.name]
        optional = type(None) in get_args(hint)
        base = next((a for a in get_args(hint) if a is not type(None)), hint) if optional else hint
        want = {int: (int,), float: (int, float), str: (str,)}.get(base)
        checks.append((f.name, optional, want))

    def check(values: tuple) -> str | None:
        for (name, optional, want), value in zip(checks, values):
            if value is None:
                if not optional:
                    return f"{name} is NULL"
                continue
            if want == (int,) and isinstance(value, float) and value.is_integer():
                continue  # a count in a column SQLite typed REAL (a mode's own column)
            if want is not None and (isinstance(value, bool) or not isinstance(value, want)):
                return f"{name} is {value!r}, not {'a number' if want != (str,) else 'text'}"
            if name in _JSON_WHOLE and not (value[:1], value[-1:]) in (("{", "}"), ("[", "]")):
                return f"{name} is not valid JSON"
            if name in _JSON:
                try:
                    parsed = json.loads(value)
                except ValueError:
                    return f"{name} is not valid JSON"
                if name == "confusion" and not _square(parsed):
                    return "confusion is not a square matrix of numbers"
        return None

    return check


def _square(matrix: Any) -> bool:
    """Whether ``matrix`` (as JSON reads it) is a non-empty square list of lists of numbers."""
    if not isinstance(matrix, list) or not matrix:
        return False
    n = len(matrix)
    if not all(isinstance(row, list) and len(row) == n for row in matrix):
        return False
    return {type(v) for row in matrix for v in row} <= _NUMBERS  # one set per matrix: every stored row is checked


_NUMBERS = frozenset({int, float})  # JSON's numbers (a bool is neither)


def _insert(kind: type, table: str, key: tuple[str, ...], replace: bool = False) -> str:
    """The statement storing one row of ``kind``: ignored if its key is stored, unless the stored row is stale
    (``replace``: it replaces the stored row of its key)."""
    names = [_column(f.name) for f in fields(kind)]
    head = f"INTO {table} ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})"
    if replace:
        return f"INSERT OR REPLACE {head}"
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
            raise StoreError(_sqlite_message("write to", str(file), exc)) from None
    return file


def _sqlite_message(doing: str, path: str, exc: sqlite3.Error) -> str:
    """One line for an SQLite error on the store at ``path`` (a full disk said as such: SQLite reports one as
    "database or disk is full", or, failing to grow its WAL index, as "disk I/O error")."""
    code = getattr(exc, "sqlite_errorcode", None) or 0
    if code == sqlite3.SQLITE_FULL or (code & 0xFF == sqlite3.SQLITE_IOERR and _disk_full(Path(path))):
        return f"no space left on device writing {path}"
    return f"cannot {doing} results store {path}: {exc}"


def _disk_full(file: Path) -> bool:
    """Whether the disk holding ``file`` has (next to) no room left."""
    try:
        return shutil.disk_usage(file.expanduser().absolute().parent).free < 1 << 20
    except OSError:
        return False


def _create_store(file: Path) -> None:
    """Create an empty store at ``file`` whole: built under a temporary name beside it and moved into place only
    if no other process created one meanwhile (an empty file there is replaced)."""

    def build(tmp: Path) -> None:
        conn = sqlite3.connect(tmp)
        try:
            migrate(conn, set(), 0)
        except sqlite3.Error as exc:
            if getattr(exc, "sqlite_errorcode", None) == sqlite3.SQLITE_FULL:
                raise OSError(errno.ENOSPC, "No space left on device") from None
            raise OSError(errno.EIO, str(exc)) from None
        finally:
            conn.close()

    def place(tmp: Path) -> None:
        build(tmp)
        if file.exists() and file.stat().st_size:
            return  # another process created it: keep theirs (write_with replaces it with itself, below)
        try:
            os.link(tmp, file)  # atomic, and never over a store created meanwhile
        except FileExistsError:
            if file.stat().st_size == 0:
                os.replace(tmp, file)
        except OSError:  # a file system without hard links
            os.replace(tmp, file)

    try:
        with temporary_folder(file) as folder:
            place(folder / file.name)
    except WriteError as exc:
        raise StoreError(str(exc)) from None


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
    transaction; a store normalised by it (schema 10 or older -> 11, see the
    module docstring) is then vacuumed, returning the space the repeated JSON
    took.  Schema 11 -> 12 (:data:`MODE_OUTPUTS`, :func:`_add_mode_outputs`)
    adds the tables of the other modes' per-instance outputs.

    Args:
        conn: The store's connection (no transaction open).
        tables: The tables the store had when opened (empty: a new store).
        version: Its ``PRAGMA user_version`` when opened.
        normalise: Move the rows' shared JSON into the shared tables (schema 11).

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
        if tables and version < MODE_OUTPUTS:
            _add_mode_outputs(conn)
        for kind, (table, key) in _tables().items():
            conn.execute(_create(kind, table, key))
        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    if normalised and conn.execute("PRAGMA database_list").fetchone()[2]:  # a file, not memory
        conn.execute("VACUUM")
    return normalised


def _normalise(conn: sqlite3.Connection) -> bool:
    """Schema 10 -> 11: each row table's ``config``, ``versions`` and ``provenance`` JSON moves into the shared
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


def _add_mode_outputs(conn: sqlite3.Connection) -> None:
    """Schema 11 -> 12 (:data:`MODE_OUTPUTS`): the tables of the online, open-set and zero-shot rows' per-instance
    outputs, empty (rows stored before have none); every row is kept as it is."""
    for kind in OUTPUT_KINDS.values():
        if kind.name != outputs.TABLE:
            conn.execute(_create(kind.row, kind.name, kind.key))


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
    table's ``adapt_seconds_per_goal`` and ``score_us_per_observation``; schema 10 ``task_fingerprint`` in every
    mode's table; schema 11 ``source`` in every mode's table. (Schema 5 added tables, and schema 6
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
