"""The ``grail-bench results`` commands: the published format of results (:mod:`grail_bench.harness.published`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import typer

from grail_bench.cli.inputs import CARDS_HELP, console, err_console, errors, fail, open_store, outputs, say, use_cards

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


@app.command()
def validate(
    path: Path = typer.Argument(..., help="A submission: a published folder (or one row file in one)."),
    need_outputs: bool = typer.Option(True, "--outputs/--no-outputs",
                                      help="Require per-instance outputs of every row, of every mode, and "
                                           "recompute its metrics (--no-outputs: for rows published before "
                                           "outputs were kept)."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """Check a submission: the schema, that its tasks exist, that seeds and levels are complete, and that its
    metrics are those its per-instance outputs give."""
    from grail_bench.harness.submissions import MAX_LISTED
    from grail_bench.harness.submissions import validate as validate_submission

    with errors():
        use_cards(cards)
        published, problems = validate_submission(path, need_outputs)
    if problems:
        for problem in problems[:MAX_LISTED]:
            err_console.print(f"problem: {problem}", highlight=False, markup=False, soft_wrap=True)
        more = f", {len(problems) - MAX_LISTED} not listed" if len(problems) > MAX_LISTED else ""
        raise fail(f"{path} is not valid: {len(problems)} problem(s){more}")
    counts = ", ".join(f"{len(rows)} {kind}" for kind, rows in sorted(published.rows.items()))
    checked = "every metric recomputed from its outputs" if need_outputs else "outputs not checked"
    say(f"{path} is valid: {counts} rows; {checked}")


@app.command()
def merge(
    path: Path = typer.Argument(..., help="A valid submission folder, with its source.json."),
    store_path: Optional[Path] = typer.Option(None, "--store", envvar="GRAIL_BENCH_STORE", help=STORE_HELP),
) -> None:
    """Bring a validated submission into a store, its rows labelled by their source (shown as submitted)."""
    from grail_bench.harness.submissions import merge_rows

    with errors():
        rows = merge_rows(path)  # checked before the store is opened: a refused submission leaves it untouched
        with open_store(store_path) as store:
            added = store.add(rows)
            where = store.path
    say(f"{added} rows merged into {where}")


@app.command()
def verify(
    path: Path = typer.Argument(..., help="A submission folder (or one row file in one)."),
    sample: int = typer.Option(3, "--sample", "-n", min=1, max=1000,
                               help="Units to run again here, drawn over the rows of every mode (a unit: task, "
                                    "recognizer, configuration, seed, protocol and mode)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the draw of units."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """Run a sample of a submission's units (offline, online, open-set or zero-shot) again from its recognizer's
    entry point (installed here) and report how many rows agree exactly on every metric their mode recomputes."""
    from grail_bench.harness.submissions import verify as verify_submission

    with errors():
        use_cards(cards)
        with console.status(f"running {sample} unit(s) again"):
            results = verify_submission(path, sample, seed)
    for r in results:
        say(f"{r.unit}: {r.agreeing}/{r.rows} rows agree (largest F1 gap {r.max_f1_gap:.3g})")
    agree = sum(r.agreeing == r.rows for r in results)
    say(f"agreement: {agree}/{len(results)} units, {sum(r.agreeing for r in results)}/"
        f"{sum(r.rows for r in results)} rows")
