"""Processes a driver started die with it, even when the driver is killed with ``kill -9`` (harness/reaper.py)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from grail_bench.harness.reaper import start_time

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the reaper reads /proc")

# A driver that starts a process tree (a child with a grandchild of its own), hands the child to a reaper, prints
# the tree's pids, then either waits to be killed or releases the reaper and exits.
DRIVER = textwrap.dedent("""
    import json, subprocess, sys, time
    from grail_bench.harness.reaper import Reaper, descendants
    child = subprocess.Popen([sys.executable, "-c",
                              "import subprocess, sys, time; subprocess.Popen(['sleep', '120']); time.sleep(120)"])
    time.sleep(0.5)
    reaper = Reaper.start([child.pid])
    print(json.dumps([child.pid, *descendants([child.pid])]), flush=True)
    if sys.argv[1] == "release":
        reaper.release()
        print("released", flush=True)
    time.sleep(120)
""")


def _alive(stamped: dict[int, str | None]) -> set[int]:
    return {pid for pid, started in stamped.items() if started is not None and start_time(pid) == started}


def _driver(how: str) -> tuple[subprocess.Popen, dict[int, str | None]]:
    driver = subprocess.Popen([sys.executable, "-c", DRIVER, how], stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    pids = json.loads(driver.stdout.readline())
    assert len(pids) == 2  # the child and its grandchild
    return driver, {pid: start_time(pid) for pid in pids}


def _wait_gone(stamped: dict[int, str | None], seconds: float) -> set[int]:
    deadline = time.monotonic() + seconds
    while _alive(stamped) and time.monotonic() < deadline:
        time.sleep(0.1)
    return _alive(stamped)


def test_a_driver_killed_with_sigkill_takes_its_process_tree_down():
    driver, tree = _driver("wait")
    try:
        assert _alive(tree) == set(tree)
        driver.kill()
        driver.wait()
        assert _wait_gone(tree, 10) == set()
    finally:
        for pid in _alive(tree):
            os.kill(pid, signal.SIGKILL)


def test_a_released_reaper_leaves_the_processes_alone():
    driver, tree = _driver("release")
    try:
        assert driver.stdout.readline().strip() == "released"
        driver.kill()
        driver.wait()
        time.sleep(1.0)
        assert _alive(tree) == set(tree)
    finally:
        for pid in _alive(tree):
            os.kill(pid, signal.SIGKILL)


RAY_DRIVER = textwrap.dedent("""
    import json, os, time
    from grail_bench.harness.executors import RayExecutor
    from grail_bench.harness.reaper import descendants

    def worker_pid(_):
        return os.getpid()

    executor = RayExecutor(1, None)
    [(_, worker)] = list(executor.map_unordered(worker_pid, [0]))
    ray_pids = descendants([os.getpid()]) - {executor._reaper.pid}
    print(json.dumps(sorted(ray_pids | {worker})), flush=True)
    time.sleep(300)
""")


@pytest.mark.slow
def test_a_local_ray_instance_dies_with_a_driver_killed_with_sigkill():
    pytest.importorskip("ray")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "RAY_USAGE_STATS_ENABLED": "0",
           "RAY_AUTH_MODE": "disabled"}
    driver = subprocess.Popen([sys.executable, "-c", RAY_DRIVER], stdout=subprocess.PIPE, text=True, env=env)
    ray: dict[int, str | None] = {}
    try:
        ray = {pid: start_time(pid) for pid in json.loads(driver.stdout.readline())}
        assert len(ray) >= 3  # at least the GCS server, the raylet and the worker
        driver.kill()
        driver.wait()
        assert _wait_gone(ray, 15) == set()  # without the reaper some linger for a minute or more
    finally:
        driver.kill()
        for pid in _alive(ray):
            os.kill(pid, signal.SIGKILL)
