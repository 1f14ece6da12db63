"""The ``grail-bench`` commands: each parses its options, calls the library and maps errors (:mod:`.inputs`)."""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path
from typing import List, Optional

import typer
from typer.core import TyperGroup

from grail_bench.cli.inputs import (
    CARDS_HELP,
    check_store,
    console,
    err_console,
    errors,
    fail,
    is_task_path,
    mode_name,
    named_tasks,
    one_line_warnings,
    one_task,
    open_store,
    outputs,
    refuse_repeated_options,
    say,
    task_filters,
    task_object,
    use_cards,
    write_text,
)
from grail_bench.cli.inputs import executor as make_executor
from grail_bench.cli.inputs import params as parse_params
from grail_bench.cli.inputs import settings as parse_settings
from grail_bench.cli.results import app as results_app
from grail_bench.task.observation import level_text


class _Commands(TyperGroup):
    """The command group: an option that takes one value, given twice, is refused instead of the last kept."""

    def parse_args(self, ctx: typer.Context, args: list[str]) -> list[str]:
        name = next((a for a in args if not a.startswith("-")), None)
        command = self.get_command(ctx, name) if name is not None else None
        if command is not None:
            refuse_repeated_options(command, args[args.index(name) + 1:])
        return super().parse_args(ctx, args)


app = typer.Typer(cls=_Commands, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="grail-bench: goal-recognition benchmarks on gymnasium.")
app.add_typer(results_app, name="results")

DEFAULT_TASK = "GRAIL/MiniGrid-Biased-v0"
DEFAULT_RECOGNIZERS = ["bc", "graql"]
WORKERS_HELP = "Run units in parallel on this many processes (local) or CPUs (a new local Ray instance)."
EXECUTOR_HELP = "serial, local (a process pool) or ray (default: local with --workers > 1, ray with --address)."
ADDRESS_HELP = "A Ray cluster to run on: auto or HOST:PORT (implies --executor ray)."
MODE_HELP = ("offline (the paper's protocol), online, open-set or zero-shot (a third of the goals never fitted; "
             "goal-conditioned recognizers only). --online and --open-set are shortcuts.")
NOISE_HELP = ("Share of the observed steps made spurious: the state kept, another action shown (a uniform draw "
              "in a box); rows are stored as e.g. subset+noise0.2.")
CHANNEL_HELP = "What a recognizer observes: pairs, states or actions (the recognizer must declare it)."
STORE_HELP = ("Results database (default: results.sqlite in the grail-bench folder of the user data directory, "
              "~/.local/share).")


@app.callback()
def _root() -> None:
    """grail-bench: goal-recognition benchmarks on gymnasium."""


TASK_FILTER_HELP = ("Only these tasks: full IDs or globs, e.g. 'GRAIL/MiniGrid-*' (quote globs), or a symbolic "
                    "problem set's path as `run` takes it (its tasks); repeat for several.")
ONE_TASK_HELP = ("A task ID (GRAIL/... or one of --cards'), or a symbolic problem set's path as `run` takes it "
                 "(one holding a single task).")
DOMAIN_FILTER_HELP = "Only this domain's tasks (e.g. minigrid, point_maze); repeat for several."
METHOD_FILTER_HELP = "Only this method: a recognizer (bc), its published name (BC-GRAIL) or recognizer/scorer; globs."


def _all_tasks(task: Optional[List[str]] = None, domain: Optional[List[str]] = None) -> list:
    """The tasks `tasks` and `list` show: every registered one, or those ``--task`` and ``--domain`` select (a
    problem set's path, its tasks)."""
    from grail_bench.report.filters import Filters
    from grail_bench.task import make_task, task_ids

    names, own = task_filters(task)
    filters = Filters.of(names, domain)
    ids = list(dict.fromkeys([*task_ids(), *(t.id for t in own)]))
    if filters:
        filters.check_tasks(ids)
        ids = [t for t in ids if filters.task(t)]
    return [make_task(task_id) for task_id in ids]


