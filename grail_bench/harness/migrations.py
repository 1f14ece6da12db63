"""Migrations of the results store: an older store's schema (:mod:`grail_bench.harness.schema`) brought up to date.

:func:`migrate` is the one place a store's file is changed for its schema, in
one transaction, keeping every row: schema 1 -> 2 renames a column
(:func:`_migrate_v1`); later schemas add columns, NULL for the rows already
stored (:func:`_add_missing_columns`); schema 10 -> 11 moves the JSON
many rows share into the shared tables (:func:`_normalise`); schema 11 -> 12
adds the tables of the online, open-set and zero-shot rows' per-instance
outputs (:func:`_add_mode_outputs`). The store
(:class:`~grail_bench.harness.store.ResultsStore`) migrates a file only when a
command writes to it; a command that only reads reads an older store as it is,
or a copy upgraded in memory.
"""

from __future__ import annotations

import sqlite3
from dataclasses import fields

from grail_bench.harness import outputs
from grail_bench.harness.outputs import KINDS as OUTPUT_KINDS
from grail_bench.harness.schema import (
    COLUMN_TYPES,
    MODE_OUTPUTS,
    NORMALISED,
    SCHEMA_VERSION,
    SHARED,
    column_of,
    create_statement,
    ref,
    row_tables,
)

__all__ = ["migrate"]


def migrate(conn: sqlite3.Connection, tables: set[str], version: int, normalise: bool = True) -> bool:
    """Bring an opened store's schema up to date: migrate an older one and create the missing tables.

    The one place a store's file is changed for its schema: call it only for a
    command that will write (a reading one reads the store as it is, or a copy
    upgraded in memory with ``normalise=False``). The migration is one
    transaction; a store normalised by it (schema 10 or older -> 11, see
    :mod:`grail_bench.harness.schema`) is then vacuumed, returning the space the repeated JSON
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
        for kind, (table, key) in row_tables().items():
            conn.execute(create_statement(kind, table, key))
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
    for kind, (table, key) in row_tables().items():
        columns = [r[1] for r in conn.execute(f"PRAGMA table_info({table})")]
        inline = [c for c in columns if c in SHARED]
        if not inline:
            continue
        for name in inline:
            conn.execute(f"INSERT OR IGNORE INTO {SHARED[name]} (hash, json) SELECT grail_ref(v), v FROM "
                         f"(SELECT DISTINCT {name} AS v FROM {table} WHERE {name} IS NOT NULL)")
        conn.execute(f"ALTER TABLE {table} RENAME TO {table}__inline")
        conn.execute(create_statement(kind, table, key))
        target = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
        kept = [c for c in columns if column_of(c) in target]
        conn.execute(f"INSERT INTO {table} ({', '.join(column_of(c) for c in kept)}) SELECT "
                     f"{', '.join(f'grail_ref({c})' if c in SHARED else c for c in kept)} FROM {table}__inline")
        conn.execute(f"DROP TABLE {table}__inline")
        changed = True
    return changed


def _add_mode_outputs(conn: sqlite3.Connection) -> None:
    """Schema 11 -> 12 (:data:`MODE_OUTPUTS`): the tables of the online, open-set and zero-shot rows' per-instance
    outputs, empty (rows stored before have none); every row is kept as it is."""
    for kind in OUTPUT_KINDS.values():
        if kind.name != outputs.TABLE:
            conn.execute(create_statement(kind.row, kind.name, kind.key))


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
    for kind, (table, _) in row_tables().items():
        columns = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
        if not columns:  # not there yet: created whole
            continue
        normalised = any(column_of(name) in columns for name in SHARED)
        for f in fields(kind):
            column = column_of(f.name) if normalised else f.name
            if column not in columns:
                conn.execute(f"ALTER TABLE {table} ADD COLUMN {column} {COLUMN_TYPES.get(f.name, 'REAL')}")
