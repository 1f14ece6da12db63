"""The command line as one Click command, for tools that read Click (the docs site's CLI reference)."""

from __future__ import annotations

import click
import typer

from grail_bench.cli.app import app

#: ``grail-bench`` and its subcommands, as Click sees them.
command: click.Command = typer.main.get_command(app)
