"""Where a sweep's units run: in this process, a local process pool, or a Ray cluster.

An executor maps a function over work items and yields ``(item, result)`` as
each finishes, in completion order. Only the caller (the sweep's driver)
touches the results store; workers return their rows. Every worker process
runs torch on one thread, so ``n`` workers use ``n`` cores without
oversubscribing them.

* ``serial``: in this process, in order (the reference every other executor
  must match row for row).
* ``local``: :class:`concurrent.futures.ProcessPoolExecutor` with ``spawn``
  workers (fresh interpreters: no forked torch or OpenMP state). Workers die
  with the process that started them, even one killed with ``kill -9``
  (:func:`die_with_parent`), and a driver stopped by an exception (Ctrl-C
  included) kills its workers instead of waiting for their units, whose rows
  it would no longer store.
* ``ray``: Ray tasks of one CPU each, on the cluster at ``address`` or on a
  local instance started for the sweep (``pip install grail-bench[ray]``). A
  local instance dies with the driver, even one killed with ``kill -9``
  (:class:`~grail_bench.harness.reaper.Reaper`); a cluster at ``address`` is left running.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from typing import Any, Callable, Iterator, Protocol, Sequence

from grail_bench.core.errors import UserError
from grail_bench.harness.reaper import Reaper, children

EXECUTORS = ("serial", "local", "ray")
_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
_PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
PARENT_POLL_SECONDS = 0.5  #: how often a worker's watchdog checks that its parent lives


class WorkerLost(RuntimeError):
    """A worker process died; the units it was running produced no rows."""


class Executor(Protocol):
    """Runs a function over work items (see module docstring)."""

    name: str
    workers: int

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, fn(item))`` as each finishes; raise :class:`WorkerLost` if a worker dies."""

    def close(self, abandon: bool = False) -> None:
        """Stop the workers (cancelling units not yet started); with ``abandon``, also the units running."""


def one_thread() -> None:
    """Pin this process's numeric libraries to one thread (worker initializer)."""
    for var in _THREAD_VARS:
        os.environ[var] = "1"
    import torch

    torch.set_num_threads(1)


def die_with_parent(parent: int) -> None:
    """Make this process exit as soon as process ``parent``, which started it, is gone.

    On Linux the kernel sends it ``SIGKILL`` when its parent dies
    (``prctl(PR_SET_PDEATHSIG)``); everywhere, a daemon thread polls
    :func:`os.getppid` (a process whose parent died is adopted by another)
    and exits it. A parent already gone when this runs is noticed at once.
    """
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass  # no prctl: the watchdog alone
    if os.getppid() != parent:
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent,), name="grail-bench-parent-watch", daemon=True).start()


def _watch_parent(parent: int) -> None:
    event = threading.Event()
    while not event.wait(PARENT_POLL_SECONDS):
        if os.getppid() != parent:
            os._exit(1)  # the driver that would store this unit's rows is gone


def _worker_init(parent: int, cards: tuple[str, ...] = ()) -> None:
    """Initializer of every local worker: dies with the driver, runs numeric libraries on one thread, and knows
    the tasks of the cards the driver was given (``--cards``)."""
    die_with_parent(parent)
    one_thread()
    if cards:
        from grail_bench.task.external import load_cards

        load_cards(*cards)


def _cards_env() -> dict[str, str]:
    """``GRAIL_BENCH_CARDS`` for workers elsewhere: this process's, and the cards it was given (``--cards``)."""
    from grail_bench.task.external import given_paths
    from grail_bench.task.sources import ENV_VAR, env_paths

    paths = list(dict.fromkeys([*env_paths(), *given_paths()]))
    return {ENV_VAR: os.pathsep.join(paths)} if paths else {}


class SerialExecutor:
    """Runs every item in this process, in order."""

    name = "serial"
    workers = 1

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[Any, Any]]:
        for item in items:
            yield item, fn(item)

    def close(self, abandon: bool = False) -> None:
        pass


class LocalExecutor:
    """A pool of ``workers`` spawned processes on this machine, started on first use.

    Starting the pool costs seconds (each spawned worker imports torch and the
    suite), so a map of a single item runs in this process instead and starts
    no pool: one unit cannot run faster in parallel. Linux ties each worker's
    life to the thread that started it, so map from a thread that outlives the
    executor (the main thread, as every command does).
    """

    name = "local"

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool: Any = None

    def _started(self) -> Any:
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            from grail_bench.task.external import given_paths

            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_worker_init, initargs=(os.getpid(), tuple(given_paths())))
        return self._pool

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[Any, Any]]:
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        if len(items) < 2 or self.workers < 2:
            yield from SerialExecutor().map_unordered(fn, items)
            return
        pool = self._started()
        pending = {pool.submit(fn, item): item for item in items}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                item = pending.pop(future)
                try:
                    result = future.result()
                except BrokenProcessPool:
                    raise WorkerLost(f"a worker process died; {len(pending) + 1} unit(s) did not finish") from None
                yield item, result

    def close(self, abandon: bool = False) -> None:
        if self._pool is None:
            return
        # the pool's own processes: concurrent.futures offers no public way to stop a running call
        running = list((getattr(self._pool, "_processes", None) or {}).values()) if abandon else []
        self._pool.shutdown(wait=not running, cancel_futures=True)
        for process in running:
            process.kill()
        for process in running:
            process.join()
        if running:
            self._pool.shutdown(wait=True)
        self._pool = None


