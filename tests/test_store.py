"""The SQLite results store: idempotent writes, concurrency, corrupt files, read-only opening, write checks."""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import sqlite3
from pathlib import Path

import pytest
from conftest import chmod_stops_writes

from grail_bench.harness.store import (
    SCHEMA_VERSION,
    ResultRow,
    ResultsStore,
    StoreError,
    check_store_writable,
    default_store_path,
)


def row(seed: int = 0, observability: float = 0.1, f1: float = 0.5, recognizer: str = "bc") -> ResultRow:
    return ResultRow(task="GRAIL/T-v0", recognizer=recognizer, scorer="mse", config_hash="abc", seed=seed,
                     observability=observability, protocol="prefix", accuracy=f1, precision=f1, recall=f1, f1=f1,
                     n_observations=6, n_ties=0, fit_seconds_per_goal=0.1, score_us_per_observation=10.0,
                     config="{}", versions="{}")


def inline(conn: sqlite3.Connection) -> None:
    """Make a store's row tables hold their configuration, versions and provenance JSON in every row (schema 9)."""
    from grail_bench.harness.store import SHARED

    tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
    for table in tables:
        columns = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
        for name, shared in SHARED.items():
            if f"{name}_ref" in columns:
                conn.execute(f"ALTER TABLE {table} ADD COLUMN {name} TEXT")
                conn.execute(f"UPDATE {table} SET {name} = (SELECT json FROM {shared} WHERE hash = {name}_ref)")
                conn.execute(f"ALTER TABLE {table} DROP COLUMN {name}_ref")
    for shared in SHARED.values():
        conn.execute(f"DROP TABLE IF EXISTS {shared}")
    for table in ("outputs", "online_outputs", "open_set_outputs", "zero_shot_outputs"):  # added by schemas 11, 12
        conn.execute(f"DROP TABLE IF EXISTS {table}")


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
    with ResultsStore(path) as store:
        store.create()
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
    with pytest.raises(StoreError, match="is not a grail-bench results store"):
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
    inline(conn)
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


# --- reading without writing ----------------------------------------------------------------------------------


def snapshot(folder: Path) -> dict[str, tuple[bytes, int] | None]:
    """Everything under ``folder``: each file's bytes and modification time (ns), each folder as ``None``."""
    return {str(f.relative_to(folder)): None if f.is_dir() else (f.read_bytes(), f.stat().st_mtime_ns)
            for f in sorted(folder.rglob("*"))}


