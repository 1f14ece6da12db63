"""The results store's schema: its tables, the SQL creating and filling them, and the check of a row as read.

One table per mode (:data:`grail_bench.harness.modes.MODES`), named and keyed
by the mode, and one of fit diagnostics (``fits``, one
:class:`~grail_bench.harness.diagnostics.FitRow` per task, recognizer, config
hash, seed and mode): ``results`` (offline, the paper's protocol), one
:class:`~grail_bench.harness.modes.ResultRow` per (task, recognizer, scorer, config hash, seed,
observability, observation protocol); ``online`` (every prefix scored), one
:class:`~grail_bench.harness.modes.OnlineRow` per (task, recognizer, scorer, config hash, seed, protocol);
``open_set`` (a goal held out), one :class:`~grail_bench.harness.modes.OpenSetRow` per (task, recognizer,
scorer, config hash, seed, observability, protocol); ``zero_shot`` (goals never
fitted), one :class:`~grail_bench.harness.modes.ZeroShotRow` per the same key; and the per-instance outputs
of the rows (:mod:`grail_bench.harness.outputs`), one output row per row run
since, keyed like it: ``outputs`` (offline, schema 11), ``online_outputs``,
``open_set_outputs`` and ``zero_shot_outputs`` (schema 12, :data:`MODE_OUTPUTS`). A row
already stored is kept (the first write wins, :func:`insert_statement`) unless it is stale.

Stale rows. Rows of every mode record how ties between goals of equal best
score were broken (``ties``: ``"uniform"``, the expectation under uniform
tie-breaking, :data:`grail_bench.stats.metrics.TIE_RULE`) and how many
observations (online: prefixes) tied (``n_ties``). Rows stored before schema 8
have ``ties`` NULL: they gave the prediction to the lowest-index tied goal. One
that counted no tie (``n_ties = 0``, offline rows) reads the same under both
rules and stays valid. One that tied (``n_ties > 0``), or whose mode did not
count ties (online, open-set and zero-shot rows before schema 8: any of them
may have tied), is stale: :meth:`~grail_bench.harness.store.ResultsStore.completed` leaves it out, so the
next ``run`` or ``reproduce`` recomputes it, and :meth:`~grail_bench.harness.store.ResultsStore.add`
replaces it with the new row of the same key.

Shared tables (schema 11). What many rows share is stored once, keyed by the
SHA-256 of its JSON text (:func:`ref`): a row's recognizer configuration in
``configs``, its package versions in ``versions`` and its provenance in
``provenance``, and the submission a merged row came from in ``sources``
(:data:`SHARED`); the row holds the metrics and the references
(``config_ref``, ``versions_ref``, ``provenance_ref``, ``source_ref``). Rows
read and written through :class:`~grail_bench.harness.store.ResultsStore` carry the JSON as before. A
store of an older schema is normalised by :func:`grail_bench.harness.migrations.migrate` when a command opens
it to write; a command that only reads reads it as it is.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import fields
from functools import lru_cache
from typing import Any, Callable, get_args, get_type_hints

from grail_bench.harness import diagnostics
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES, Row
from grail_bench.harness.outputs import KINDS as OUTPUT_KINDS

__all__ = ["COLUMN_TYPES", "MODE_OUTPUTS", "NORMALISED", "SCHEMA_VERSION", "SHARED", "column_of", "create_statement",
           "insert_statement", "ref", "row_checker", "row_tables", "stale"]

#: The schema this version writes (the store's ``PRAGMA user_version``).
SCHEMA_VERSION = 12
#: The first schema whose row tables reference the shared tables (:data:`SHARED`) instead of repeating the JSON.
NORMALISED = 11
#: The first schema keeping the per-instance outputs of the online, open-set and zero-shot rows (their tables).
MODE_OUTPUTS = 12

#: Row field -> the SQL type of its column (REAL unless named here).
COLUMN_TYPES = {"task": "TEXT", "recognizer": "TEXT", "scorer": "TEXT", "config_hash": "TEXT", "seed": "INTEGER",
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


def column_of(name: str) -> str:
    """The column of a row field in a normalised table."""
    return f"{name}_ref" if name in SHARED else name


def row_tables() -> dict[type, tuple[str, tuple[str, ...]]]:
    """Row type -> (table, primary key): every mode's, and the fit diagnostics'."""
    out = {mode.row: (mode.table, mode.key) for mode in MODES.values()}
    out[FitRow] = (diagnostics.TABLE, diagnostics.KEY)
    out |= {kind.row: (kind.name, kind.key) for kind in OUTPUT_KINDS.values()}
    return out


def create_statement(kind: type, table: str, key: tuple[str, ...]) -> str:
    """The statement creating a (normalised) row table of ``kind``."""
    return (f"CREATE TABLE IF NOT EXISTS {table} ("
            + ", ".join(f"{column_of(f.name)} {COLUMN_TYPES.get(f.name, 'REAL')}"
                        + (" NOT NULL" if f.name in key else "") for f in fields(kind))
            + ", created_at TEXT NOT NULL DEFAULT (datetime('now'))"
            + f", PRIMARY KEY ({', '.join(key)}))")


#: Columns holding JSON text: parsed when read (their readers index into them), or only checked to be whole
#: (bracketed: a truncated text is not) where parsing every row would slow reading a large store.
_JSON = frozenset({"curve", "held_out", "confusion"})
_JSON_WHOLE = frozenset({"config", "versions", "provenance", "reliability", "diagnostics"})


@lru_cache(maxsize=None)
def row_checker(kind: type) -> Callable[[tuple], str | None]:
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


def insert_statement(kind: type, table: str, key: tuple[str, ...], replace: bool = False) -> str:
    """The statement storing one row of ``kind``: ignored if its key is stored, unless the stored row is stale
    (``replace``: it replaces the stored row of its key)."""
    names = [column_of(f.name) for f in fields(kind)]
    head = f"INTO {table} ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})"
    if replace:
        return f"INSERT OR REPLACE {head}"
    if "ties" not in names:
        return f"INSERT OR IGNORE {head}"
    update = ", ".join(f"{n} = excluded.{n}" for n in names if n not in key)
    return (f"INSERT {head} ON CONFLICT ({', '.join(key)}) DO UPDATE SET {update}, created_at = datetime('now') "
            f"WHERE {_STALE.format(t=table)}")