class RayExecutor:
    """Ray tasks of one CPU each, on an existing cluster or a local instance."""

    name = "ray"

    def __init__(self, workers: int | None, address: str | None) -> None:
        try:
            import ray
        except ImportError:
            raise UserError("--executor ray needs Ray: pip install 'grail-bench[ray]'") from None
        if address not in (None, "auto"):
            _check_reachable(address)
        self._ray = ray
        self._started = not ray.is_initialized()
        self._reaper: Reaper | None = None
        if self._started:
            env = {"env_vars": {**{var: "1" for var in _THREAD_VARS}, **_cards_env()}}
            try:
                if address is None:
                    before = children(os.getpid())
                    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                             runtime_env=env, logging_level="ERROR")
                    # The local instance's processes are this driver's new children: they die with it.
                    self._reaper = Reaper.start(children(os.getpid()) - before)
                else:
                    ray.init(address=address, log_to_driver=False, runtime_env=env, logging_level="ERROR")
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise UserError(f"cannot connect to Ray at {address!r}: {str(exc).splitlines()[0]}") from None
        self.workers = int(ray.cluster_resources().get("CPU", 1))

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[Any, Any]]:
        ray = self._ray
        remote = ray.remote(num_cpus=1)(_in_one_thread)
        pending = {remote.remote(fn, item): item for item in items}
        try:
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                item = pending.pop(done[0])
                try:
                    yield item, ray.get(done[0])
                except ray.exceptions.WorkerCrashedError:
                    raise WorkerLost(f"a Ray worker died; {len(pending) + 1} unit(s) did not finish") from None
                except ray.exceptions.RayTaskError as exc:
                    raise exc.as_instanceof_cause() from None
        finally:
            for ref in pending:
                ray.cancel(ref, force=True)

    def close(self, abandon: bool = False) -> None:
        if self._started:
            self._ray.shutdown()
        if self._reaper is not None:
            self._reaper.release()
            self._reaper = None


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail fast on a cluster address nothing listens at (Ray itself retries for minutes)."""
    import socket

    host, sep, port = address.split("://")[-1].rpartition(":")
    if not sep or not port.isdigit():
        raise UserError(f"--address must be auto or HOST:PORT, got {address!r}")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise UserError(f"cannot reach a Ray cluster at {address}: {exc.strerror or exc}") from None


def _in_one_thread(fn: Callable[[Any], Any], item: Any) -> Any:
    one_thread()
    return fn(item)


#: The most worker processes (or local Ray CPUs) one machine is asked to run per core: each runs torch on one thread.
WORKERS_PER_CORE = 4


def make_executor(name: str | None = None, workers: int | None = None, address: str | None = None) -> Executor:
    """The executor the command line asked for.

    Args:
        name: ``serial``, ``local`` or ``ray``; by default ``ray`` when an
            ``address`` is given, ``local`` when ``workers`` > 1, else ``serial``.
        workers: Processes of ``local`` (default: every core) or CPUs of a new
            local Ray instance (default: every core).
        address: A Ray cluster (``auto`` or ``host:port``); only with ``ray``.

    Raises:
        UserError: For an unknown executor, ``workers`` < 1 or above :data:`WORKERS_PER_CORE` per core, an address
            without Ray, or a cluster that cannot be reached.
    """
    if workers is not None and workers < 1:
        raise UserError(f"--workers must be at least 1, got {workers}")
    cores = os.cpu_count() or 1
    if workers is not None and workers > WORKERS_PER_CORE * cores:
        raise UserError(f"--workers {workers} is more processes than this machine's {cores} cores can run (at most "
                        f"{WORKERS_PER_CORE * cores}, {WORKERS_PER_CORE} per core)")
    if name is None:
        name = "ray" if address is not None else "local" if (workers or 1) > 1 else "serial"
    if name not in EXECUTORS:
        raise UserError(f"unknown executor {name!r}; choose one of {', '.join(EXECUTORS)}")
    if address is not None and name != "ray":
        raise UserError("--address names a Ray cluster; use it with --executor ray")
    if name == "serial":
        if (workers or 1) > 1:
            raise UserError("the serial executor runs one unit at a time; drop --workers or choose local or ray")
        return SerialExecutor()
    if name == "local":
        return LocalExecutor(workers or os.cpu_count() or 1)
    if address is not None and workers is not None:
        raise UserError("--workers sizes a new local Ray instance; a cluster at --address brings its own CPUs")
    return RayExecutor(workers, address)
