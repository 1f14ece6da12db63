"""The modes a sweep can run, in one table the sweep, the store, the reports and the page read.

* ``offline`` (:mod:`.offline`): the paper's protocol, each test demonstration observed once per level;
* ``online`` (:mod:`.online`): every prefix of every test observation scored;
* ``open-set`` (:mod:`.open_set`): one goal held out of the fit per seed, to be answered "none of these";
* ``zero-shot`` (:mod:`.zero_shot`): a third of the goals held out of the fit, to be recognised all the same.

A new mode is one module defining a :class:`~.base.Mode` and one entry here.
"""

from __future__ import annotations

from grail_bench.core.registry import Registry
from grail_bench.harness.modes import offline, online, open_set, zero_shot
from grail_bench.harness.modes.base import Column, Mode, Record, Run, SeedRun

MODES: Registry[Mode] = Registry("mode")
for _mode in (offline.MODE, online.MODE, open_set.MODE, zero_shot.MODE):
    MODES.add(_mode.name, _mode)

ResultRow, OnlineRow, OpenSetRow = offline.ResultRow, online.OnlineRow, open_set.OpenSetRow
ZeroShotRow = zero_shot.ZeroShotRow
Row = ResultRow | OnlineRow | OpenSetRow | ZeroShotRow


def get_mode(name: str) -> Mode:
    """The mode called ``name``.

    Raises:
        UserError: For an unknown name, listing the known ones.
    """
    return MODES.get(name)


def mode_of(row_type: type) -> Mode:
    """The mode whose rows are of ``row_type``."""
    for mode in MODES.values():
        if mode.row is row_type:
            return mode
    raise TypeError(f"{row_type.__name__} is not the row type of any mode")


__all__ = ["MODES", "Column", "Mode", "OnlineRow", "OpenSetRow", "Record", "ResultRow", "Row", "Run", "SeedRun",
           "ZeroShotRow", "get_mode", "mode_of"]
