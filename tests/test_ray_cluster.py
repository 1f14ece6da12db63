"""Ray as a cluster: a head and a worker node started with `ray start` (one CPU each), a sweep sent to it."""

from __future__ import annotations

import os
import shutil
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent
# Stamps of where and when, not results (schema 11 keeps provenance by reference).
TIMING = {"fit_seconds_per_goal", "score_us_per_observation", "provenance", "provenance_ref", "created_at"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def cluster(tmp_path):
    """A two-node Ray cluster on this machine, each node with its own temp dir and one CPU; torn down after."""
    env = {**os.environ, "RAY_AUTH_MODE": "disabled", "RAY_USAGE_STATS_ENABLED": "0"}
    roots = [tempfile.mkdtemp(prefix="gb-ray-", dir="/tmp") for _ in range(2)]  # short: Ray's socket paths
    port = _free_port()
    ray = str(BIN / "ray")
    try:
        head = subprocess.run([ray, "start", "--head", f"--port={port}", "--num-cpus=1", f"--temp-dir={roots[0]}",
                               "--include-dashboard=false", "--disable-usage-stats"], env=env, capture_output=True,
                              text=True, timeout=180)
        assert head.returncode == 0, head.stderr
        worker = subprocess.run([ray, "start", f"--address=127.0.0.1:{port}", "--num-cpus=1",
                                 f"--temp-dir={roots[1]}", "--disable-usage-stats"], env=env, capture_output=True,
                                text=True, timeout=180)
        assert worker.returncode == 0, worker.stderr
        yield f"127.0.0.1:{port}", env
    finally:
        subprocess.run([ray, "stop", "--force"], env=env, capture_output=True, timeout=180)
        for root in roots:
            shutil.rmtree(root, ignore_errors=True)


def _live_nodes(address: str, env: dict[str, str], wait: float = 60.0) -> int:
    """How many nodes `ray status` lists, polling while the cluster's services start (up to `wait` seconds)."""
    deadline = time.monotonic() + wait
    while True:
        status = subprocess.run([str(BIN / "ray"), "status", f"--address={address}"], env=env, capture_output=True,
                                text=True, timeout=120)
        nodes = status.stdout.count(" node_") if status.returncode == 0 else 0
        if nodes >= 2 or time.monotonic() > deadline:
            return nodes
        time.sleep(2)


def _rows(path: Path) -> list[tuple]:
    conn = sqlite3.connect(path)
    names = [r[1] for r in conn.execute("PRAGMA table_info(results)")]
    keep = [i for i, n in enumerate(names) if n not in TIMING]
    return sorted(tuple(row[i] for i in keep) for row in conn.execute("SELECT * FROM results"))


@pytest.mark.slow
def test_a_sweep_on_a_two_node_cluster_stores_the_serial_rows(cluster, tmp_path):
    address, env = cluster
    assert _live_nodes(address, env) == 2
    args = ["run", "-t", "GRAIL/MiniGrid-Optimal-4Goals-v0", "-r", "bc", "-r", "graql", "--set", "bc.n_epochs=2",
            "--set", "graql.episodes=100", "--seeds", "3", "--no-progress"]
    for name, extra in (("ray", ["--executor", "ray", "--address", address]), ("serial", [])):
        run_env = {**env, "GRAIL_BENCH_CACHE": str(tmp_path / f"cache-{name}"), "COLUMNS": "200"}
        out = subprocess.run([str(BIN / "grail-bench"), *args, *extra, "--store", str(tmp_path / f"{name}.sqlite")],
                             env=run_env, capture_output=True, text=True, timeout=900)
        assert out.returncode == 0, out.stderr
    ray_rows, serial_rows = _rows(tmp_path / "ray.sqlite"), _rows(tmp_path / "serial.sqlite")
    assert len(ray_rows) == 3 * 3 * 2 and ray_rows == serial_rows  # seeds x levels x recognizers, row for row
