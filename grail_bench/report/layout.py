"""Terminal tables that fit the console's width.

A table is offered in several layouts, widest first (:class:`Fitted`); the first whose every cell shows whole
at the console's width is drawn, so a name is never cut to ``…``: narrower layouts wrap other columns or stack
a row's values on lines of their own (:func:`stacked`). A legend under a table (its caption) says what
bracketed or marked values are.
"""

from __future__ import annotations

from typing import Iterable, Sequence

from rich import box
from rich.console import Console, ConsoleOptions, RenderResult
from rich.measure import Measurement
from rich.segment import Segment
from rich.table import Table
from rich.text import Text

Cell = str | Text


class Fitted:
    """The first of several layouts of one table whose cells all show whole at the width it is drawn at (else
    the last)."""

    def __init__(self, *layouts: Table) -> None:
        self.layouts = layouts

    def choose(self, console: Console, options: ConsoleOptions) -> Table:
        """The layout drawn at ``options.max_width``."""
        for table in self.layouts[:-1]:
            if whole(table, console, options):
                return table
        return self.layouts[-1]

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        yield self.choose(console, options)

    def __rich_measure__(self, console: Console, options: ConsoleOptions) -> Measurement:
        return Measurement.get(console, options, self.choose(console, options))


def whole(table: Table, console: Console, options: ConsoleOptions) -> bool:
    """Whether ``table`` drawn at ``options.max_width`` fits it and shows every cell whole (nothing cut to
    ``…``)."""
    for line in Segment.split_lines(console.render(table, options)):
        if Segment.get_line_length(line) > options.max_width or any("…" in segment.text for segment in line):
            return False
    return True


def grid_table(title: str, header: Sequence[str], rows: Iterable[Sequence[Cell]], caption: str | None = None,
               first_style: str | None = "bold") -> Table:
    """The plain layout: one column per header entry, one line (wrapped where it must) per row."""
    table = Table(title=title, caption=_caption(caption), caption_justify="left")
    for i, name in enumerate(header):
        table.add_column(name, style=first_style if i == 0 else None)
    for row in rows:
        table.add_row(*(_text(v) for v in row))
    return table


#: Widest the keys' column of :func:`stacked` grows (of an 80-column terminal: the values keep the rest).
KEY_WIDTH = 40


def stacked(title: str, header: Sequence[str], rows: Iterable[Sequence[Cell]], keys: int = 1,
            caption: str | None = None, key_width: int | None = KEY_WIDTH) -> Table:
    """The narrow layout: two columns, a row's first ``keys`` values stacked on the left (the first in bold),
    each other value on a line of its own on the right, after its header. A key longer than ``key_width``
    (a task label carrying a long parameter, ``problem=/a/long/path``) is cut with an ellipsis, so the values
    keep their room; None never cuts (names a user copies, such as task IDs)."""
    table = Table(title=title, caption=_caption(caption), caption_justify="left", show_lines=True, box=box.SQUARE)
    table.add_column("\n".join(header[:keys]), no_wrap=True, overflow="ellipsis", max_width=key_width)
    table.add_column("values")
    for row in rows:
        left = Text("\n").join(Text(_text(v).plain, style="bold" if i == 0 else "") for i, v in enumerate(row[:keys]))
        right = Text("\n").join(Text.assemble((f"{name}: ", "dim"), _text(value))
                                for name, value in zip(header[keys:], row[keys:]))
        table.add_row(left, right)
    return table


def _caption(caption: str | None) -> Text | None:
    """A legend as plain text (its brackets are values, not markup)."""
    return None if caption is None else Text(caption)


def _text(value: Cell) -> Text:
    return value if isinstance(value, Text) else Text(value)
