"""The results store: an embedded SQLite database, the only code that touches it.

Three tables, one per kind of run: ``results`` (the paper's protocol), one
:class:`ResultRow` per (task, recognizer, scorer, config hash, seed,
observability, observation protocol); ``online`` (every prefix scored), one
:class:`OnlineRow` per (task, recognizer, scorer, config hash, seed, protocol);
``open_set`` (a goal held out), one :class:`OpenSetRow` per (task, recognizer,
scorer, config hash, seed, observability, protocol). Rows are written in one transaction per fitted seed with
``INSERT OR IGNORE``, in WAL mode with a busy timeout, so an interrupted run
keeps what it finished and concurrent writers lose nothing.

Default location: ``$GRAIL_BENCH_STORE``, else
``$XDG_DATA_HOME/grail-bench/results.sqlite`` (``~/.local/share/...``).
"""

from __future__ import annotations

import json
import os
import sqlite3
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Iterable, Sequence

from grail_bench.errors import UserError

SCHEMA_VERSION = 5
KEY = ("task", "recognizer", "scorer", "config_hash", "seed", "observability", "protocol")
ONLINE_KEY = ("task", "recognizer", "scorer", "config_hash", "seed", "protocol")


class StoreError(UserError):
    """The store cannot be opened, read or written."""


@dataclass(frozen=True)
class _Run:
    """What every row is about: one recognizer (its scorer and configuration) on one task and seed."""

    task: str
    recognizer: str
    scorer: str
    config_hash: str
    seed: int


@dataclass(frozen=True)
class ResultRow(_Run):
    """Metrics of one recognizer on one task, seed and observability level."""

    observability: float
    protocol: str
    accuracy: float
    precision: float
    recall: float
    f1: float
    n_observations: int
    n_ties: int
    fit_seconds_per_goal: float
    score_us_per_observation: float
    config: str
    versions: str
    brier: float | None = None
    nll: float | None = None
    provenance: str | None = None  # JSON of grail_bench.provenance.stamp(); None for rows stored before it
    top2: float | None = None  # share of observations whose true goal ranks in the top 2 (None: stored before)
    mean_rank: float | None = None  # mean rank of the true goal, 1 = best (None: stored before)


@dataclass(frozen=True)
class OnlineRow(_Run):
    """Online recognition of one recognizer on one task and seed: every prefix of every test observation scored.

    Per test trajectory the harness records the convergence point (the
    observed fraction from which the prediction stays correct; 1.0 when it is
    not correct at the end) and the share of prefixes predicted correctly;
    the row holds their means over trajectories.
    """

    protocol: str
    n_trajectories: int
    convergence: float  # mean convergence point, a fraction of the observation (1.0 for never)
    never: float  # share of trajectories whose prediction is wrong after the last step
    step_accuracy: float  # mean share of prefixes predicted correctly
    f1_auc: float  # area under macro F1 against the observed fraction, over all prefixes
    curve: str  # JSON: {"fractions": [...], "accuracy": [...], "f1": [...]} on a fixed grid
    fit_seconds_per_goal: float
    score_us_per_prefix: float
    config: str
    versions: str
    provenance: str | None = None


@dataclass(frozen=True)
class OpenSetRow(_Run):
    """Open-set recognition of one recognizer on one task, seed and level: one goal held out of the fit.

    Observations of the held-out goal should be answered "none of these";
    the decision rule was calibrated on the training demonstrations only.
    """

    observability: float
    protocol: str
    held_out: str  # JSON list: the goal the recognizer was not fitted on
    auroc: float  # known versus unknown, ranking observations by their best score
    f1: float  # macro F1 over the known goals and the extra class "none of these"
    accuracy: float
    unknown_recall: float  # share of the held-out goal's observations answered "none of these"
    false_alarm: float  # share of known goals' observations answered "none of these"
    threshold: float  # the calibrated rule's threshold on the best score
    n_observations: int
    fit_seconds_per_goal: float
    config: str
    versions: str
    provenance: str | None = None


