"""The ``grail-bench`` command line: parses, calls the library, maps errors to exit codes."""

from __future__ import annotations

import sys
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="grail-bench: goal-recognition benchmarks on gymnasium.")
console = Console()
err_console = Console(stderr=True)

EXIT_USAGE = 2


def fail(message: str, code: int = EXIT_USAGE) -> typer.Exit:
    """Print one error line to stderr and return the exit to raise."""
    err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    return typer.Exit(code)


def _tasks_table() -> Table:
    from grail_bench.task import make_task
    from grail_bench.registration import task_ids

    table = Table(title="GRAIL/ tasks")
    table.add_column("task", no_wrap=True, style="bold")
    for col in ("domain", "regime", "goals", "demos/goal (train/test)", "observability"):
        table.add_column(col)
    for task_id in task_ids():
        task = make_task(task_id)
        goals = " ".join("(" + ",".join(f"{c:g}" for c in g) + ")" for g in task.goals)
        table.add_row(task_id, task.domain, task.regime, goals,
                      f"{task.n_demos} ({task.n_train}/{task.n_demos - task.n_train})",
                      ", ".join(f"{p:.0%}" for p in task.observability))
    return table


@app.callback()
def _root() -> None:
    """grail-bench: goal-recognition benchmarks on gymnasium."""


@app.command()
def tasks() -> None:
    """List every registered GRAIL/ task with its domain, regime, goals and demo counts."""
    console.print(_tasks_table())


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except KeyboardInterrupt:
        err_console.print("interrupted; completed results are kept")
        sys.exit(130)


if __name__ == "__main__":
    main()
