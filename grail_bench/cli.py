"""The ``grail-bench`` command line: parses, calls the library, maps errors to exit codes."""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path
from typing import Any, Iterator, List, Optional

import typer
from rich.console import Console
from rich.table import Table

from grail_bench.errors import UserError
from grail_bench.executors import WorkerLost

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="grail-bench: goal-recognition benchmarks on gymnasium.")
console = Console()
err_console = Console(stderr=True)

EXIT_USAGE = 2
DEFAULT_TASK = "GRAIL/MiniGrid-Biased-v0"
DEFAULT_RECOGNIZERS = ["bc", "graql"]


def fail(message: str) -> typer.Exit:
    """Print one error line to stderr and return the exit (code 2) to raise."""
    err_console.print(f"error: {message}", highlight=False, markup=False, soft_wrap=True)
    return typer.Exit(EXIT_USAGE)


def _user_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that mean bad input, reported as one line with exit code 2 (anything else is a bug)."""
    from gymnasium.error import Error as GymError

    return (GymError, UserError)


WORKERS_HELP = "Run units in parallel on this many processes (local) or CPUs (a new local Ray instance)."
EXECUTOR_HELP = "serial, local (a process pool) or ray (default: local with --workers > 1, ray with --address)."
ADDRESS_HELP = "A Ray cluster to run on: auto or HOST:PORT (implies --executor ray)."


@contextlib.contextmanager
def _executor(name: Optional[str], workers: Optional[int], address: Optional[str]) -> Iterator[Any]:
    """The chosen executor, shut down (its unfinished units cancelled) however the block ends."""
    from grail_bench.executors import make_executor

    chosen = make_executor(name, workers, address)
    try:
        yield chosen
    finally:
        chosen.close()


def _lost(exc: Exception) -> typer.Exit:
    """A worker died: say so in one line; finished units are stored and a rerun resumes."""
    err_console.print(f"error: {exc}; the units that finished are stored: run the same command again to resume",
                      highlight=False, markup=False, soft_wrap=True)
    return typer.Exit(1)


def _open_store(path: Optional[Path]):
    from grail_bench.store import ResultsStore, default_store_path

    return ResultsStore(path or default_store_path())


def _tasks_table() -> Table:
    from grail_bench.registration import task_ids
    from grail_bench.task import make_task

    table = Table(title="GRAIL/ tasks")
    table.add_column("task", no_wrap=True, style="bold")
    for col in ("domain", "regime", "goals", "demos/goal (train/test)", "observability", "protocol"):
        table.add_column(col)
    for task_id in task_ids():
        task = make_task(task_id)
        goals = " ".join("(" + ",".join(f"{c:g}" for c in g) + ")" for g in task.goals)
        table.add_row(task_id, task.domain, task.regime, goals,
                      f"{task.n_demos} ({task.n_train}/{task.n_demos - task.n_train})",
                      ", ".join(f"{p:.0%}" for p in task.observability), task.protocol)
    return table


@app.callback()
def _root() -> None:
    """grail-bench: goal-recognition benchmarks on gymnasium."""


@app.command()
def tasks() -> None:
    """List every registered GRAIL/ task with its domain, regime, goals and demo counts."""
    console.print(_tasks_table())


@app.command("list")
def list_(what: str = typer.Argument("all", help="tasks, recognizers, scorers or all")) -> None:
    """List tasks, recognizers and scorers (imports no recognizer code)."""
    from grail_bench.recognizers.registry import available_recognizers

    if what not in ("all", "tasks", "recognizers", "scorers"):
        raise fail(f"cannot list {what!r}; choose tasks, recognizers, scorers or all")
    if what in ("all", "tasks"):
        console.print(_tasks_table())
    if what in ("all", "recognizers"):
        table = Table(title="recognizers (entry-point group grail_bench.recognizers)")
        table.add_column("name", style="bold")
        table.add_column("provided by")
        for name, target in available_recognizers().items():
            table.add_row(name, target)
        console.print(table)
    if what in ("all", "scorers"):
        from grail_bench.scoring import BUILTIN, available_scorers

        table = Table(title="scorers (entry-point group grail_bench.scorers)")
        table.add_column("name", style="bold")
        table.add_column("what it computes")
        for name, target in available_scorers().items():
            table.add_row(name, BUILTIN[name].description if name in BUILTIN else target)
        console.print(table)


def _value(raw: str) -> Any:
    """A command-line value: JSON when it parses (numbers, lists, booleans), else the string."""
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        return raw


def _parse_settings(settings: List[str], names: List[str]) -> dict[str, dict[str, Any]]:
    """``["bc.n_epochs=10"]`` -> ``{"bc": {"n_epochs": 10}}``."""
    out: dict[str, dict[str, Any]] = {name: {} for name in names}
    for item in settings:
        key, sep, raw = item.partition("=")
        name, dot, param = key.partition(".")
        if not sep or not dot or not param:
            raise UserError(f"--set expects RECOGNIZER.PARAM=VALUE, got {item!r}")
        if name not in out:
            raise UserError(f"--set {item!r} names recognizer {name!r}, which is not being run")
        out[name][param] = _value(raw)
    return out


def _parse_params(params: List[str]) -> dict[str, Any]:
    """``["turn_prob=0.5"]`` -> ``{"turn_prob": 0.5}``."""
    out = {}
    for item in params:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise UserError(f"--param expects NAME=VALUE, got {item!r}")
        out[key] = _value(raw)
    return out


@app.command()
def run(
    task: str = typer.Option(DEFAULT_TASK, "--task", "-t", help="A GRAIL/ task ID."),
    recognizer: Optional[List[str]] = typer.Option(None, "--recognizer", "-r",
                                                   help="Recognizer name; repeat for several (default: bc, graql)."),
    seeds: int = typer.Option(3, "--seeds", "-s", min=1, help="Seeds 0..N-1 (the paper uses 10)."),
    observability: Optional[str] = typer.Option(None, "--observability", "-o",
                                                help="Comma-separated fractions, e.g. 0.1,0.2,0.3 (default: the task's)."),
    protocol: Optional[str] = typer.Option(
        None, "--protocol", "-p", help="Observation protocol (see `grail-bench protocols`; default: the task's)."),
    rounding: str = typer.Option("ceil", help="Observed pairs k = ceil(p*T) (ceil) or gr_libs' int(p*T) (floor)."),
    sampling: Optional[str] = typer.Option(None, "--sampling", hidden=True,
                                           help="Deprecated alias of --protocol (random = subset)."),
    scorer: Optional[List[str]] = typer.Option(None, "--scorer",
                                               help="Scorer; repeat for several (default: each recognizer's own)."),
    settings: Optional[List[str]] = typer.Option(None, "--set", help="Recognizer hyperparameter, e.g. bc.n_epochs=50."),
    params: Optional[List[str]] = typer.Option(
        None, "--param", help="Task parameter, as gym.make takes it, e.g. turn_prob=0.5, expert=scripted, n_demos=20."),
    json_path: Optional[Path] = typer.Option(None, "--json", help="Also write the records to this JSON file."),
    store_path: Optional[Path] = typer.Option(None, "--store", envvar="GRAIL_BENCH_STORE",
                                              help="Results database (default: ~/.local/share/grail-bench/results.sqlite)."),
    progress: bool = typer.Option(True, help="Show progress bars."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", help=WORKERS_HELP),
    executor: Optional[str] = typer.Option(None, "--executor", "-x", help=EXECUTOR_HELP),
    address: Optional[str] = typer.Option(None, "--address", help=ADDRESS_HELP),
    online: bool = typer.Option(False, "--online", help="Score every prefix k = 1..T: convergence point, step "
                                "accuracy, F1 area (no --observability)."),
    open_set: bool = typer.Option(False, "--open-set", help="Hold one goal out per seed (each in turn) and "
                                  "measure answering 'none of these' (tasks with 3 or more goals)."),
) -> None:
    """Benchmark recognizers on one task; finished seeds in the store are reused."""
    from grail_bench.evaluation.runner import RecognizerSpec, evaluate

    if online and open_set:
        raise fail("choose one of --online and --open-set")
    if online and observability is not None:
        raise fail("--online scores every prefix k = 1..T; it takes no --observability")
    mode = "online" if online else "open-set" if open_set else "offline"
    names = list(dict.fromkeys(recognizer or DEFAULT_RECOGNIZERS))
    if sampling is not None:
        if protocol is not None:
            raise fail("give --protocol only (--sampling is its deprecated alias)")
        err_console.print("warning: --sampling is deprecated; use --protocol", highlight=False)
        protocol = {"random": "subset"}.get(sampling, sampling)
    try:
        config = _parse_settings(settings or [], names)
        with _open_store(store_path) as store, _executor(executor, workers, address) as chosen:
            scorers = tuple(dict.fromkeys(scorer or []))
            records = evaluate(task, [RecognizerSpec(n, config[n], scorers) for n in names], seeds=seeds,
                               observability=observability, protocol=protocol, rounding=rounding, store=store,
                               progress=progress, task_params=_parse_params(params or []), executor=chosen,
                               mode=mode)
            where = store.path
    except _user_errors() as exc:
        raise fail(str(exc)) from None
    except WorkerLost as exc:
        raise _lost(exc) from None
    if mode == "offline":
        _offline_tables(records)
    else:
        from grail_bench.reports import ONLINE_TITLE, OPEN_SET_TITLE, online_grid, open_set_grid, rich_table

        grid, title = (online_grid, ONLINE_TITLE) if online else (open_set_grid, OPEN_SET_TITLE)
        console.print(rich_table(grid(records), title))
    console.print(f"results stored in {where}", highlight=False)
    if json_path is not None:
        json_path.write_text(json.dumps(records, indent=2) + "\n", encoding="utf-8")
        console.print(f"records written to {json_path}", highlight=False)


def _offline_tables(records: list[dict[str, Any]]) -> None:
    """The paper-style F1 tables (with Bayes ceilings) and the timings of a run."""
    from grail_bench.leaderboard import build_boards, rich_tables

    with console.status("Bayes ceilings (computed once, then cached)"):
        boards = build_boards(records)
    for table in rich_tables(boards):
        console.print(table)
    timing = Table(title="timings (mean over seeds)")
    for col in ("recognizer", "scorer", "fit s/goal", "score µs/observation"):
        timing.add_column(col)
    pairs = dict.fromkeys((r["recognizer"], r["scorer"]) for r in records)
    for name, scorer_name in pairs:
        mine = [r for r in records if (r["recognizer"], r["scorer"]) == (name, scorer_name)]
        timing.add_row(name, scorer_name, f"{mine[0]['fit_seconds_per_goal']:.2f}",
                       f"{sum(r['score_us_per_observation'] for r in mine) / len(mine):.0f}")
    console.print(timing)


@app.command()
def leaderboard(
    store_path: Optional[Path] = typer.Option(None, "--store", envvar="GRAIL_BENCH_STORE", help="Results database."),
    markdown_path: Optional[Path] = typer.Option(None, "--markdown", help="Also write the leaderboard as Markdown here."),
    reference: Optional[Path] = typer.Option(None, "--reference",
                                             help="CSV of reported values (task,recognizer,observability,f1) to show beside ours."),
    task: Optional[List[str]] = typer.Option(None, "--task", "-t", help="Only these tasks."),
    scorer: Optional[List[str]] = typer.Option(
        None, "--scorer", help="Only these scorers (NAME), or recognizer/scorer pairs (e.g. bc/mse)."),
    protocol: Optional[List[str]] = typer.Option(
        None, "--protocol", "-p", help="Only these observation protocols (as stored, e.g. subset, prefix+floor)."),
    ceiling_samples: int = typer.Option(2000, min=2, help="Monte Carlo samples of the Bayes ceilings (cached)."),
    no_ceiling: bool = typer.Option(False, "--no-ceiling", help="Do not compute or show Bayes ceilings."),
    ablation: bool = typer.Option(False, "--ablation", help="Compare scorers: F1 and scoring time per scorer."),
    online: bool = typer.Option(False, "--online", help="The online runs (`run --online`) instead."),
    open_set: bool = typer.Option(False, "--open-set", help="The open-set runs (`run --open-set`) instead."),
    plot: Optional[Path] = typer.Option(
        None, "--plot", help="With --ablation or --online: also write a PNG plot here."),
    html: Optional[Path] = typer.Option(
        None, "--html", help="Also write the leaderboard as a static web page into this folder (index.html)."),
) -> None:
    """Paper-style F1 tables from the results store."""
    from grail_bench.evaluation.runner import aggregate
    from grail_bench.leaderboard import (ablation_markdown, ablation_plot, ablation_rows, ablation_table,
                                         build_boards, markdown, read_reference, rich_tables)

    from grail_bench.store import OnlineRow, OpenSetRow, ResultRow, default_store_path

    if sum((ablation, online, open_set)) > 1:
        raise fail("choose one of --ablation, --online and --open-set")
    if plot is not None and not (ablation or online):
        raise fail("--plot needs --ablation or --online")
    if html is not None and (online or open_set):
        raise fail("--html shows the paper's protocol only; drop --online / --open-set")
    path = store_path or default_store_path()
    if not path.exists():
        raise fail(f"no results store at {path}; run `grail-bench run` first")
    if online or open_set:
        _study_board(path, online, task, scorer, protocol, markdown_path, plot, None if no_ceiling else ceiling_samples)
        return
    try:
        ref = read_reference(reference) if reference else None
        with _open_store(path) as store:
            rows = _select(store, ResultRow, task, scorer, protocol)
            studies = ({"online": _select(store, OnlineRow, task, scorer, protocol),
                        "open_set": _select(store, OpenSetRow, task, scorer, protocol)} if html is not None else {})
            records = aggregate(rows)
    except OSError as exc:
        raise fail(f"cannot read {exc.filename}: {exc.strerror}") from None
    except _user_errors() as exc:
        raise fail(str(exc)) from None
    if not records:
        raise fail(f"no results in {path} yet; run `grail-bench run` first")
    if ablation:
        rows = ablation_rows(records)
        if not rows:
            raise fail("no recognizer was run with several scorers; use `grail-bench run --scorer A --scorer B`")
        console.print(ablation_table(rows))
        if markdown_path is not None:
            markdown_path.parent.mkdir(parents=True, exist_ok=True)
            markdown_path.write_text(ablation_markdown(rows), encoding="utf-8")
            console.print(f"Markdown written to {markdown_path}", highlight=False)
        if plot is not None:
            plot.parent.mkdir(parents=True, exist_ok=True)
            ablation_plot(rows, plot)
            console.print(f"plot written to {plot}", highlight=False)
        return
    try:
        with console.status("Bayes ceilings (computed once, then cached)"):
            boards = build_boards(records, ref, None if no_ceiling else ceiling_samples)
    except _user_errors() as exc:
        raise fail(str(exc)) from None
    for table in rich_tables(boards):
        console.print(table)
    if markdown_path is not None:
        markdown_path.parent.mkdir(parents=True, exist_ok=True)
        markdown_path.write_text(markdown(boards, records), encoding="utf-8")
        console.print(f"Markdown written to {markdown_path}", highlight=False)
    if html is not None:
        from grail_bench.site import write_site

        try:
            with console.status("web page (bootstrap intervals)"):
                index = write_site(rows, html, ref, None if no_ceiling else ceiling_samples, **studies)[0]
        except OSError as exc:
            raise fail(f"cannot write {exc.filename}: {exc.strerror}") from None
        console.print(f"web page written to {index}", highlight=False)


def _select(store: Any, kind: type, task: Optional[List[str]], scorer: Optional[List[str]],
            protocol: Optional[List[str]]) -> list[Any]:
    """Stored rows of one kind, narrowed by the leaderboard's --task, --scorer and --protocol."""
    where = ({"protocol": protocol} if protocol else {}) | ({"task": task} if task else {})
    return [r for r in store.select(kind, **where)
            if not scorer or r.scorer in scorer or f"{r.recognizer}/{r.scorer}" in scorer]