@app.command()
def tasks(
    task: Optional[List[str]] = typer.Option(None, "--task", "-t", help=TASK_FILTER_HELP),
    domain: Optional[List[str]] = typer.Option(None, "--domain", "-d", help=DOMAIN_FILTER_HELP),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """List every registered task, GRAIL/ and your cards' (full IDs, as --task takes them) with its domain, regime, goals and demo
    counts."""
    from grail_bench.report.tables import tasks_table

    with errors():
        use_cards(cards)
        console.print(tasks_table(_all_tasks(task, domain)))
    _say_skipped_cards()


def _say_not_loaded(rows: list) -> None:
    """One line when rows belong to a user's own tasks not known here (a card not loaded, a problem set not read):
    their configurations are judged by their recognizers' settings alone (:func:`~grail_bench.report.configs.
    not_loaded`), and how to check them in full."""
    from grail_bench.domains.symbolic.problem_set import PREFIX
    from grail_bench.report.configs import not_loaded

    missing = sorted({r.task for r in rows if not_loaded(r.task)})
    sets = [t for t in missing if t.startswith(PREFIX)]
    cards = [t for t in missing if not t.startswith(PREFIX)]
    parts = ([f"the problem set {_names(sets)} (give --task PATH to check it)"] if sets else []) + \
            ([f"the cards of {_names(cards)} (give --cards PATH or GRAIL_BENCH_CARDS)"] if cards else [])
    if parts:
        say(f"not loaded here, their rows judged by their recognizers' settings alone: {'; '.join(parts)}")


def _names(names: list[str], shown: int = 3) -> str:
    """``a, b, c and 4 more``."""
    more = f" and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more


def _say_skipped_cards() -> None:
    """One line per broken task card that was skipped (its tasks are absent)."""
    from grail_bench.task.cards import skipped_cards

    for card, why in skipped_cards().items():
        say(f"skipped the broken task card {card}: {why}")


@app.command("list")
def list_(
    what: str = typer.Argument("all", help="tasks, recognizers, scorers or all"),
    task: Optional[List[str]] = typer.Option(None, "--task", "-t", help=TASK_FILTER_HELP),
    domain: Optional[List[str]] = typer.Option(None, "--domain", "-d", help=DOMAIN_FILTER_HELP),
    method: Optional[List[str]] = typer.Option(None, "--method", help=METHOD_FILTER_HELP),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """List tasks, recognizers and scorers (imports no recognizer code)."""
    from grail_bench.recognizers.registry import available_recognizers
    from grail_bench.recognizers.scoring import BUILTIN, available_scorers
    from grail_bench.report.filters import Filters
    from grail_bench.report.tables import names_table, tasks_table

    if what not in ("all", "tasks", "recognizers", "scorers"):
        raise fail(f"cannot list {what!r}; choose tasks, recognizers, scorers or all")
    filters = Filters.of(task, domain, method)
    with errors():
        use_cards(cards)
        if what in ("all", "tasks"):
            console.print(tasks_table(_all_tasks(task, domain)))
            _say_skipped_cards()
        if what in ("all", "recognizers"):
            console.print(names_table("recognizers (entry-point group grail_bench.recognizers)",
                                      [(n, t) for n, t in available_recognizers().items() if filters.method(n)],
                                      "provided by"))
        if what in ("all", "scorers"):
            rows = [(n, BUILTIN[n].description if n in BUILTIN else t) for n, t in available_scorers().items()]
            console.print(names_table("scorers (entry-point group grail_bench.scorers)", rows, "what it computes"))


@app.command()
def run(
    task: Optional[List[str]] = typer.Option(
        None, "--task", "-t", help=f"A task ID (GRAIL/... or one of --cards'), or a symbolic problem set (an archive "
                                   f"or folder in the PDDL dataset's layout, or a folder of them); repeat for "
                                   f"several. Default: {DEFAULT_TASK}"),
    recognizer: Optional[List[str]] = typer.Option(None, "--recognizer", "-r",
                                                   help="Recognizer name; repeat for several (default: bc, graql)."),
    seeds: int = typer.Option(3, "--seeds", "-s", help="Seeds 0..N-1 (the paper uses 10)."),
    observability: Optional[str] = typer.Option(None, "--observability", "-o",
                                                help="Comma-separated fractions, e.g. 0.1,0.2,0.3 (default: the task's)."),
    protocol: Optional[str] = typer.Option(
        None, "--protocol", "-p", help="Observation protocol (see `grail-bench protocols`; default: the task's)."),
    rounding: Optional[str] = typer.Option(
        None, help="Observed pairs k = ceil(p*T) (ceil) or gr_libs' int(p*T) (floor); default: the task's."),
    sampling: Optional[str] = typer.Option(None, "--sampling", hidden=True,
                                           help="Deprecated alias of --protocol (random = subset)."),
    noise: float = typer.Option(0.0, "--noise", help=NOISE_HELP),
    channel: str = typer.Option("pairs", "--channel", help=CHANNEL_HELP),
    observation: Optional[str] = typer.Option(
        None, "--observation", help="An observation profile setting levels, rounding and protocols: gr_libs "
                                    "(30/50/70/90/100 %, int(p*T) pairs, prefix and subset)."),
    scorer: Optional[List[str]] = typer.Option(None, "--scorer",
                                               help="Scorer; repeat for several (default: each recognizer's own)."),
    settings: Optional[List[str]] = typer.Option(None, "--set", help="Recognizer hyperparameter, e.g. bc.n_epochs=50."),
    params: Optional[List[str]] = typer.Option(
        None, "--param", help="Task parameter, as gym.make takes it, e.g. turn_prob=0.5, expert=scripted, n_demos=20."),
    demos: Optional[str] = typer.Option(
        None, "--demos", help="Take the demonstrations from a Minari dataset (folder, folder of datasets, or ID)."),
    json_path: Optional[Path] = typer.Option(None, "--json", help="Also write the records to this JSON file."),
    store_path: Optional[Path] = typer.Option(None, "--store", envvar="GRAIL_BENCH_STORE", help=STORE_HELP),
    progress: bool = typer.Option(True, help="Show progress bars."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", help=WORKERS_HELP),
    executor: Optional[str] = typer.Option(None, "--executor", "-x", help=EXECUTOR_HELP),
    address: Optional[str] = typer.Option(None, "--address", help=ADDRESS_HELP),
    online: bool = typer.Option(False, "--online", help="Score every prefix k = 1..T: convergence point, step "
                                "accuracy, F1 area (no --observability)."),
    open_set: bool = typer.Option(False, "--open-set", help="Hold one goal out per seed (each in turn) and "
                                  "measure answering 'none of these' (tasks with 3 or more goals)."),
    mode_: Optional[str] = typer.Option(None, "--mode", "-m", help=MODE_HELP),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
    rerun: bool = typer.Option(False, "--rerun", help="Recompute the selected units even where the store has "
                               "them, replacing their rows (each unit's in one transaction, once it finished)."),
) -> None:
    """Benchmark recognizers on one task or several; finished seeds in the store are reused (not with --rerun)."""
    from grail_bench.harness.api import collect, request
    from grail_bench.harness.modes import MODES
    from grail_bench.harness.planning import RecognizerSpec
    from grail_bench.harness.sweep import run_sweep
    from grail_bench.task.observation import canonical_name

    mode = mode_name(mode_, ("online", online), ("open-set", open_set))
    if mode == "online" and observability is not None:
        raise fail("--online scores every prefix k = 1..T; it takes no --observability")
    if sampling is not None:
        if protocol is not None:
            raise fail("give --protocol only (--sampling is its deprecated alias)")
        err_console.print("warning: --sampling is deprecated; use --protocol", highlight=False)
    names = list(dict.fromkeys(recognizer or DEFAULT_RECOGNIZERS))
    with errors():
        use_cards(cards)
        outputs(files=[json_path])
        check_store(store_path)
        config = parse_settings(settings or [], names)
        scorers = tuple(dict.fromkeys(scorer or []))
        setups = _observations(observation, observability, canonical_name(sampling) if sampling else protocol,
                               rounding)
        tasks = named_tasks(task or [DEFAULT_TASK])
        reqs = [request(t, [RecognizerSpec(n, config[n], scorers) for n in names], seeds=seeds,
                        observability=levels, protocol=chosen_protocol, rounding=chosen_rounding,
                        task_params=parse_params(params or []) | ({"demos": demos} if demos else {}), mode=mode,
                        noise=noise, channel=channel)
                for t in tasks for levels, chosen_protocol, chosen_rounding in setups]
        # The executor first: one refused (a bad --workers or --address) leaves no store behind.
        with make_executor(executor, workers, address) as chosen, open_store(store_path) as store:
            what = getattr(tasks[0], "id", tasks[0]) if len(tasks) == 1 else f"{len(tasks)} tasks"
            summary = run_sweep(reqs, store, chosen, progress=progress, description=f"{what} ({mode})",
                                rerun=rerun, notice=say)
            records = [r for req, planned in summary.planned for r in collect(req, store, planned)]
            where = store.path
            _show(records, MODES[mode], chosen, store.path)
        say(f"results stored in {where}")
        if json_path is not None:
            write_text(json_path, json.dumps([r.to_dict() for r in records], indent=2) + "\n", "records")


def _observations(profile: Optional[str], observability: Optional[str], protocol: Optional[str],
                  rounding: Optional[str]) -> list[tuple[Optional[str], Optional[str], Optional[str]]]:
    """The (levels, protocol, rounding) of each request of a run: the options as given, or one per protocol of an
    observation profile (which refuses the options it sets)."""
    if profile is None:
        return [(observability, protocol, rounding)]
    from grail_bench.task.observation import get_profile

    chosen = get_profile(profile)
    given = [name for name, value in (("--observability", observability), ("--protocol", protocol),
                                      ("--rounding", rounding)) if value is not None]
    if given:
        raise fail(f"--observation {chosen.name} sets the levels, protocols and rounding; drop {', '.join(given)}")
    return [(",".join(map(str, chosen.levels)), name, chosen.rounding) for name in chosen.protocols]


def _show(records: list, mode, executor, store: str = ":memory:") -> None:  # noqa: ANN001 - a Mode, an Executor
    """A run's tables: offline, the paper-style F1 tables of its canonical configurations and of its named
    variants (with Bayes ceilings, those not cached yet computed on the run's executor and kept in the run's
    store) and the timings."""
    from grail_bench.harness.ceiling_cache import CeilingCache
    from grail_bench.report import leaderboard
    from grail_bench.report.tables import mode_table, timing_table
    from grail_bench.report.text import rich_tables

    if mode.name != "offline":
        console.print(mode_table(records, mode))
        return
    with console.status("Bayes ceilings (computed once, then cached)"):
        board = leaderboard.build([], records=records, executor=executor,
                                  cache=CeilingCache(store) if store != ":memory:" else None)
    for table in rich_tables([*board.boards, *board.variants]):
        console.print(table)
    console.print(timing_table(records))


@app.command("leaderboard")
def leaderboard_(
    store_path: Optional[Path] = typer.Option(None, "--store", envvar="GRAIL_BENCH_STORE", help="Results database."),
    markdown_path: Optional[Path] = typer.Option(None, "--markdown", help="Also write the leaderboard as Markdown here."),
    reference: Optional[Path] = typer.Option(None, "--reference",
                                             help="CSV of reported values (columns task, recognizer, observability, f1) to show beside "
                                                  "ours."),
    task: Optional[List[str]] = typer.Option(
        None, "--task", "-t", help=TASK_FILTER_HELP[:-1] + " (a set's rows are then checked against today's code; "
                                   "a shifted task's rows, which share its ID, need --shifted too)."),
    domain: Optional[List[str]] = typer.Option(None, "--domain", "-d", help=DOMAIN_FILTER_HELP),
    method: Optional[List[str]] = typer.Option(None, "--method", help=METHOD_FILTER_HELP),
    boards: bool = typer.Option(False, "--boards", help="Also print the paper-style F1 tables, a row per task and "
                                "level, with Bayes ceilings (computed once, then cached in the store)."),
    read_only: bool = typer.Option(False, "--read-only", help="Change nothing in the store: the Bayes ceilings it "
                                   "holds are read, those computed are kept in the user's cache folder only "
                                   "(default: in the store's ceilings table too, where it can be written)."),
    all_variants: bool = typer.Option(False, "--all-variants", help="List every named variant under its method "
                                      "in the claims table (default: the best one beside it)."),
    scorer: Optional[List[str]] = typer.Option(
        None, "--scorer", help="Only these scorers (NAME), or recognizer/scorer pairs (e.g. bc/mse)."),
    protocol: Optional[List[str]] = typer.Option(
        None, "--protocol", "-p", help="Only these observation protocols (as stored, e.g. subset, prefix+floor)."),
    ceiling_samples: int = typer.Option(2000, help="Monte Carlo samples of the Bayes ceilings (cached)."),
    no_ceiling: bool = typer.Option(False, "--no-ceiling", help="Do not compute or show Bayes ceilings."),
    workers: Optional[int] = typer.Option(
        None, "--workers", "-w", help="Processes computing the ceilings not cached yet (default: 1)."),
    ablation: bool = typer.Option(False, "--ablation", help="Compare scorers: F1 and scoring time per scorer."),
    online: bool = typer.Option(False, "--online", help="The online runs (`run --online`) instead."),
    open_set: bool = typer.Option(False, "--open-set", help="The open-set runs (`run --open-set`) instead."),
    mode_: Optional[str] = typer.Option(None, "--mode", "-m", help="The runs of this mode (`run --mode NAME`) instead."),
    plot: Optional[Path] = typer.Option(
        None, "--plot", help="With --ablation or --online: also write a PNG plot here."),
    html: Optional[Path] = typer.Option(
        None, "--html", help="Also write the leaderboard as a static web site into this folder (index.html and a page per domain)."),
    profiles: Optional[Path] = typer.Option(
        None, "--profiles", help="Also write performance profiles, optimality gaps and calibration (PROFILES.md, "
        "performance_profiles.png, CALIBRATION.md, reliability.png) into this folder."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
    shifted: bool = typer.Option(False, "--shifted", help="Also rank the rows of tasks under test-time shifts "
                                 "(test_slip, test_regime...), each shifted task a variant of its own; left out by "
                                 "default (`reproduce --profile open-questions` reports them) and only this shows "
                                 "them, with --task or not."),
) -> None:
    """The results store ranked: per domain the methods' IQM of F1 with 95 % intervals first, then the paper's
    headline claims (when the store holds their tasks); --boards adds the paper-style F1 tables."""
    from grail_bench.harness.ceiling import SAMPLES
    from grail_bench.harness.diagnostics import FitRow
    from grail_bench.harness.modes import MODES
    from grail_bench.harness.ceiling_cache import CeilingCache
    from grail_bench.report import leaderboard, plots
    from grail_bench.report.filters import Filters
    from grail_bench.report.reference import read_reference
    from grail_bench.report.rows import ablation_rows
    from grail_bench.report.tables import ablation_markdown, ablation_table, mode_markdown, mode_table

    mode = MODES[mode_name(mode_, ("online", online), ("open-set", open_set))]
    if ablation and mode.name != "offline":
        raise fail("--ablation compares scorers under the paper's protocol; drop the mode")
    if plot is not None and not (ablation or mode.name == "online"):
        raise fail("--plot needs --ablation or --online")
    if (html is not None or profiles is not None) and (mode.name != "offline" or ablation):
        raise fail("--html and --profiles report the paper's protocol (and the page every mode); drop the mode "
                   "and --ablation")
    samples = None if no_ceiling else ceiling_samples
    with errors():
        use_cards(cards)
        if samples is not None:
            SAMPLES.check("samples", samples)
        outputs(files=[markdown_path, plot], folders=[html, profiles])
        ref = read_reference(reference) if reference else None
        filters = Filters.of(task_filters(task)[0], domain, method)
        with open_store(store_path, must_exist=True) as store:
            selected = {name: _select(store, m, filters, scorer, protocol) for name, m in MODES.items()
                        if name == mode.name or (html is not None)}
            hidden = {} if shifted else _drop_shifted(selected)
            unseen = {h for counts in hidden.values() for h in counts}
            shown = mode.name == "offline" and (markdown_path is not None or html is not None)  # the terminal: none
            fits = ([f for f in store.select(FitRow) if filters.task(f.task) and filters.method(f.recognizer)
                     and f.config_hash not in unseen] if shown else [])
            where = store.path
        cache = CeilingCache(where, read_only=read_only) if where != ":memory:" else None
        if not selected[mode.name] and hidden.get(mode.name):
            raise fail(f"the{'' if mode.name == 'offline' else ' ' + mode.name} results in {where}"
                       f"{' that match ' + _filter_text(filters) if filters else ''} are all of tasks under "
                       "test-time shifts; --shifted shows them")
        if not selected[mode.name] and filters:
            raise fail(f"no{'' if mode.name == 'offline' else ' ' + mode.name} results in {where} match "
                       f"{_filter_text(filters)}")
        if not selected[mode.name]:
            hint = "" if mode.name == "offline" else f" --mode {mode.name}"
            raise fail(f"no{'' if mode.name == 'offline' else ' ' + mode.name} results in {where} yet; run "
                       f"`grail-bench run{hint}` first")
        _say_not_loaded(selected[mode.name])
        note = _shifted_note(sum(counts.total() for counts in hidden.values())) if unseen else None
        if note:
            say(note)
        if ablation:
            rows = ablation_rows(MODES["offline"].aggregate(selected["offline"]))
            if not rows:
                raise fail("no recognizer was run with several scorers; use `grail-bench run --scorer A --scorer B`")
            console.print(ablation_table(rows))
            if markdown_path is not None:
                write_text(markdown_path, ablation_markdown(rows), "Markdown")
            if plot is not None:
                say(f"plot written to {plots.save_png(plots.ablation(rows), plot)}")
            return
        offline = selected.pop("offline", [])
        if mode.name != "offline" and plot is None:
            samples = None  # the tables show no ceiling; only the online plot draws one
        if mode.name == "offline":
            _ranked(offline, ref, selected, fits, samples, workers, cache, boards, all_variants,
                    markdown_path, html, profiles, note)
            return
        with make_executor(None, workers, None) as pool:
            board = leaderboard.build(offline, ref, samples, studies=selected, progress=True, fits=fits,
                                      executor=pool, cache=cache)
        study = board.studies[mode.name]
        console.print(mode_table(study.records, mode))
        if markdown_path is not None:
            write_text(markdown_path, mode_markdown(study.records, mode), "Markdown")
        if plot is not None:
            say(f"plot written to {plots.save_png(plots.online(study.records, study.curves), plot)}")


def _ranked(offline: list, ref, studies: dict, fits: list, samples: Optional[int], workers: Optional[int],  # noqa: ANN001
            cache, boards: bool, all_variants: bool, markdown_path: Optional[Path], html: Optional[Path],
            profiles: Optional[Path], note: Optional[str]) -> None:
    """The leaderboard of the paper's protocol: the domain summaries as soon as the records are aggregated (they
    need no ceiling), the headline claims, then (--boards, or a file that shows them) the ceilings and the boards
    (``note``: what the rows leave out, in Markdown, for the files too)."""
    from grail_bench.report import leaderboard
    from grail_bench.report.claims import claim_tasks, headline_claims
    from grail_bench.report.html import write_site
    from grail_bench.report.reproduce import write_robust
    from grail_bench.report.summary import domain_summaries
    from grail_bench.report.text import claims_table, markdown, rich_tables, summary_tables

    files = markdown_path is not None or html is not None or profiles is not None
    with console.status("aggregating seeds and domain summaries (bootstrap intervals)"):
        board = leaderboard.build(offline, ref, None, studies=studies, fits=fits)
        summaries = domain_summaries(board.boards, improvement=files)
    for table in summary_tables(summaries):
        console.print(table)
    claims = None
    if claim_tasks() & {r.task for r in board.records}:  # only where this store ran the paper's tasks
        with console.status("headline claims (bootstrap intervals)"):
            claims = headline_claims(board.records)
        console.print(claims_table(claims, all_variants))
    if samples is not None and (boards or files):
        with make_executor(None, workers, None) as pool:
            leaderboard.add_ceilings(board, samples, progress=True, executor=pool, cache=cache)
        summaries = domain_summaries(board.boards) if files else summaries  # with the ceilings' profiles
    if boards:
        for table in rich_tables(board.boards):
            console.print(table)
    if board.variants or board.archive:
        say(f"{sum(len(b.columns) for b in board.variants)} named variants and {len(board.archive)} archived "
            "configurations are not shown here: see --markdown or --html"
            + ("" if boards else "; --boards prints the F1 tables per task and level"))
    if markdown_path is not None:
        write_text(markdown_path, markdown(board.boards, board.records, fits=board.fits, variants=board.variants,
                                           archive=board.archive, summaries=summaries, claims=claims, note=note),
                   "Markdown")
    if html is not None:
        with console.status("web page (bootstrap intervals)"):
            index = write_site(board, html, summaries=summaries, claims=claims,
                               note=note and note.replace("`", ""))[0]
        say(f"web page written to {index}")
    if profiles is not None:
        with console.status("performance profiles (bootstrap bands)"):
            for path in write_robust(board, profiles):
                say(f"wrote {path}")


def _drop_shifted(selected: dict[str, list]) -> dict[str, Counter]:
    """Leave the rows of tasks under test-time shifts out of every mode's selection (in place); per mode, how many
    rows of each configuration (hash) were left out."""
    from grail_bench.report.filters import shifted

    hidden = {}
    for name, rows in selected.items():
        hidden[name] = Counter(r.config_hash for r in rows if shifted(r))
        selected[name] = [r for r in rows if not shifted(r)]
    return hidden


def _shifted_note(count: int) -> str:
    """The line saying ``count`` rows of shifted tasks are left out (Markdown: commands in backticks)."""
    return (f"{count:,} rows of tasks under test-time shifts are not shown: `grail-bench reproduce --profile "
            "open-questions` reports them (SHIFTS.md, REGIMES.md); `grail-bench leaderboard --shifted` shows them "
            "here")


def _filter_text(filters) -> str:  # noqa: ANN001 - a report.filters.Filters
    parts = [f"--{name} {' '.join(values)}" for name, values in (("task", filters.tasks), ("domain", filters.domains),
                                                                  ("method", filters.methods)) if values]
    return " ".join(parts)


def _select(store, mode, filters, scorer: Optional[List[str]],  # noqa: ANN001
            protocol: Optional[List[str]]) -> list:
    """Stored rows of one mode, narrowed by the leaderboard's --task, --domain, --method, --scorer and
    --protocol."""
    from grail_bench.domains.symbolic.problem_set import PREFIX

    where = {"protocol": protocol} if protocol else {}
    exact = filters.tasks and not any(set(p) & set("*?[") for p in filters.tasks)
    if exact:  # plain IDs: narrowed where the rows are read
        where["task"] = [p if "/" in p or p.startswith(PREFIX) else f"GRAIL/{p}" for p in filters.tasks]
    return [r for r in store.select(mode, **where) if filters.row(r)
            and (not scorer or r.scorer in scorer or f"{r.recognizer}/{r.scorer}" in scorer)]


@app.command()
def reproduce(
    profile: str = typer.Option("quick", "--profile", help="quick (2 seeds, small budgets), paper, support "
                                "(off-support rules, occupancy, demonstrator), breadth (gr_libs' problems, symbolic "
                                "tasks), open-questions (test-time shifts, cross-regime), or a TOML file."),
    only: Optional[List[str]] = typer.Option(
        None, "--only", help="Only this section of the profile (minigrid, panda, budget-bc, ...; an unknown name "
                             "lists them all); repeatable."),
    recognizer: Optional[List[str]] = typer.Option(
        None, "--recognizer", "-r", help="Only this recognizer of the chosen sections (e.g. -r bc -r draco to add "
                                         "seeds of those alone); repeatable. The tables show every stored row."),
    seeds: Optional[int] = typer.Option(
        None, "--seeds", help="Seeds 0..N-1 of every chosen section instead of the profile's (e.g. 3 seeds of the "
                              "slow methods first). The tables show every stored row."),
    out: Path = typer.Option(..., "--out", help="Folder for the tables, figures and manifest.json."),
    store_path: Optional[Path] = typer.Option(None, "--store", help="Results database (default: OUT/results.sqlite)."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", help=WORKERS_HELP),
    executor: Optional[str] = typer.Option(None, "--executor", "-x", help=EXECUTOR_HELP),
    address: Optional[str] = typer.Option(None, "--address", help=ADDRESS_HELP),
    site: bool = typer.Option(True, help="Also write the web page into OUT/site (--no-site: tables and figures only)."),
    run: bool = typer.Option(True, help="Run the units the store lacks (--no-run: write the tables and figures "
                                        "from the rows it holds, and count the units missing)."),
    progress: bool = typer.Option(True, help="Show a progress bar."),
    add_outputs: bool = typer.Option(False, "--add-outputs", help="Also run again the units stored without "
                                     "per-instance outputs (rows from before the store kept them), replacing "
                                     "their rows as each finishes; resumable."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """Run a profile's grid (resuming from the store), then write the paper's tables and figures."""
    from datetime import datetime, timezone

    from grail_bench.core.provenance import git_commit
    from grail_bench.core.seeding import seed_list
    from grail_bench.harness.diagnostics import FitRow
    from grail_bench.harness.modes import MODES
    from grail_bench.harness.sweep import plan_sweep, run_sweep
    from grail_bench.report.reproduce import load_profile, manifest, write_outputs

    started, commit = datetime.now(timezone.utc), git_commit()
    with errors():
        use_cards(cards)
        outputs(folders=[out])
        check_store(store_path or out / "results.sqlite")
        if seeds is not None:
            seed_list(seeds)  # bounded before the profile builds its seeds
        chosen_profile = load_profile(profile)
        requests = chosen_profile.requests(only or (), recognizer or (), seeds)
        with make_executor(executor, workers, address) as chosen, \
                open_store(store_path or out / "results.sqlite") as store:
            if run:
                summary = run_sweep(requests, store, chosen, progress=progress, description=f"reproduce {profile}",
                                    notice=say, add_outputs=add_outputs)
            else:
                summary = plan_sweep(requests, store, add_outputs=add_outputs)[1]
            meta = manifest(sys.argv, chosen_profile, only or [], chosen, started, summary, commit,
                            recognizer or [], seeds)
            tasks = sorted({r.task_id for r in requests})
            rows = [row for mode in MODES.values() for row in store.select(mode, task=tasks)]
            fits = store.select(FitRow, task=tasks)
            with console.status("tables, figures and web page"):
                written = write_outputs(rows, chosen_profile, out, meta, only or (), site=site, fits=fits,
                                        executor=chosen, plans=summary.planned)
    if run:
        say(f"{summary.units} units ({summary.skipped} already stored) in {summary.seconds:.0f} s on {chosen.name} x "
            f"{chosen.workers}; models trained {summary.trained}, reused from the cache {summary.reused}, a run "
            f"without reuse would train {summary.naive}")
    else:
        say(f"{summary.units} units, {summary.skipped} stored; {summary.units - summary.skipped} not run (--no-run)")
    for path in written:
        say(f"wrote {path}")


@app.command()
def inspect(
    task: str = typer.Option(DEFAULT_TASK, "--task", "-t", help=ONE_TASK_HELP),
    recognizer: str = typer.Option("bc", "--recognizer", "-r", help="The recognizer to inspect."),
    seed: int = typer.Option(0, "--seed", "-s", min=0, help="The seed whose fit to inspect."),
    settings: Optional[List[str]] = typer.Option(None, "--set", help="Recognizer hyperparameter, e.g. bc.n_epochs=50."),
    params: Optional[List[str]] = typer.Option(None, "--param", help="Task parameter, as for `run`."),
    protocol: Optional[str] = typer.Option(None, "--protocol", "-p", help="Observation protocol (default: the task's)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Also write diagnostics.json and the heatmaps (PNG) here."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """Train (or reload from the model cache) one fit and show whether it imitates: per goal, the greedy rollout,
    agreement with the demonstrations and the imitation and confusion matrices. Nothing is stored."""
    from grail_bench.harness.api import inspect_fit
    from grail_bench.harness.diagnostics import to_json
    from grail_bench.report import plots
    from grail_bench.report.tables import diagnostics_table, goal_label

    with errors():
        use_cards(cards)
        outputs(folders=[out])
        config = parse_settings(settings or [], [recognizer])[recognizer]
        chosen = one_task(task, "inspect")
        with console.status(f"fitting {recognizer} on {getattr(chosen, 'id', chosen)}, seed {seed} (or reading it "
                            "from the model cache)"):
            seen = inspect_fit(chosen, recognizer, seed, config, parse_params(params or []), protocol)
        labels = [goal_label(g) for g in seen.task.goals]
        if seen.diagnostics is None:
            say(f"recognizer {recognizer!r} offers no fit diagnostics")
        else:
            console.print(diagnostics_table(seen.diagnostics, f"{recognizer} on {seen.task.id}, seed {seed}"))
        levels = ", ".join(f"{level_text(r.observability)} F1 {r.f1:.2f}" for r in seen.rows)
        say(f"{seen.rows[0].protocol}: {levels}; confusion over these levels (rows true, columns predicted): "
            f"{seen.confusion}")
        if out is not None:
            data = {"task": seen.task.id, "recognizer": recognizer, "seed": seed, "confusion": seen.confusion,
                    "diagnostics": json.loads(to_json(seen.diagnostics)) if seen.diagnostics else None}
            write_text(out / "diagnostics.json", json.dumps(data, indent=1) + "\n", "diagnostics")
            say(f"heatmap written to {plots.save_png(plots.heatmap(seen.confusion, labels, 'confusion', 'predicted', 'true goal', 0), out / 'confusion.png')}")
            if seen.diagnostics is not None:
                say(f"heatmap written to {plots.save_png(plots.heatmap(seen.diagnostics.imitation, labels, 'imitation: P(goal i action | policy j)', 'policy of goal', 'demonstrations of goal'), out / 'imitation.png')}")
                figure = plots.fit_curves(dict(seen.diagnostics.curves), labels)
                if figure is not None:
                    say(f"curves written to {plots.save_png(figure, out / 'curves.png')}")


@app.command()
def export(
    task: str = typer.Option(DEFAULT_TASK, "--task", "-t", help="A task ID (GRAIL/... or one of --cards')."),
    seeds: int = typer.Option(1, "--seeds", "-s", help="One dataset per seed 0..N-1."),
    params: Optional[List[str]] = typer.Option(None, "--param", help="Task parameter, as for `run`."),
    out: Optional[Path] = typer.Option(None, "--out", help="Folder the datasets are written into (as Minari lays "
                                       "them out; default: Minari's, $MINARI_DATASETS_PATH or ~/.minari/datasets)."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """Write a task's demonstrations as Minari datasets, one per seed (goals and splits in episode metadata)."""
    from grail_bench.core.seeding import seed_list
    from grail_bench.task import make_task
    from grail_bench.task.export import export as export_datasets

    with errors():
        use_cards(cards)
        if is_task_path(task):
            raise fail(f"export writes datasets of registered tasks, whose env gymnasium rebuilds by ID; the problem "
                       f"set {task} has no such ID (run it with `run --task PATH`)")
        gr_task = make_task(task, **parse_params(params or []))  # checked before the folder is made
        outputs(folders=[out])
        with console.status(f"exporting {gr_task.id}"):
            written = export_datasets(gr_task, seed_list(seeds), out)
    for path in written:
        say(f"wrote {path}")


@app.command()
def protocols() -> None:
    """List the observation protocols (built in and from the entry-point group grail_bench.protocols)."""
    from grail_bench.report.tables import protocols_table
    from grail_bench.task.observation import BUILTIN, available_protocols, get_protocol

    with errors():
        rows = []
        for name, target in available_protocols().items():
            chosen = BUILTIN.get(name) or get_protocol(name)
            own = name in BUILTIN or target == "built-in"
            rows.append((name, chosen.leaks_goal, chosen.description + ("" if own else f" ({target})")))
    console.print(protocols_table(rows))
    say("k = max(1, ceil(p * T)) or max(1, int(p * T)) pairs (gr_libs'), by each task's rounding "
        "(`grail-bench tasks`) or --rounding.")


@app.command()
def ceiling(
    task: str = typer.Option(DEFAULT_TASK, "--task", "-t", help=ONE_TASK_HELP),
    protocol: Optional[str] = typer.Option(None, "--protocol", "-p", help="Observation protocol (default: the task's)."),
    observability: Optional[str] = typer.Option(None, "--observability", "-o",
                                                help="Comma-separated fractions (default: the task's)."),
    rounding: Optional[str] = typer.Option(None, help="ceil or floor, as for `run` (default: the task's)."),
    method: str = typer.Option("auto", help="auto (exact where it can enumerate), exact or monte-carlo."),
    samples: int = typer.Option(2000, help="Monte Carlo observations (2 to 1,000,000)."),
    seed: int = typer.Option(0, min=0, help="Monte Carlo seed."),
    params: Optional[List[str]] = typer.Option(None, "--param", help="Task parameter, e.g. turn_pattern=around-and-back."),
    json_path: Optional[Path] = typer.Option(None, "--json", help="Also write the ceilings to this JSON file."),
    pairs_only: bool = typer.Option(False, "--pairs-only",
                                    help="The best accuracy of scoring the observed pairs with per-goal policies "
                                         "(the demonstrators' own), as GRAIL, GRAQL and DRACO score."),
    noise: float = typer.Option(0.0, "--noise", help=NOISE_HELP),
    channel: str = typer.Option("pairs", "--channel", help="What is observed: pairs, states or actions."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """The Bayes ceiling: the best accuracy any recognizer can reach under a protocol and level."""
    from grail_bench.harness.ceiling import bayes_ceiling
    from grail_bench.report.tables import ceiling_table
    from grail_bench.task.observation import DATASET, ObservationSpec

    with errors():
        use_cards(cards)
        outputs(files=[json_path])
        chosen = one_task(task, "ceiling")
        gr_task = task_object(chosen, parse_params(params or []))
        if (protocol or gr_task.protocol) == DATASET:
            raise fail(f"the {DATASET} protocol of {gr_task.id} (each problem's own obs.dat) has no Bayes ceiling; "
                       "give --protocol subset or prefix (the task's optimal plans)")
        spec = ObservationSpec.resolve(protocol or gr_task.protocol, rounding or gr_task.rounding,
                                       observability or gr_task.observability)
        with console.status("computing the Bayes ceiling"):
            results = [bayes_ceiling(gr_task, spec.protocol, level, rounding=spec.rounding, method=method,
                                     samples=samples, seed=seed, pairs_only=pairs_only, noise=noise, channel=channel)
                       for level in spec.levels]
        variant = gr_task.overrides_against(task_object(chosen, {})).label()  # e.g. test_slip=0.1
        console.print(ceiling_table(f"{gr_task.id} ({variant})" if variant else gr_task.id, results))
        if json_path is not None:
            write_text(json_path, json.dumps([c.as_dict() for c in results], indent=2) + "\n", "ceilings")


@app.command()
def study(
    name: Optional[str] = typer.Argument(None, help="The study to run (without one: the list)."),
    show_list: bool = typer.Option(False, "--list", help="List the studies."),
    store_path: Optional[Path] = typer.Option(
        None, "--store", help="Results database the study reads (causes; default: $GRAIL_BENCH_STORE, else "
                              "results.sqlite in the grail-bench folder of ~/.local/share)."),
    task: Optional[List[str]] = typer.Option(
        None, "--task", "-t", help="A task to study; repeatable (off-route: required; causes, readings: a subset "
                                   "of their six)."),
    params: Optional[List[str]] = typer.Option(None, "--param", help="Task parameter, as for `run` (off-route)."),
    seeds: Optional[int] = typer.Option(None, "--seeds", "-s", min=1, help="Seeds 0..N-1 (off-route; default 10)."),
    samples: Optional[int] = typer.Option(
        None, "--samples", min=2, help="Monte Carlo samples of each ceiling (causes, readings; default 2000)."),
    cards: Optional[List[Path]] = typer.Option(None, "--cards", help=CARDS_HELP),
) -> None:
    """Run a study behind leaderboard/README.md and print its Markdown table (`--list` names them)."""
    from grail_bench.report.studies import STUDIES, get_study, study_options
    from grail_bench.report.tables import names_table

    if show_list or name is None:
        console.print(names_table("studies (grail-bench study NAME)",
                                  [(n, text) for n, (_, text) in STUDIES.items()], "what it reports"))
        return
    flags = {"store": "--store", "tasks": "--task", "params": "--param", "seeds": "--seeds", "samples": "--samples"}
    with errors():
        use_cards(cards)
        paths = [t for t in task or () if is_task_path(t)]
        if paths:
            raise fail(f"study {name} takes task IDs, not a problem set's path ({paths[0]}); a problem set runs as a "
                       "task of its own with `run --task PATH`")
        given = {"store": store_path, "tasks": tuple(task) if task else None,
                 "params": parse_params(params) if params else None, "seeds": seeds, "samples": samples}
        takes = study_options(name)  # argument -> whether required
        for key, value in given.items():
            if value is not None and key not in takes:
                raise fail(f"study {name} takes no {flags[key]}")
            if value is None and takes.get(key) and key != "store":
                raise fail(f"study {name} needs {flags[key]}")
        options = {k: v for k, v in given.items() if k != "store" and v is not None}
        with console.status(f"study {name}"):
            if "store" in takes:
                with open_store(store_path, must_exist=True) as store:
                    text = get_study(name)(store=store, **options)
            else:
                text = get_study(name)(**options)
    typer.echo(text, nl=False)


def main() -> None:
    """Console-script entry point."""
    one_line_warnings()
    app()
