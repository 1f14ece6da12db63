"""MkDocs hook: the command-line reference, rendered from the Typer app's Click command.

A page holding the marker ``<!-- cli-reference -->`` gets, in its place, a section per ``grail-bench`` command
with its help, usage and options, read from ``typer.main.get_command(grail_bench.cli.app)``. The command is read
by duck typing (``commands``, ``get_params``, ``get_help_record``), so it works whether Typer builds it on
Click itself or on the copy of Click it ships.
"""

from __future__ import annotations

import inspect
from typing import Any

MARKER = "<!-- cli-reference -->"
PROG = "grail-bench"


def _cell(text: str) -> str:
    return " ".join(text.replace("|", "\\|").replace("*", "\\*").split())


def _section(command: Any, ctx: Any, level: int) -> list[str]:
    out = [f"{'#' * level} `{ctx.command_path}`", ""]
    if command.help:
        out += [inspect.cleandoc(command.help).replace("\b\n", ""), ""]
    usage = " ".join([ctx.command_path, *command.collect_usage_pieces(ctx)])
    out += ["```text", usage, "```", ""]
    rows = [param.get_help_record(ctx) for param in command.get_params(ctx) if not getattr(param, "hidden", False)]
    rows = [row for row in rows if row is not None]
    if rows:
        out += ["| option | what it does |", "|---|---|"]
        out += [f"| `{_cell(names)}` | {_cell(help_text)} |" for names, help_text in rows]
        out.append("")
    return out


def reference() -> str:
    """Markdown for ``grail-bench`` and each of its commands, in name order."""
    import typer

    from grail_bench.cli.app import app

    group = typer.main.get_command(app)
    root = group.context_class(group, info_name=PROG)
    out = _section(group, root, 2)
    for name in sorted(group.commands):
        command = group.commands[name]
        if getattr(command, "hidden", False):
            continue
        out += _section(command, command.context_class(command, info_name=name, parent=root), 2)
    return "\n".join(out)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace the CLI marker with the generated reference."""
    return markdown.replace(MARKER, reference()) if MARKER in markdown else markdown