def _study_board(path: Path, online: bool, task: Optional[List[str]], scorer: Optional[List[str]],
                 protocol: Optional[List[str]], markdown_path: Optional[Path], plot: Optional[Path],
                 ceiling_samples: Optional[int]) -> None:
    """``leaderboard --online`` / ``--open-set``: across-seed tables (and the online plot, with the Bayes
    ceiling where the task has one) from the store."""
    from grail_bench.evaluation.online import aggregate_online
    from grail_bench.evaluation.open_set import aggregate_open_set
    from grail_bench.reports import (ONLINE_INTRO, ONLINE_TITLE, OPEN_SET_INTRO, OPEN_SET_TITLE, markdown_table,
                                     online_ceilings, online_grid, online_plot, open_set_grid, rich_table)
    from grail_bench.store import OnlineRow, OpenSetRow

    kind, flag = (OnlineRow, "--online") if online else (OpenSetRow, "--open-set")
    try:
        with _open_store(path) as store:
            rows = _select(store, kind, task, scorer, protocol)
    except _user_errors() as exc:
        raise fail(str(exc)) from None
    if not rows:
        raise fail(f"no {flag.removeprefix('--')} results in {path} yet; run `grail-bench run {flag}` first")
    records = (aggregate_online if online else aggregate_open_set)(rows)
    grid, title, intro = ((online_grid(records), ONLINE_TITLE, ONLINE_INTRO) if online
                          else (open_set_grid(records), OPEN_SET_TITLE, OPEN_SET_INTRO))
    console.print(rich_table(grid, title))
    try:
        if markdown_path is not None:
            markdown_path.parent.mkdir(parents=True, exist_ok=True)
            markdown_path.write_text(markdown_table(grid, title, intro), encoding="utf-8")
            console.print(f"Markdown written to {markdown_path}", highlight=False)
        if plot is not None:
            ceilings = online_ceilings(records, ceiling_samples, progress=True)
            console.print(f"plot written to {online_plot(records, plot, ceilings)}", highlight=False)
    except OSError as exc:
        raise fail(f"cannot write {exc.filename}: {exc.strerror}") from None
    except _user_errors() as exc:
        raise fail(str(exc)) from None


