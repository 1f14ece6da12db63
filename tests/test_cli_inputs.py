"""Inputs refused where they enter, before any work, in one line (exit 2), with every stored result kept.

Each case runs the command in this process (a few seconds at most) and, where
the Python API takes the same input, its twin raises :class:`UserError`.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import chmod_stops_writes, install_plugin, stored_config
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.core.errors import UserError
from grail_bench.core.seeding import MAX_SEED, MAX_SEEDS, seed_list
from grail_bench.harness.store import SCHEMA_VERSION, ResultRow, ResultsStore

TASK = "GRAIL/MiniGrid-Biased-v0"
BIN = Path(sys.executable).parent / "grail-bench"


def invoke(args: list[str], store: Path) -> tuple[int, str]:
    """Run a command in this process; its exit code and everything it printed."""
    start = time.perf_counter()
    result = CliRunner().invoke(app, args, env={"COLUMNS": "200", "GRAIL_BENCH_STORE": str(store)})
    assert time.perf_counter() - start < 10, f"{args} took too long to be refused"
    return result.exit_code, result.output


def refused(args: list[str], store: Path, message: str) -> str:
    """Assert a command exits 2 with one ``error:`` line containing ``message``; return the line."""
    code, output = invoke(args, store)
    lines = output.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], output
    return lines[0]


def snapshot(folder: Path) -> dict[str, tuple[bytes, int] | None]:
    """Everything under ``folder``: each file's bytes and modification time (ns), each folder as ``None``."""
    return {str(f.relative_to(folder)): None if f.is_dir() else (f.read_bytes(), f.stat().st_mtime_ns)
            for f in sorted(folder.rglob("*"))}


def results(path: Path) -> Path:
    """A store of offline rows of bc at its defaults on the default task (2 seeds at its levels), as a run would
    leave it."""
    task = grail_bench.make_task(TASK)
    config, hashed = stored_config(TASK, "bc")
    rows = [ResultRow(TASK, "bc", "mse", hashed, seed, level, task.protocol_label, 0.7, 0.7, 0.7, 0.7, 6, 0, 1.0,
                      10.0, config, "{}", confusion=json.dumps([[3, 0], [0, 3]]))
            for seed in range(2) for level in task.observability]
    path.parent.mkdir(parents=True, exist_ok=True)
    with ResultsStore(path) as store:
        store.add(rows)
    return path


# --- options ----------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("args, message", [
    (["run", "--seeds", "1", "--seeds=2"], "--seeds/-s given more than once (1, 2); run takes one"),
    (["reproduce", "--profile", "quick", "--profile", "paper", "--out", "OUT"],
     "--profile given more than once (quick, paper); reproduce takes one"),
    (["leaderboard", "--markdown", "OUT/a.md", "--workers", "1", "--markdown", "OUT/b.md"],
     "--markdown given more than once (OUT/a.md, OUT/b.md); leaderboard takes one"),
])
def test_an_option_given_twice_is_refused_not_overridden(tmp_path, args, message):
    """Click keeps the last of a repeated single-valued option; here it is refused before any work."""
    store = results(tmp_path / "r.sqlite")
    before = snapshot(tmp_path)
    out = str(tmp_path / "out")
    refused([a.replace("OUT", out) for a in args], store, message.replace("OUT", out))
    assert snapshot(tmp_path) == before


# --- seeds ------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("count", ["100000000", str(10**20), str(MAX_SEEDS + 1)])
def test_too_many_seeds_are_refused_at_once(tmp_path, count):
    refused(["run", "-r", "bc", "--seeds", count], tmp_path / "s.sqlite", f"at most {MAX_SEEDS:,} seeds")
    refused(["reproduce", "--seeds", count, "--out", str(tmp_path / "out")], tmp_path / "s.sqlite",
            f"at most {MAX_SEEDS:,} seeds")
    assert not (tmp_path / "s.sqlite").exists() and not (tmp_path / "out" / "results.sqlite").exists()


@pytest.mark.parametrize("seeds", [10**8, [MAX_SEED + 1], [-1], [], [0.5], range(10**12)])
def test_api_refuses_the_same_seeds(seeds):
    with pytest.raises(UserError, match="seed"):
        grail_bench.evaluate(TASK, ["bc"], seeds=seeds)


def test_seed_list_bounds():
    assert seed_list(MAX_SEEDS) == list(range(MAX_SEEDS))
    assert seed_list([0, MAX_SEED]) == [0, MAX_SEED]
    with pytest.raises(UserError, match="at most"):
        seed_list(iter(range(10**12)))  # a generator is never drawn past the limit


# --- observability levels ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("levels, message", [
    ("0.0000001", "is 0 at the 6 decimals levels are stored to"),
    ("0.1000001,0.1000004", "are the same level, 0.1"),
    ("0.3,0.30000004", "are the same level, 0.3"),
])
def test_levels_that_collide_when_stored_are_refused(tmp_path, levels, message):
    store = tmp_path / "s.sqlite"
    refused(["run", "-r", "bc", "-o", levels], store, message)
    refused(["ceiling", "-o", levels], store, message)
    assert not store.exists()
    with pytest.raises(UserError, match=message):
        grail_bench.evaluate(TASK, ["bc"], observability=levels)
    with pytest.raises(UserError, match=message):
        grail_bench.evaluate(TASK, ["bc"], observability=[float(v) for v in levels.split(",")])


def test_small_distinct_levels_and_repeats_are_kept(tmp_path):
    from grail_bench.task.observation import parse_observability

    assert parse_observability("0.0001,0.000001,0.2,0.2") == (0.0001, 0.000001, 0.2)