def stored(folder: Path, rows: int = 2) -> Path:
    """A closed store of ``rows`` rows in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "r.sqlite"
    with ResultsStore(path) as store:
        store.add([row(seed=s) for s in range(rows)])
    return path


def test_read_only_store_reads_and_leaves_every_file_as_it_was(tmp_path):
    path = stored(tmp_path / "pub")
    before = snapshot(path.parent)
    with ResultsStore(path, read_only=True) as store:
        assert [r.seed for r in store.rows()] == [0, 1]
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix") == {(0, 0.1), (1, 0.1)}
        with pytest.raises(StoreError, match="read-only"):
            store.add([row(seed=7)])
    assert snapshot(path.parent) == before  # no -wal, -shm or -journal left beside it, bytes and mtime as they were


def test_read_only_folder_and_file_are_readable(tmp_path):
    """chmod does not stop root, so what is checked is that nothing at all is written: same files, bytes, mtimes."""
    path = stored(tmp_path / "ro")
    os.chmod(path, 0o444)
    os.chmod(path.parent, 0o555)
    try:
        before = snapshot(path.parent)
        with ResultsStore(path, read_only=True) as store:
            assert len(store.rows()) == 2
        assert snapshot(path.parent) == before
    finally:
        os.chmod(path.parent, 0o755)


def test_read_only_sees_the_rows_of_a_store_being_written(tmp_path):
    path = stored(tmp_path)
    with ResultsStore(path) as writer:  # open: its -wal holds rows not yet in the main file
        writer.add([row(seed=5)])
        with ResultsStore(path, read_only=True) as reader:
            assert [r.seed for r in reader.rows()] == [0, 1, 5]
        writer.add([row(seed=6)])
    with ResultsStore(path, read_only=True) as reader:
        assert [r.seed for r in reader.rows()] == [0, 1, 5, 6]


def test_read_only_old_schema_is_upgraded_in_memory_only(tmp_path):
    path = stored(tmp_path)
    conn = sqlite3.connect(path)  # a schema-2 file: no provenance column, no other tables
    inline(conn)
    conn.execute("ALTER TABLE results DROP COLUMN provenance")
    for table in ("online", "open_set", "zero_shot", "fits"):
        conn.execute(f"DROP TABLE IF EXISTS {table}")
    conn.execute("PRAGMA user_version = 2")
    conn.commit()
    conn.close()
    before = snapshot(tmp_path)
    from grail_bench.harness.store import OnlineRow

    with ResultsStore(path, read_only=True) as store:
        assert len(store.rows()) == 2 and all(r.provenance is None for r in store.rows())
        assert store.select(OnlineRow) == []
    assert snapshot(tmp_path) == before
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == 2


@pytest.mark.parametrize("content", [b"", b"not a database" * 100, None], ids=["empty", "garbage", "folder"])
def test_read_only_refuses_what_is_not_a_store_and_leaves_it(tmp_path, content):
    path = tmp_path / "r.sqlite"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    before = snapshot(tmp_path)
    with pytest.raises(StoreError, match="not a grail-bench results store"):
        ResultsStore(path, read_only=True)
    assert snapshot(tmp_path) == before


def test_read_only_refuses_a_foreign_sqlite_file_and_a_missing_one(tmp_path):
    path = tmp_path / "other.sqlite"
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE notes (x TEXT)")
    conn.commit()
    conn.close()
    before = snapshot(tmp_path)
    with pytest.raises(StoreError, match="an SQLite file but not a grail-bench results store"):
        ResultsStore(path, read_only=True)
    with pytest.raises(StoreError, match="no results store at"):
        ResultsStore(tmp_path / "missing.sqlite", read_only=True)
    assert snapshot(tmp_path) == before


def newer(path: Path) -> Path:
    conn = sqlite3.connect(path)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.commit()
    conn.close()
    return path


def test_newer_schema_is_refused_either_way_and_left_alone(tmp_path):
    path = newer(stored(tmp_path))
    before = snapshot(tmp_path)
    for read_only in (True, False):
        with pytest.raises(StoreError, match="newer grail-bench"):
            ResultsStore(path, read_only=read_only)
    assert snapshot(tmp_path) == before


# --- checking a store can be written, before a run ------------------------------------------------------------


def test_check_store_writable_creates_nothing(tmp_path):
    path = tmp_path / "sub" / "r.sqlite"
    assert check_store_writable(path) == path
    assert not path.parent.exists()  # the folder is made by the first rows written, not by the check
    empty = tmp_path / "empty.sqlite"
    empty.write_bytes(b"")
    check_store_writable(empty)  # an empty file is an empty database, as SQLite reads it
    assert empty.read_bytes() == b""
    existing = stored(tmp_path / "s")
    before = snapshot(existing.parent)
    check_store_writable(existing)
    assert {name: data for name, (data, _) in snapshot(existing.parent).items()} == \
        {name: data for name, (data, _) in before.items()}  # the write probe may touch the mtime, not the bytes


def test_check_store_writable_refuses_what_a_run_could_not_write(tmp_path):
    garbage = tmp_path / "g.sqlite"
    garbage.write_bytes(b"somebody's notes" * 50)
    foreign = tmp_path / "f.sqlite"
    conn = sqlite3.connect(foreign)
    conn.execute("CREATE TABLE notes (x TEXT)")
    conn.commit()
    conn.close()
    newest = newer(stored(tmp_path / "n"))
    (tmp_path / "folder.sqlite").mkdir()
    (tmp_path / "a_file").write_text("x")
    before = snapshot(tmp_path)
    cases = {garbage: "is not a grail-bench results store", foreign: "not a grail-bench results store",
             newest: "newer grail-bench", tmp_path / "folder.sqlite": "it is a folder",
             tmp_path / "a_file" / "r.sqlite": "cannot write"}
    for path, message in cases.items():
        with pytest.raises(StoreError, match=message):
            check_store_writable(path)
        with pytest.raises(StoreError, match=message):
            ResultsStore(path)
    assert snapshot(tmp_path) == before


@pytest.mark.skipif(not chmod_stops_writes(), reason="this user (root) writes read-only files")
def test_read_only_file_is_refused_for_writing_at_once(tmp_path):
    path = stored(tmp_path)
    os.chmod(path, 0o444)
    with pytest.raises(StoreError, match="cannot write"):
        check_store_writable(path)
    with pytest.raises(StoreError, match="cannot write"):
        ResultsStore(path)
    with ResultsStore(path, read_only=True) as store:
        assert len(store.rows()) == 2


# --- ties: rows stored under the old rule (lowest-index tie-breaking) -----------------------------------------


def _old_schema(path: Path) -> None:
    """Make ``path`` a schema-7 store: no ``ties`` column anywhere, no ``n_ties`` outside ``results``."""
    conn = sqlite3.connect(path)
    inline(conn)
    for table in ("results", "online", "open_set", "zero_shot"):
        conn.execute(f"ALTER TABLE {table} DROP COLUMN ties")
    for table in ("online", "open_set", "zero_shot"):
        conn.execute(f"ALTER TABLE {table} DROP COLUMN n_ties")
    conn.execute("PRAGMA user_version = 7")
    conn.commit()
    conn.close()


def _online(seed: int, accuracy: float = 0.7, **changes):
    from grail_bench.harness.store import OnlineRow

    return OnlineRow(task="GRAIL/T-v0", recognizer="bc", scorer="mse", config_hash="abc", seed=seed,
                     protocol="prefix", n_trajectories=6, convergence=0.5, never=0.0, step_accuracy=accuracy,
                     f1_auc=0.6, curve="{}", fit_seconds_per_goal=0.1, score_us_per_prefix=1.0, config="{}",
                     versions="{}", **changes)


def old_store(tmp_path: Path) -> Path:
    """A schema-7 store: offline seed 0 tied (n_ties 2), seed 1 did not; one online row (ties not counted)."""
    path = tmp_path / "old.sqlite"
    with ResultsStore(path) as store:
        store.add([dataclasses.replace(row(0), n_ties=2), row(1), _online(0)])
    _old_schema(path)
    return path


def test_an_old_rule_row_with_ties_is_not_completed_and_a_rerun_replaces_it(tmp_path):
    from grail_bench.harness.store import OnlineRow, stale

    path = old_store(tmp_path)
    with ResultsStore(path) as store:
        rows = store.rows()
        assert [(r.seed, r.n_ties, r.ties) for r in rows] == [(0, 2, None), (1, 0, None)]
        assert [stale(r) for r in rows] == [True, False]
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix") == {(1, 0.1)}  # seed 0 is rerun
        assert store.select(OnlineRow)[0].ties is None
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix", OnlineRow) == set()  # ties uncounted
        # The rerun: seed 0 and the online row replace the stale ones, seed 1 (valid) keeps its first write.
        rerun = [dataclasses.replace(row(0, f1=0.8), n_ties=2), row(1, f1=0.9), _online(0, 0.9, n_ties=3)]
        assert store.add(rerun) == 2
        assert [(r.seed, r.f1, r.n_ties, r.ties) for r in store.rows()] == [(0, 0.8, 2, "uniform"), (1, 0.5, 0, None)]
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix") == {(0, 0.1), (1, 0.1)}
        assert [(r.step_accuracy, r.n_ties, r.ties) for r in store.select(OnlineRow)] == [(0.9, 3, "uniform")]
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix", OnlineRow) == {(0, None)}
        # A row of the uniform rule is never replaced, ties or not: the first write wins.
        assert store.add([dataclasses.replace(row(0, f1=0.1), n_ties=2), _online(0, 0.1, n_ties=3)]) == 0
        assert [r.f1 for r in store.rows()] == [0.8, 0.5]
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_a_run_recomputes_exactly_the_stale_units_and_replaces_their_rows(tmp_path):
    import grail_bench
    from grail_bench.harness.planning import RecognizerSpec
    from grail_bench.harness.sweep import Request, plan_request, run_sweep
    from grail_bench.task.observation import ObservationSpec

    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0")
    request = Request(task.id, (RecognizerSpec("bc", {"n_epochs": 1}),), (0, 1),
                      ObservationSpec("subset", "ceil", (0.5,)))
    path = tmp_path / "old.sqlite"
    with ResultsStore(path) as store:
        (p,), _, _ = plan_request(request, store)
        stored = [ResultRow(task=task.id, recognizer=p.name, scorer=label, config_hash=p.config_hash, seed=seed,
                            observability=0.5, protocol=request.label, accuracy=-1.0, precision=-1.0, recall=-1.0,
                            f1=-1.0, n_observations=6, n_ties=2 * (seed == 0), fit_seconds_per_goal=0.1,
                            score_us_per_observation=10.0, config="{}", versions="{}")
                  for label in p.labels for seed in (0, 1)]
        store.add(stored)
    _old_schema(path)
    with ResultsStore(path) as store:
        _, units, skipped = plan_request(request, store)
        assert [u.seed for u in units] == [0] and skipped == 1  # seed 0 tied under the old rule
        run_sweep([request], store)
        after = store.rows()
        assert {(r.seed, r.ties) for r in after} == {(0, "uniform"), (1, None)} and len(after) == len(stored)
        assert all(r.f1 >= 0 for r in after if r.seed == 0) and all(r.f1 == -1.0 for r in after if r.seed == 1)
        assert plan_request(request, store)[1] == []


def test_read_only_opens_an_old_schema_store_with_its_old_rule_rows(tmp_path):
    from grail_bench.harness.store import OnlineRow

    path = old_store(tmp_path)
    before = snapshot(tmp_path)
    with ResultsStore(path, read_only=True) as store:
        assert [(r.seed, r.n_ties, r.ties) for r in store.rows()] == [(0, 2, None), (1, 0, None)]
        assert [(r.n_ties, r.ties) for r in store.select(OnlineRow)] == [(None, None)]
        assert store.completed("GRAIL/T-v0", "bc", "mse", "abc", "prefix") == {(1, 0.1)}
    assert snapshot(tmp_path) == before
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == 7


# --- schema 11: configurations, versions and provenance stored once -------------------------------------------


def test_a_schema_9_store_is_normalised_by_its_first_write_and_read_as_it_is_before(tmp_path):
    from grail_bench.harness.store import OnlineRow, OutputRow

    path = tmp_path / "v9.sqlite"
    config = '{"recognizer": "bc", "params": {"n_epochs": 3}}'
    rows = [dataclasses.replace(row(s, f1=0.1 * s), config=config, provenance='{"host": "a"}' if s else None)
            for s in range(4)]
    with ResultsStore(path) as store:
        store.add([*rows, _online(0)])
    conn = sqlite3.connect(path)
    inline(conn)
    conn.execute("PRAGMA user_version = 9")
    conn.commit()
    conn.execute("VACUUM")
    conn.close()
    before = snapshot(tmp_path)
    with ResultsStore(path, read_only=True) as reader:  # read as it is, the file itself: nothing written
        assert reader.rows() == rows and reader.select(OnlineRow) == [_online(0)]
        assert reader.rows(config=config, seed=[1, 2]) == rows[1:3]
        assert reader.select(OutputRow) == [] and reader._conn.execute("PRAGMA database_list").fetchone()[2]
    assert snapshot(tmp_path) == before
    with ResultsStore(path) as store:  # opened to write: read as it is until the first rows are written
        assert store.rows() == rows and store.select(OnlineRow) == [_online(0)] and store.select(OutputRow) == []
        assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == 9
        store.create()  # as the first add does: normalised
        assert store.rows() == rows and store.select(OnlineRow) == [_online(0)] and store.select(OutputRow) == []
        assert store.rows(config=config, seed=[1, 2]) == rows[1:3]
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    columns = {r[1] for r in conn.execute("PRAGMA table_info(results)")}
    assert {"config_ref", "versions_ref", "provenance_ref"} <= columns and "config" not in columns
    assert conn.execute("SELECT COUNT(*) FROM configs").fetchone()[0] == 2  # "{}" (online) and the offline one
    assert conn.execute("SELECT COUNT(*) FROM provenance").fetchone()[0] == 1


def test_a_schema_11_store_gains_the_tables_of_every_modes_outputs_and_keeps_every_row(tmp_path):
    from grail_bench.harness.outputs import KINDS, OnlineOutputRow, OutputRow, pack, pack_arrays
    from grail_bench.harness.store import MODE_OUTPUTS, OnlineRow

    path = tmp_path / "v11.sqlite"
    offline = [row(s, f1=0.1 * s) for s in range(3)]
    kept = OutputRow("GRAIL/T-v0", "bc", "mse", "abc", 0, 0.1, "prefix", False, pack([0, 1], [2, 3], [[0, 1], [1, 0]]))
    with ResultsStore(path) as store:
        store.add([*offline, _online(0), kept])
    conn = sqlite3.connect(path)
    for kind in KINDS.values():
        if kind.name != "outputs":
            conn.execute(f"DROP TABLE {kind.name}")
    conn.execute(f"PRAGMA user_version = {MODE_OUTPUTS - 1}")
    conn.commit()
    conn.close()
    before = snapshot(tmp_path)
    with ResultsStore(path, read_only=True) as reader:  # read as it is: no outputs of the other modes
        assert reader.rows() == offline and reader.select(OutputRow) == [kept]
        assert reader.select(OnlineOutputRow) == []
    assert snapshot(tmp_path) == before
    online = OnlineOutputRow("GRAIL/T-v0", "bc", "mse", "abc", 0, "prefix",
                             pack_arrays(OnlineOutputRow.NAMES, {"y_true": [1], "lengths": [2], "scores": [[0, 1]] * 2}))
    with ResultsStore(path) as store:
        assert store.add([online]) == 1  # the first write migrates the file
        assert store.rows() == offline and store.select(OnlineRow) == [_online(0)] and store.select(OutputRow) == [kept]
        assert store.select(OnlineOutputRow) == [online]
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION >= MODE_OUTPUTS
    assert {k.name for k in KINDS.values()} <= {r[0] for r in conn.execute("SELECT name FROM sqlite_master")}


def test_shared_json_is_stored_once_however_many_rows_carry_it(tmp_path):
    path = tmp_path / "r.sqlite"
    with ResultsStore(path) as store:
        store.add([dataclasses.replace(row(s), config='{"a": 1}', provenance='{"p": 1}') for s in range(50)])
        assert {r.config for r in store.rows()} == {'{"a": 1}'}
    conn = sqlite3.connect(path)
    assert [conn.execute(f"SELECT COUNT(*) FROM {t}").fetchone()[0] for t in ("configs", "versions", "provenance")] \
        == [1, 1, 1]


def test_what_moved_out_of_the_store_module_is_still_importable_from_it():
    from grail_bench.harness import ceiling_cache, migrations, schema, store

    assert store.migrate is migrations.migrate
    assert store.CeilingCache is ceiling_cache.CeilingCache
    for name in ("MODE_OUTPUTS", "NORMALISED", "SCHEMA_VERSION", "SHARED", "ref", "stale"):
        assert getattr(store, name) is getattr(schema, name)
    namespace: dict = {}
    exec("from grail_bench.harness.store import *", namespace)
    assert set(store.__all__) <= namespace.keys()
    with pytest.raises(AttributeError):
        store.no_such_name