@app.command()
def reproduce(
    profile: str = typer.Option("quick", "--profile", help="quick (2 seeds, small budgets), paper, or a TOML file."),
    only: Optional[List[str]] = typer.Option(None, "--only",
                                             help="Only this section (minigrid, panda, online, open-set); repeatable."),
    out: Path = typer.Option(..., "--out", help="Folder for the tables, figures and manifest.json."),
    store_path: Optional[Path] = typer.Option(None, "--store", help="Results database (default: OUT/results.sqlite)."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", help=WORKERS_HELP),
    executor: Optional[str] = typer.Option(None, "--executor", "-x", help=EXECUTOR_HELP),
    address: Optional[str] = typer.Option(None, "--address", help=ADDRESS_HELP),
    progress: bool = typer.Option(True, help="Show a progress bar."),
) -> None:
    """Run a profile's grid (resuming from the store), then write the paper's tables and figures."""
    from datetime import datetime, timezone

    from grail_bench.evaluation.sweep import MODES, run_sweep
    from grail_bench.provenance import git_commit
    from grail_bench.reproduce import load_profile, manifest, write_outputs

    started = datetime.now(timezone.utc)
    commit = git_commit()
    try:
        chosen_profile = load_profile(profile)
        requests = chosen_profile.requests(only or ())
        with _open_store(store_path or out / "results.sqlite") as store, \
                _executor(executor, workers, address) as chosen:
            summary = run_sweep(requests, store, chosen, progress=progress, description=f"reproduce {profile}")
            meta = manifest(sys.argv, chosen_profile, only or [], chosen, started, summary, commit)
            tasks = sorted({r.task_id for r in requests})
            rows = [row for kind in MODES.values() for row in store.select(kind, task=tasks)]
        with console.status("tables, figures and web page"):
            written = write_outputs(rows, chosen_profile, requests, out, meta)
    except _user_errors() as exc:
        raise fail(str(exc)) from None
    except WorkerLost as exc:
        raise _lost(exc) from None
    except OSError as exc:
        raise fail(f"cannot write {exc.filename}: {exc.strerror}") from None
    console.print(f"{summary.units} units ({summary.skipped} already stored) in {summary.seconds:.0f} s on "
                  f"{chosen.name} x {chosen.workers}; models trained {summary.trained}, reused from the cache "
                  f"{summary.reused}, a run without reuse would train {summary.naive}", highlight=False)
    for path in written:
        console.print(f"wrote {path}", highlight=False)


@app.command()
def protocols() -> None:
    """List the observation protocols (built in and from the entry-point group grail_bench.protocols)."""
    from grail_bench.evaluation.protocol import BUILTIN, available_protocols, get_protocol

    table = Table(title="observation protocols (entry-point group grail_bench.protocols)")
    table.add_column("name", style="bold")
    table.add_column("leaks the goal")
    table.add_column("what a recognizer observes")
    try:
        for name, target in available_protocols().items():
            chosen = BUILTIN.get(name) or get_protocol(name)
            table.add_row(name, "yes" if chosen.leaks_goal else "no",
                          chosen.description + ("" if name in BUILTIN else f" ({target})"))
    except _user_errors() as exc:
        raise fail(str(exc)) from None
    console.print(table)
    console.print("k = max(1, ceil(p * T)) pairs, or floor with --rounding floor (gr_libs' int(p * T)).",
                  highlight=False)


@app.command()
def ceiling(
    task: str = typer.Option(DEFAULT_TASK, "--task", "-t", help="A GRAIL/ task ID (MiniGrid)."),
    protocol: Optional[str] = typer.Option(None, "--protocol", "-p", help="Observation protocol (default: the task's)."),
    observability: Optional[str] = typer.Option(None, "--observability", "-o",
                                                help="Comma-separated fractions (default: the task's)."),
    rounding: str = typer.Option("ceil", help="ceil or floor, as for `run`."),
    method: str = typer.Option("auto", help="auto (exact where it can enumerate), exact or monte-carlo."),
    samples: int = typer.Option(2000, min=2, help="Monte Carlo observations."),
    seed: int = typer.Option(0, min=0, help="Monte Carlo seed."),
    params: Optional[List[str]] = typer.Option(None, "--param", help="Task parameter, e.g. turn_pattern=around-and-back."),
    json_path: Optional[Path] = typer.Option(None, "--json", help="Also write the ceilings to this JSON file."),
) -> None:
    """The Bayes ceiling: the best accuracy any recognizer can reach under a protocol and level."""
    from grail_bench.evaluation.ceiling import bayes_ceiling
    from grail_bench.evaluation.protocol import parse_observability
    from grail_bench.task import make_task

    try:
        gr_task = make_task(task, **_parse_params(params or []))
        levels = parse_observability(observability) if observability else gr_task.observability
        name = protocol or gr_task.protocol
        with console.status("computing the Bayes ceiling"):
            results = [bayes_ceiling(gr_task, name, level, rounding=rounding, method=method, samples=samples,
                                     seed=seed) for level in levels]
    except _user_errors() as exc:
        raise fail(str(exc)) from None
    table = Table(title=f"Bayes ceiling (accuracy): {task}")
    for col in ("protocol", "obs", "ceiling", "std. error", "chance", "method"):
        table.add_column(col)
    for c in results:
        table.add_row(c.protocol, f"{c.observability:.0%}", f"{c.accuracy:.3f}",
                      f"{c.stderr:.3f}" if c.method == "monte-carlo" else "exact", f"{c.chance:.3f}",
                      c.method + (f" ({c.samples} samples)" if c.samples else ""))
    console.print(table)
    if json_path is not None:
        json_path.write_text(json.dumps([c.as_dict() for c in results], indent=2) + "\n", encoding="utf-8")
        console.print(f"ceilings written to {json_path}", highlight=False)


def _one_line_warnings() -> None:
    """Show grail-bench's own warnings (e.g. a cached model being retrained) as one line."""
    import warnings

    from grail_bench.cache import CacheWarning

    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        if issubclass(category, CacheWarning):
            err_console.print(f"warning: {message}", highlight=False, markup=False, soft_wrap=True)
        else:
            default(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def main() -> None:
    """Console-script entry point."""
    _one_line_warnings()
    try:
        app()
    except KeyboardInterrupt:
        err_console.print("interrupted; finished units are kept in the store: run the same command to resume")
        sys.exit(130)


if __name__ == "__main__":
    main()
