"""A reaper that takes the processes a driver started down with it, even when the driver is killed with ``kill -9``.

A local Ray instance (``ray.init`` without an address) runs as children of the
driver: its GCS server, raylet, monitors and agents, and the raylet's
workers. A driver that dies without ``ray.shutdown()`` leaves them running for a
minute or more (some until killed). :class:`Reaper` is a tiny watcher process
(this file run as a script: the standard library only, no grail-bench import)
holding the read end of a pipe whose write end only the driver holds. The
kernel closes that end however the driver ends, so the watcher's read returns at
once: a driver that says "done" first (:meth:`Reaper.release`, after an orderly
shutdown) lets it exit quietly; otherwise it kills the processes it was given and
every descendant of theirs it has seen (it notes them every second, as a process
whose parent dies first is adopted by init). The watcher runs in a session of its own, so a
terminal's Ctrl-C, which the driver handles, does not reach it.

Linux only (it reads ``/proc``); elsewhere :meth:`Reaper.start` returns ``None``.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
from pathlib import Path
from typing import IO, Iterable

_DONE = b"done\n"
POLL_SECONDS = 1.0  #: how often the watcher notes new descendants
_PROC = Path("/proc")


def children(pid: int) -> set[int]:
    """The live processes whose parent is ``pid``."""
    return {child for child, parent in _parents().items() if parent == pid}


def _parents() -> dict[int, int]:
    """Every live process's parent, read from ``/proc`` (none where there is no ``/proc``)."""
    out: dict[int, int] = {}
    if not _PROC.is_dir():
        return out
    for entry in _PROC.iterdir():
        if entry.name.isdigit():
            stat = _stat(int(entry.name))
            if stat is not None:
                out[int(entry.name)] = int(stat[1])
    return out


def _stat(pid: int) -> list[str] | None:
    """``/proc/PID/stat``'s fields after the command name (state, ppid, ..., start time at index 19)."""
    try:
        text = (_PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    return text[text.rfind(")") + 2:].split()


def start_time(pid: int) -> str | None:
    """When ``pid`` started (clock ticks since boot), to tell it from a later process given the same pid."""
    stat = _stat(pid)
    return None if stat is None else stat[19]


def descendants(roots: Iterable[int]) -> set[int]:
    """``roots``' live descendants (not the roots themselves)."""
    parents = _parents()
    found: set[int] = set()
    frontier = set(roots)
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


class Reaper:
    """The watcher of one driver (see module docstring)."""

    def __init__(self, process: subprocess.Popen, pipe: IO[bytes]) -> None:
        self._process = process
        self._pipe = pipe

    @classmethod
    def start(cls, pids: Iterable[int]) -> Reaper | None:
        """Watch this process on behalf of ``pids`` (and their descendants); ``None`` where ``/proc`` is missing."""
        stamped = [f"{pid}:{start_time(pid)}" for pid in pids if start_time(pid) is not None]
        if not sys.platform.startswith("linux") or not stamped:
            return None
        process = subprocess.Popen([sys.executable, "-I", __file__, *stamped], stdin=subprocess.PIPE,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        return cls(process, process.stdin)

    @property
    def pid(self) -> int:
        """The watcher's process id."""
        return self._process.pid

    def release(self) -> None:
        """The processes were stopped in order: the watcher exits without killing anything."""
        try:
            self._pipe.write(_DONE)
            self._pipe.close()
        except OSError:  # the watcher is gone already
            pass
        try:
            self._process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self._process.kill()


def _stamped(args: Iterable[str]) -> dict[int, str]:
    """``pid:start time`` arguments as a mapping."""
    return {int(pid): started for pid, _, started in (item.partition(":") for item in args)}


def _live(known: dict[int, str]) -> dict[int, str]:
    """The processes of ``known`` still running (not a later process given one's pid)."""
    return {pid: started for pid, started in known.items() if start_time(pid) == started}


def _grow(known: dict[int, str]) -> dict[int, str]:
    """``known``'s live processes and every live descendant of theirs, stamped."""
    known = _live(known)
    for pid in descendants(known):
        started = start_time(pid)
        if started is not None:
            known[pid] = started
    return known


def reap(known: dict[int, str]) -> None:
    """Kill the still-running processes of ``known`` (pid: start time) and all their descendants."""
    known = _live(known)
    for pid in known:  # stopped first, so they start no new children
        _signal(pid, signal.SIGSTOP)
    for pid in _grow(known):
        _signal(pid, signal.SIGKILL)


def _signal(pid: int, sig: int) -> None:
    try:
        os.kill(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def _main(args: list[str]) -> None:
    """Wait for the driver's end of the pipe to close, noting the processes' descendants every ``POLL_SECONDS``
    (a child whose parent dies first is adopted by init, out of reach of a walk down from the roots)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    known = _grow(_stamped(args))
    message = b""
    while True:
        ready, _, _ = select.select([0], [], [], POLL_SECONDS)
        if ready:
            chunk = os.read(0, 64)
            if not chunk:  # every writer (the driver) has closed its end, however it ended
                break
            message += chunk
        else:
            known.update(_grow(known))
    if message != _DONE:
        reap(known)


if __name__ == "__main__":
    _main(sys.argv[1:])
