"""The SQLite results store: idempotent writes, concurrency, corrupt files."""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import sqlite3

import pytest

from grail_bench.harness.store import ResultRow, ResultsStore, StoreError, default_store_path


def row(seed: int = 0, observability: float = 0.1, f1: float = 0.5, recognizer: str = "bc") -> ResultRow:
    return ResultRow(task="GRAIL/T-v0", recognizer=recognizer, scorer="mse", config_hash="abc", seed=seed,
                     observability=observability, protocol="prefix", accuracy=f1, precision=f1, recall=f1, f1=f1,
                     n_observations=6, n_ties=0, fit_seconds_per_goal=0.1, score_us_per_observation=10.0,
                     config="{}", versions="{}")


def test_add_is_idempotent_and_first_write_wins(tmp_path):
    with ResultsStore(tmp_path / "r.sqlite") as store:
        assert store.add([row(0), row(1)]) == 2
        assert store.add([row(1, f1=0.9), row(2)]) == 1
        assert [(r.seed, r.f1) for r in store.rows()] == [(0, 0.5), (1, 0.5), (2, 0.5)]
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix") == {(0, 0.1), (1, 0.1), (2, 0.1)}


def test_rows_survive_reopening(tmp_path):
    path = tmp_path / "sub" / "r.sqlite"
    with ResultsStore(path) as store:
        store.add([row(0)])
    with ResultsStore(path) as store:
        assert len(store.rows()) == 1


def test_reading_leaves_the_file_as_it_was(tmp_path):
    """A published store is committed: a command that only reads it (a leaderboard) must not change its bytes."""
    path = tmp_path / "r.sqlite"
    with ResultsStore(path) as store:
        store.add([row(0)])
    before = path.read_bytes()
    with ResultsStore(path) as store:
        assert len(store.rows()) == 1
    assert path.read_bytes() == before


def _writer(path: str, offset: int) -> None:
    with ResultsStore(path) as store:
        for i in range(60):
            store.add([row(seed=offset + i, observability=o) for o in (0.1, 0.2)])


def test_concurrent_writers_lose_nothing(tmp_path):
    path = str(tmp_path / "r.sqlite")
    ResultsStore(path).close()
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(path, k * 1000)) for k in range(3)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=120)
        assert p.exitcode == 0
    with ResultsStore(path) as store:
        assert len(store.rows()) == 3 * 60 * 2


def test_corrupt_file_is_reported_and_left_alone(tmp_path):
    path = tmp_path / "r.sqlite"
    path.write_bytes(b"this is not a database, but it is somebody's file" * 100)
    before = path.read_bytes()
    with pytest.raises(StoreError, match="cannot use results store"):
        ResultsStore(path)
    assert path.read_bytes() == before


def test_foreign_sqlite_file_is_rejected(tmp_path):
    path = tmp_path / "other.sqlite"
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE notes (x TEXT)")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="not a grail-bench results store"):
        ResultsStore(path)


def test_default_location(monkeypatch, tmp_path):
    monkeypatch.setenv("GRAIL_BENCH_STORE", str(tmp_path / "x.sqlite"))
    assert default_store_path() == tmp_path / "x.sqlite"
    monkeypatch.delenv("GRAIL_BENCH_STORE")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    assert default_store_path() == tmp_path / "grail-bench" / "results.sqlite"


def test_schema_2_store_gains_provenance_and_keeps_rows(tmp_path):
    path = tmp_path / "v2.sqlite"
    with ResultsStore(path) as store:
        store.add([row(seed=s) for s in range(3)])
    conn = sqlite3.connect(path)  # make it a schema-2 file: no provenance column
    conn.execute("ALTER TABLE results DROP COLUMN provenance")
    conn.execute("PRAGMA user_version = 2")
    conn.commit()
    conn.close()
    with ResultsStore(path) as store:
        rows = store.rows()
        assert len(rows) == 3 and all(r.provenance is None for r in rows)
        store.add([dataclasses.replace(row(seed=9), provenance='{"command": ["grail-bench"]}')])
        assert store.rows(seed=9)[0].provenance == '{"command": ["grail-bench"]}'


def test_schema_4_store_gains_the_online_and_open_set_tables(tmp_path):
    from grail_bench.harness.store import OnlineRow, OpenSetRow

    path = tmp_path / "v4.sqlite"
    with ResultsStore(path) as store:
        store.add([row(seed=s) for s in range(2)])
    conn = sqlite3.connect(path)  # make it a schema-4 file: one table
    conn.execute("DROP TABLE online")
    conn.execute("DROP TABLE open_set")
    conn.execute("PRAGMA user_version = 4")
    conn.commit()
    conn.close()
    online = OnlineRow(task="GRAIL/T-v0", recognizer="bc", scorer="mse", config_hash="abc", seed=0, protocol="prefix",
                       n_trajectories=6, convergence=0.5, never=0.0, step_accuracy=0.7, f1_auc=0.6, curve="{}",
                       fit_seconds_per_goal=0.1, score_us_per_prefix=1.0, config="{}", versions="{}")
    with ResultsStore(path) as store:
        assert len(store.rows()) == 2 and store.select(OnlineRow) == [] and store.select(OpenSetRow) == []
        assert store.add([online, row(seed=5)]) == 2  # one transaction, each row into its own table
        assert store.select(OnlineRow) == [online] and len(store.rows()) == 3
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix", OnlineRow) == {(0, None)}
