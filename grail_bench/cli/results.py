"""The ``grail-bench results`` commands: the published format of results (:mod:`grail_bench.harness.published`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from grail_bench.cli.inputs import console, errors, open_store, outputs, say

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Results as data: the published format (JSON Lines under a JSON Schema), to export, import, "
                       "check and submit.")
STORE_HELP = "Results database (default: $GRAIL_BENCH_STORE or results.sqlite in the user data directory)."


@app.command()
def schema() -> None:
    """Print the JSON Schema of the published format."""
    from grail_bench.harness.published import schema as published_schema

    console.print_json(json.dumps(published_schema()))


@app.command()
def export(
    store_path: Optional[Path] = typer.Option(None, "--store", envvar="GRAIL_BENCH_STORE", help=STORE_HELP),
    out: Path = typer.Option(..., "--out", help="Folder to write the published files into (made to hold exactly "
                                                "this store's rows)."),
) -> None:
    """Write a store's rows in the published format: same store, byte-identical files."""
    from grail_bench.harness.published import export as export_store

    with errors():
        outputs(folders=[out])
        with open_store(store_path, must_exist=True) as store:
            written = export_store(store, out)
    say(f"wrote {len(written)} files into {out} ({sum(p.stat().st_size for p in written)} bytes)")


@app.command("import")
def import_(
    path: Path = typer.Argument(..., help="A published folder (or one row file in one)."),
    store_path: Optional[Path] = typer.Option(None, "--store", envvar="GRAIL_BENCH_STORE", help=STORE_HELP),
) -> None:
    """Build (or add to) a store from published files; rows already stored are kept."""
    from grail_bench.harness.published import read

    with errors():
        published = read(path)
        with open_store(store_path) as store:
            added = store.add(published.all_rows())
            where = store.path
    say(f"{added} of {len(published.all_rows())} rows added to {where}")