# --- stores: read-only commands ---------------------------------------------------------------------------------


@pytest.mark.parametrize("content", [b"", b"somebody's notes\n" * 100], ids=["empty", "not-sqlite"])
def test_leaderboard_refuses_a_file_that_is_not_a_store_and_leaves_it(tmp_path, content):
    store = tmp_path / "s.sqlite"
    store.write_bytes(content)
    before = snapshot(tmp_path)
    refused(["leaderboard"], store, f"{store} is not a grail-bench results store")
    refused(["leaderboard", "--store", str(store)], tmp_path / "other.sqlite", "is not a grail-bench results store")
    assert snapshot(tmp_path) == before  # no schema written, no -journal, -wal or -shm file


def test_leaderboard_refuses_a_folder_and_a_newer_store(tmp_path):
    (tmp_path / "folder").mkdir()
    refused(["leaderboard", "--store", str(tmp_path / "folder")], tmp_path / "s.sqlite", "is a folder")
    path = results(tmp_path / "new.sqlite")
    conn = sqlite3.connect(path)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.commit()
    conn.close()
    before = snapshot(tmp_path)
    refused(["leaderboard", "--store", str(path)], tmp_path / "s.sqlite", "newer grail-bench")
    assert snapshot(tmp_path) == before


def test_leaderboard_reads_a_read_only_store_and_changes_nothing(tmp_path):
    """Tests may run as root, whom chmod does not stop: what is checked is that nothing is written at all."""
    path = results(tmp_path / "published" / "results.sqlite")
    os.chmod(path, 0o444)
    os.chmod(path.parent, 0o555)
    try:
        before = snapshot(path.parent)
        code, output = invoke(["leaderboard", "--store", str(path), "--no-ceiling", "--boards"],
                              tmp_path / "unused.sqlite")
        assert code == 0, output
        assert "BC-GRAIL" in output and "0.70 ± 0.00" in output  # bc's default configuration on the main board
        assert snapshot(path.parent) == before  # same files (no -journal, -wal, -shm), bytes and mtimes
    finally:
        os.chmod(path.parent, 0o755)
    assert not (tmp_path / "unused.sqlite").exists()


# --- stores: commands that write, checked before any work -------------------------------------------------------


def bad_stores(tmp_path: Path) -> dict[Path, str]:
    """Store paths a run cannot write to, with what the error says."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    garbage = tmp_path / "garbage.sqlite"
    garbage.write_bytes(b"somebody's notes\n" * 100)
    foreign = tmp_path / "foreign.sqlite"
    conn = sqlite3.connect(foreign)
    conn.execute("CREATE TABLE notes (x TEXT)")
    conn.commit()
    conn.close()
    newer = results(tmp_path / "newer.sqlite")
    conn = sqlite3.connect(newer)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.commit()
    conn.close()
    (tmp_path / "folder.sqlite").mkdir()
    (tmp_path / "a_file").write_text("x")
    return {garbage: f"{garbage} is not a grail-bench results store",
            foreign: "is an SQLite file but not a grail-bench results store",
            newer: "newer grail-bench", tmp_path / "folder.sqlite": "it is a folder",
            tmp_path / "a_file" / "results.sqlite": "cannot write"}


def test_run_checks_the_store_before_planning(tmp_path):
    cases = bad_stores(tmp_path)
    before = snapshot(tmp_path)
    for store, message in cases.items():
        # an unknown recognizer would be refused by planning: the store is refused first
        refused(["run", "-r", "no-such-recognizer", "--store", str(store)], tmp_path / "unused.sqlite", message)
        refused(["run", "-r", "bc"], store, message)
    assert snapshot(tmp_path) == before


def test_reproduce_checks_the_store_before_planning(tmp_path):
    cases = bad_stores(tmp_path / "stores")
    out = tmp_path / "out"
    out.mkdir()
    before = snapshot(tmp_path)
    for store, message in cases.items():
        refused(["reproduce", "--profile", "no-such-profile", "--out", str(out), "--store", str(store)],
                tmp_path / "unused.sqlite", message)
    assert snapshot(tmp_path) == before


@pytest.mark.skipif(not chmod_stops_writes(), reason="this user (root) writes read-only files")
def test_run_refuses_a_read_only_store_at_once(tmp_path):
    path = results(tmp_path / "ro" / "results.sqlite")
    os.chmod(path, 0o444)
    refused(["run", "-r", "bc", "--store", str(path)], tmp_path / "unused.sqlite", "cannot write")
    os.chmod(path.parent, 0o555)
    try:
        refused(["run", "-r", "bc", "--store", str(path)], tmp_path / "unused.sqlite", "cannot write")
    finally:
        os.chmod(path.parent, 0o755)


# --- Ctrl-C -----------------------------------------------------------------------------------------------------


def test_ctrl_c_interrupts_a_large_run_promptly(tmp_path):
    """SIGINT while a 10 000-seed run plans or runs its units: out in seconds, saying what was kept."""
    site = install_plugin(tmp_path / "site")
    env = {**os.environ, "COLUMNS": "200", "PYTHONPATH": str(site), "GRAIL_BENCH_STORE": str(tmp_path / "s.sqlite")}
    # A job started in the background of a non-interactive shell inherits SIGINT ignored; a terminal's does not.
    proc = subprocess.Popen([str(BIN), "run", "-r", "toy", "--seeds", str(MAX_SEEDS), "--no-progress"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        time.sleep(6)  # past start-up: planning or the first units
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)  # a run that ignored it would go on for minutes
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("interrupted"), err