Row = ResultRow | OnlineRow | OpenSetRow
TABLES: dict[type, tuple[str, tuple[str, ...]]] = {  # row type -> (table, primary key)
    ResultRow: ("results", KEY), OnlineRow: ("online", ONLINE_KEY), OpenSetRow: ("open_set", KEY),
}
_COLUMNS = [f.name for f in fields(ResultRow)]
_TYPES = {"task": "TEXT", "recognizer": "TEXT", "scorer": "TEXT", "config_hash": "TEXT", "seed": "INTEGER",
          "observability": "REAL", "protocol": "TEXT", "n_observations": "INTEGER", "n_ties": "INTEGER",
          "config": "TEXT", "versions": "TEXT", "provenance": "TEXT", "n_trajectories": "INTEGER",
          "curve": "TEXT", "held_out": "TEXT"}


def _create(kind: type) -> str:
    table, key = TABLES[kind]
    return (f"CREATE TABLE IF NOT EXISTS {table} ("
            + ", ".join(f"{f.name} {_TYPES.get(f.name, 'REAL')}" + (" NOT NULL" if f.name in key else "")
                        for f in fields(kind))
            + ", created_at TEXT NOT NULL DEFAULT (datetime('now'))"
            + f", PRIMARY KEY ({', '.join(key)}))")


def default_store_path() -> Path:
    """Where results go unless ``--store`` or ``GRAIL_BENCH_STORE`` says otherwise."""
    from grail_bench.paths import data_dir

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
            with self._conn:
                if tables and version < 2:
                    _migrate_v1(self._conn)
                if tables and version < SCHEMA_VERSION:
                    _add_missing_columns(self._conn)
                for kind in TABLES:
                    self._conn.execute(_create(kind))
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
                for kind, values in by_kind.items():
                    names = [f.name for f in fields(kind)]
                    self._conn.executemany(f"INSERT OR IGNORE INTO {TABLES[kind][0]} ({', '.join(names)}) "
                                           f"VALUES ({', '.join('?' * len(names))})", values)
                return self._conn.total_changes - before
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write to results store {self.path}: {exc}") from None

    def rows(self, **where: Any) -> list[ResultRow]:
        """Stored :class:`ResultRow` rows, optionally filtered by column equality (a list means any of)."""
        return self.select(ResultRow, **where)

    def select(self, kind: type[Row], **where: Any) -> list[Any]:
        """Stored rows of one kind (:data:`TABLES`), optionally filtered by column equality (a list means any of)."""
        columns = [f.name for f in fields(kind)]
        clauses, params = [], []
        for column, value in where.items():
            if column not in columns:
                raise ValueError(f"unknown column {column!r}")
            values = list(value) if isinstance(value, (list, tuple, set)) else [value]
            clauses.append(f"{column} IN ({', '.join('?' * len(values))})")
            params += values
        sql = f"SELECT {', '.join(columns)} FROM {TABLES[kind][0]}"
        if clauses:
            sql += " WHERE " + " AND ".join(clauses)
        sql += " ORDER BY task, recognizer, scorer, " + ("observability, " if "observability" in columns else "") + "seed"
        try:
            return [kind(*r) for r in self._conn.execute(sql, params)]
        except sqlite3.Error as exc:
            raise StoreError(f"cannot read results store {self.path}: {exc}") from None

    def completed(self, task: str, recognizer: str, scorer: str, config_hash: str, protocol: str,
                  kind: type[Row] = ResultRow) -> set[tuple[int, float | None]]:
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
    """Schema 2 -> 3 -> 4: the columns added since (``provenance``; ``top2``, ``mean_rank``), empty for the rows
    already stored. (Schema 5 only adds tables.)"""
    columns = {r[1] for r in conn.execute("PRAGMA table_info(results)")}
    for name in _COLUMNS:
        if name not in columns:
            conn.execute(f"ALTER TABLE results ADD COLUMN {name} {_TYPES.get(name, 'REAL')}")


def config_hash(payload: dict[str, Any]) -> str:
    """Short, stable hash of a JSON-able configuration (no git state involved)."""
    import hashlib

    text = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def package_versions(names: Sequence[str] = ("grail-bench", "gymnasium", "stable-baselines3", "imitation",
                                              "minigrid", "torch", "numpy")) -> str:
    """JSON of the installed versions of the packages that shape a result."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return json.dumps(out, sort_keys=True)
