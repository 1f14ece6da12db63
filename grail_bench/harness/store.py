"""The results store: an embedded SQLite database, the only code that touches it.

The store is four modules, one job each; their public names are importable from this one too:

* this module: :class:`ResultsStore`, which opens, creates, reads and writes a
  store file, and what a command checks before any work
  (:func:`check_store_writable`, :func:`default_store_path`);
* :mod:`grail_bench.harness.schema`: the tables (one per mode, the fit
  diagnostics, the per-instance outputs and the JSON many rows share), the SQL
  that creates and fills them, stale rows, and the check of a row as read;
* :mod:`grail_bench.harness.migrations`: an older store's schema brought up to
  date (:func:`~grail_bench.harness.migrations.migrate`);
* :mod:`grail_bench.harness.ceiling_cache`: the Bayes ceilings cached beside the
  rows (:class:`~grail_bench.harness.ceiling_cache.CeilingCache`).

Rows are written in one transaction per fitted seed, in WAL mode with a busy timeout, so an
interrupted run keeps what it finished and concurrent writers lose nothing; a
row already stored is kept (the first write wins), unless it is stale (:func:`~grail_bench.harness.schema.stale`)
or the run recomputes it on purpose (``run --rerun``: its new rows replace the stored ones of their keys in one
transaction). Rows read and written through this module carry the JSON the file holds once in its shared tables.
A store of an older schema is migrated when a command opens it to write; a command that only reads reads it as
it is.

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
import os
import shutil
import sqlite3
from dataclasses import asdict, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable

from grail_bench.core.atomic import WriteError, temporary_folder, write_error
from grail_bench.core.errors import UserError
from grail_bench.core.paths import check_writable, data_dir
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.migrations import migrate
from grail_bench.harness.modes import Mode, OnlineRow, OpenSetRow, ResultRow, Row, ZeroShotRow
from grail_bench.harness.outputs import KINDS as OUTPUT_KINDS
from grail_bench.harness.outputs import OutputRow
from grail_bench.harness.planning import task_params
from grail_bench.harness.schema import (
    MODE_OUTPUTS,
    NORMALISED,
    SCHEMA_VERSION,
    SHARED,
    column_of,
    insert_statement,
    ref,
    row_checker,
    row_tables,
    stale,
)
from grail_bench.task import versions

if TYPE_CHECKING:  # imported on first use (__getattr__, below): that module builds on this one
    from grail_bench.harness.ceiling_cache import CeilingCache

__all__ = ["MODE_OUTPUTS", "NORMALISED", "SCHEMA_VERSION", "SHARED", "CeilingCache", "FitRow", "OnlineRow", "OpenSetRow", "OutputRow",
           "ResultRow", "ResultsStore", "Row", "StoreError", "ZeroShotRow", "check_store_writable",
           "default_store_path", "migrate", "ref", "stale"]
_HEADER = b"SQLite format 3\x00"  # the first 16 bytes of every SQLite database file
_SIDECARS = ("-wal", "-journal")  # present while a connection has the store open (or after a crash)


class StoreError(UserError):
    """The store cannot be opened, read or written."""


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
                self._conn = connect_read_only(Path(self.path).expanduser())
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
        missing = {table for table, _ in row_tables().values()} - tables
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
            if version < SCHEMA_VERSION or {table for table, _ in row_tables().values()} - tables:
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
        for table, _ in row_tables().values():
            columns = {r[1] for r in self._conn.execute(f"PRAGMA table_info({table})")}
            self._refs[table] = {name for name in SHARED if column_of(name) in columns}
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
                tables = row_tables()
                for kind, values in by_kind.items():
                    self._conn.executemany(insert_statement(kind, *tables[kind], replace=replace), values)
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
        table = row_tables()[kind][0]
        columns = [f.name for f in fields(kind)]
        refs, present = self._refs[table], self._columns[table]
        if not present:  # a table added since the store was written (read as it is): no rows
            return []
        # A field the file has no column for (a store of an older schema, read as it is) reads as NULL.
        expression = {c: f"{SHARED[c]}.json" if c in refs else f"t.{c}" if c in present else "NULL" for c in columns}
        joins = "".join(f" LEFT JOIN {SHARED[c]} ON {SHARED[c]}.hash = t.{column_of(c)}" for c in columns if c in refs)
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
        check = row_checker(kind)
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


def connect_read_only(file: Path) -> sqlite3.Connection:
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


def __getattr__(name: str) -> Any:
    """:class:`~grail_bench.harness.ceiling_cache.CeilingCache`, importable from here as before."""
    if name == "CeilingCache":
        from grail_bench.harness.ceiling_cache import CeilingCache

        return CeilingCache
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
