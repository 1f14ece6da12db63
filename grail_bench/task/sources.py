"""Where task cards from outside the package are found: given paths, ``GRAIL_BENCH_CARDS`` and entry points.

* A path is a card file (``.toml``) or a folder, whose ``*.toml`` files (not its subfolders) are cards, in name
  order.
* ``GRAIL_BENCH_CARDS`` holds such paths, separated as ``PATH`` is (``:``; ``;`` on Windows).
* An installed package ships cards through the entry-point group ``grail_bench.cards``: each entry point names
  a package (``mylab = "mylab.cards"``: every ``*.toml`` in that package's folder) or one file or folder inside
  a package (``mylab = "mylab:cards.toml"``), read with :mod:`importlib.resources` (so from a wheel or a zip too).

This module only finds and parses cards (:class:`Card`); :mod:`grail_bench.task.registration` registers their
tasks and skips a broken one with one line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, Iterator

from grail_bench.core.registry import installed_entry_points
from grail_bench.task.cards import CardError, parse_card, read_card
from grail_bench.task.model import GRTask

#: The environment variable that lists card files and folders.
ENV_VAR = "GRAIL_BENCH_CARDS"
#: The entry-point group installed packages ship cards through.
GROUP = "grail_bench.cards"
SUFFIX = ".toml"


@dataclass(frozen=True)
class Card:
    """One card file from outside the package.

    Attributes:
        source: How messages name it: its absolute path, or ``package:file`` for a packaged card.
        entry: The file (a :class:`~pathlib.Path` or a package resource).
    """

    source: str
    entry: Any

    def tasks(self) -> list[GRTask]:
        """The card's tasks, validated.

        Raises:
            CardError: ``source: field: why``, for an unreadable or malformed card.
        """
        folder = self.entry.parent if isinstance(self.entry, Path) else None
        return parse_card(read_card(self.entry, self.source), self.source, folder)


def path_cards(path: str | os.PathLike[str]) -> list[Card]:
    """The cards at ``path``: the file itself, or a folder's ``*.toml`` files in name order.

    Raises:
        CardError: For a path that does not exist, or a file that is no ``.toml`` file.
    """
    given = Path(path).expanduser().absolute()
    if given.is_dir():
        return [Card(str(p), p) for p in sorted(given.glob(f"*{SUFFIX}")) if p.is_file()]
    if not given.exists():
        raise CardError(f"{given}: no such task card or folder of cards")
    if given.suffix != SUFFIX:
        raise CardError(f"{given}: a task card is a {SUFFIX} file")
    return [Card(str(given), given)]


def env_paths(environ: Any = None) -> list[str]:
    """The paths ``GRAIL_BENCH_CARDS`` lists (empty entries dropped)."""
    value = (os.environ if environ is None else environ).get(ENV_VAR, "")
    return [p for p in value.split(os.pathsep) if p.strip()]


def entry_point_cards() -> Iterator[Card | CardError]:
    """The cards installed packages ship (entry-point group ``grail_bench.cards``); an entry point that names
    nothing readable is a :class:`CardError` in their place, naming it."""
    for ep in installed_entry_points(GROUP):
        label = f"entry point {ep.name} = {ep.value}"
        try:
            root = files(ep.module)
            entry = root.joinpath(ep.attr) if ep.attr else root
            if entry.is_dir():
                yield from (Card(f"{ep.module}:{e.name}", e)
                            for e in sorted(entry.iterdir(), key=lambda e: e.name)
                            if e.name.endswith(SUFFIX) and e.is_file())
            elif entry.is_file():
                yield Card(f"{ep.module}:{ep.attr}", entry)
            else:
                yield CardError(f"{label}: names no card file or folder")
        except Exception as exc:  # noqa: BLE001 - a third party's package: whatever it raises, name it and go on
            yield CardError(f"{label}: cannot be read: {type(exc).__name__}: {exc}")
