"""Executors' workers die with the process that started them, and an interrupted driver stops them at once."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from grail_bench.cli.inputs import executor
from grail_bench.harness.executors import PARENT_POLL_SECONDS

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc")
BIN = Path(sys.executable).parent / "grail-bench"


def stat(pid: int) -> list[str] | None:
    """Fields of ``/proc/PID/stat`` after the command name (state first), or None for no such process."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return None


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not yet reaped by whoever adopted it, does not)."""
    fields = stat(pid)
    return fields is not None and fields[0] != "Z"


def children(pid: int) -> list[int]:
    """Live processes whose parent is ``pid``."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            fields = stat(int(entry.name))
            if fields is not None and int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(entry.name))
    return out


def cpu_seconds(pid: int) -> float:
    fields = stat(pid)
    return 0.0 if fields is None else (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_until(condition, timeout: float, what: str) -> None:  # noqa: ANN001
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)


def all_gone(pids: list[int], within: float) -> None:
    """Assert every process of ``pids`` is gone ``within`` seconds (and kill any left, which this test started)."""
    try:
        wait_until(lambda: not any(alive(p) for p in pids), within, f"workers {pids} to die")
    finally:
        for pid in pids:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)


def busy(item: tuple[str, int]) -> int:
    """A unit that never finishes on its own: it records its worker's pid, then waits."""
    folder, index = item
    Path(folder, f"{os.getpid()}.{index}").touch()
    time.sleep(600)
    return index


def started_workers(folder: Path, n: int, timeout: float = 120.0) -> list[int]:
    """The pids of the first ``n`` workers that started a :func:`busy` unit in ``folder``."""
    wait_until(lambda: len({p.name.split(".")[0] for p in folder.iterdir()}) >= n, timeout, f"{n} busy workers")
    return sorted({int(p.name.split(".")[0]) for p in folder.iterdir()})


DRIVER = textwrap.dedent("""
    import sys

    from grail_bench.harness.executors import LocalExecutor
    from test_executors import busy

    if __name__ == "__main__":
        folder = sys.argv[1]
        for _ in LocalExecutor(2).map_unordered(busy, [(folder, i) for i in range(4)]):
            pass
""")


def test_local_workers_die_with_a_driver_killed_with_sigkill(tmp_path):
    (tmp_path / "pids").mkdir()
    (tmp_path / "driver.py").write_text(DRIVER)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])}
    driver = subprocess.Popen([sys.executable, str(tmp_path / "driver.py"), str(tmp_path / "pids")], env=env)
    try:
        workers = started_workers(tmp_path / "pids", 2)
        assert set(workers) <= set(children(driver.pid))
        driver.kill()
        driver.wait()
        all_gone(workers, within=3.0)
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait()


def test_an_interrupted_driver_stops_its_running_units(tmp_path):
    """Ctrl-C in the driver: the executor's workers are killed, not waited for (their rows would not be stored)."""
    with pytest.raises(KeyboardInterrupt):
        with executor("local", 2, None) as chosen:
            pool = chosen._started()
            for i in range(2):
                pool.submit(busy, (str(tmp_path), i))
            workers = started_workers(tmp_path, 2)
            interrupted = time.monotonic()
            raise KeyboardInterrupt
    assert time.monotonic() - interrupted < 5
    all_gone(workers, within=1.0)


def test_a_worker_whose_parent_is_already_gone_exits():
    code = "from grail_bench.harness.executors import die_with_parent\ndie_with_parent(-1)\nprint('alive')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "alive" not in out.stdout, out


def test_the_watchdog_alone_ends_an_orphan():
    """Without prctl (as off Linux), the polling thread notices the parent is gone."""
    child = ("import os, sys, time\nfrom grail_bench.harness.executors import die_with_parent\n"
             "sys.platform = 'darwin'  # no prctl\n"
             "die_with_parent(os.getppid())\nprint('ready', flush=True)\ntime.sleep(600)")
    parent = ("import subprocess, sys, time\n"
              f"p = subprocess.Popen([sys.executable, '-c', {child!r}], stdout=subprocess.PIPE, text=True)\n"
              "p.stdout.readline()\nprint(p.pid, flush=True)\ntime.sleep(600)")
    proc = subprocess.Popen([sys.executable, "-c", parent], stdout=subprocess.PIPE, text=True)
    try:
        orphan = int(proc.stdout.readline())
        assert alive(orphan)
        proc.kill()
        proc.wait()
        all_gone([orphan], within=PARENT_POLL_SECONDS + 2.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_run_workers_die_when_the_run_is_killed_mid_unit(tmp_path):
    """`grail-bench run --workers 2` killed with kill -9 while both workers train GAIL: no worker is left."""
    env = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_STORE": str(tmp_path / "s.sqlite"),
           "GRAIL_BENCH_CACHE": str(tmp_path / "cache")}  # nothing cached: the units train
    run = subprocess.Popen([str(BIN), "run", "-t", "GRAIL/MiniGrid-Biased-v0", "-r", "gail", "--seeds", "2",
                            "--workers", "2", "--no-progress"], env=env, stdout=subprocess.DEVNULL,
                           stderr=subprocess.PIPE)
    workers: list[int] = []
    try:
        def training() -> bool:
            assert run.poll() is None, run.stderr.read().decode()
            workers[:] = [p for p in children(run.pid)
                          if b"resource_tracker" not in Path(f"/proc/{p}/cmdline").read_bytes()]
            return len(workers) == 2 and all(cpu_seconds(p) > 8 for p in workers)  # past start-up, in the unit

        wait_until(training, 240, "two workers to be training")
        run.kill()
        run.wait()
        all_gone(workers, within=3.0)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
        for pid in workers:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)

