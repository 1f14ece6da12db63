"""Progress on stderr: a live bar on a terminal, plain lines in a log.

A rich bar redrawn into a file (CI logs, ``2> run.log``) is cut to the console's width and leaves fragments such
as ``━━ 9… … eta 0:…``; where stderr is no terminal, :func:`progress` writes whole lines instead, one at most
every ``every`` seconds and one at the end.
"""

from __future__ import annotations

import sys
import time
from datetime import timedelta
from typing import Any, TextIO


def _clock(seconds: float) -> str:
    return str(timedelta(seconds=int(seconds)))


class LineProgress:
    """Progress as plain lines: ``description: 12/40 units, 0:01:05 elapsed, eta 0:02:31``."""

    def __init__(self, description: str, total: int, stream: TextIO | None = None, every: float = 10.0) -> None:
        self.description, self.total, self.every = description, total, every
        self.stream = stream if stream is not None else sys.stderr
        self.done = 0
        self.start = self.last = time.monotonic()

    def __enter__(self) -> LineProgress:
        self.start = self.last = time.monotonic()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.done and self.done < self.total:  # interrupted: say where it stopped
            self._line()

    def advance(self) -> None:
        """One more done; a line when ``every`` seconds have passed since the last, and at the end."""
        self.done += 1
        now = time.monotonic()
        if self.done >= self.total or now - self.last >= self.every:
            self.last = now
            self._line()

    def _line(self) -> None:
        elapsed = time.monotonic() - self.start
        eta = elapsed / self.done * (self.total - self.done) if self.done else 0.0
        tail = "done" if self.done >= self.total else f"eta {_clock(eta)}"
        print(f"{self.description}: {self.done}/{self.total}, {_clock(elapsed)} elapsed, {tail}", file=self.stream,
              flush=True)


class BarProgress:
    """A rich bar over one task (``advance()`` moves it), on stderr."""

    def __init__(self, description: str, total: int, columns: tuple = (), transient: bool = False) -> None:
        from rich.console import Console
        from rich.progress import Progress

        self.bar = Progress(*columns, console=Console(stderr=True), transient=transient)
        self.job = self.bar.add_task(description, total=total)

    def __enter__(self) -> BarProgress:
        self.bar.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.bar.__exit__(*exc)

    def advance(self) -> None:
        self.bar.advance(self.job)


def progress(description: str, total: int, columns: tuple = (), transient: bool = False) -> LineProgress | BarProgress:
    """A bar where stderr is a terminal, else plain lines (see the module docstring); use it as a context manager
    and call ``advance()`` per unit done."""
    from rich.console import Console

    if not Console(stderr=True).is_terminal:
        return LineProgress(description, total)
    return BarProgress(description, total, columns, transient)
