"""What the command line does around every command: parsing values, checking outputs, mapping errors.

Bad input (every :class:`~grail_bench.core.errors.UserError`, and gymnasium's
own errors for unknown IDs) is one ``error:`` line and exit status 2; a dead
worker is one line and exit status 1; Ctrl-C during a sweep says how many
units were kept, elsewhere (while planning, say) just that it interrupted, and
exits with 130. Anything else is a bug and shows its traceback. Commands that
read the results store open it read-only; commands that write it check, before
any work, that it can be written.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Any, Iterator, Optional, Sequence

import typer
from rich.console import Console

from grail_bench.core.errors import UserError
from grail_bench.core.paths import check_writable

console = Console()
err_console = Console(stderr=True)

EXIT_USAGE = 2
EXIT_WORKER = 1
EXIT_INTERRUPTED = 130


def fail(message: str, code: int = EXIT_USAGE) -> typer.Exit:
    """Print one error line to stderr and return the exit to raise."""
    err_console.print(f"error: {message}", highlight=False, markup=False, soft_wrap=True)
    return typer.Exit(code)


def say(message: str) -> None:
    """One plain line on stdout."""
    console.print(message, highlight=False, markup=False, soft_wrap=True)


@contextlib.contextmanager
def errors() -> Iterator[None]:
    """Map bad input, lost workers, unwritable outputs and Ctrl-C in a sweep to one line and an exit code."""
    from gymnasium.error import Error as GymError

    from grail_bench.harness.executors import WorkerLost
    from grail_bench.harness.sweep import Interrupted

    try:
        yield
    except (GymError, UserError) as exc:
        raise fail(str(exc)) from None
    except WorkerLost as exc:
        raise fail(f"{exc}; the units that finished are stored: run the same command again to resume",
                   EXIT_WORKER) from None
    except Interrupted as exc:
        err_console.print(f"interrupted: {exc.summary.done} unit(s) of this run were kept in the store "
                          f"({exc.summary.skipped} were there already); run the same command again to resume",
                          highlight=False, markup=False, soft_wrap=True)
        raise typer.Exit(EXIT_INTERRUPTED) from None
    except KeyboardInterrupt:
        err_console.print("interrupted", highlight=False, markup=False, soft_wrap=True)
        raise typer.Exit(EXIT_INTERRUPTED) from None
    except OSError as exc:
        if exc.filename is None:
            raise
        raise fail(f"cannot write {exc.filename}: {exc.strerror}") from None


def outputs(files: Sequence[Optional[Path]] = (), folders: Sequence[Optional[Path]] = ()) -> None:
    """Check every output path the command was given, before any work starts.

    Raises:
        UserError: For a path that cannot be written.
    """
    for path in files:
        if path is not None:
            check_writable(path)
    for path in folders:
        if path is not None:
            check_writable(path, folder=True)


def write_text(path: Path, text: str, what: str) -> None:
    """Write an output file whole (its folders created; :mod:`grail_bench.core.atomic`) and say so."""
    from grail_bench.core import atomic

    atomic.write_text(path, text)
    say(f"{what} written to {path}")


def refuse_repeated_options(command: Any, args: Sequence[str]) -> None:
    """Refuse an option of ``command`` (a Click command) that takes one value but is given more than once in
    ``args`` (its arguments, after its name): Click would keep the last silently.

    Raises:
        typer.Exit: For the first such option.
    """
    single = {name: param for param in command.params
              if param.param_type_name == "option" and not (param.multiple or param.is_flag or param.count)
              for name in param.opts}
    seen: dict[str, list[str]] = {}
    it = iter(args)
    for arg in it:
        if arg == "--":
            break
        name, sep, given = arg.partition("=") if arg.startswith("--") else (arg, "", "")
        if name not in single:
            continue
        param = single[name]
        seen.setdefault(param.name, []).append(given if sep else next(it, ""))
        if len(seen[param.name]) > 1:
            raise fail(f"{'/'.join(param.opts)} given more than once ({', '.join(seen[param.name])}); "
                       f"{command.name} takes one")


def mode_name(mode: Optional[str], *shortcuts: tuple[str, bool]) -> str:
    """The mode a command runs or reports: ``--mode NAME`` or one of its shortcut flags (``--online``, ...).

    Raises:
        typer.Exit: Two modes were asked for, or the name is unknown.
    """
    from grail_bench.harness.modes import MODES

    asked = [name for name, on in shortcuts if on] + ([mode] if mode is not None else [])
    if len(set(asked)) > 1:
        raise fail("choose one mode: " + ", ".join(f"--{n}" if n != mode else f"--mode {n}" for n in asked))
    name = asked[0] if asked else "offline"
    if name not in MODES:
        raise fail(f"unknown mode {name!r}; choose one of {', '.join(MODES)}")
    return name


def value(raw: str) -> Any:
    """A command-line value: JSON when it parses (numbers, lists, booleans), else the string."""
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        return raw


def settings(items: Sequence[str], names: Sequence[str]) -> dict[str, dict[str, Any]]:
    """``["bc.n_epochs=10"]`` -> ``{"bc": {"n_epochs": 10}}`` (types are checked when the run is planned).

    Raises:
        UserError: For a malformed item, a recognizer not being run, or a setting given twice.
    """
    out: dict[str, dict[str, Any]] = {name: {} for name in names}
    for item in items:
        key, sep, raw = item.partition("=")
        name, dot, param = key.partition(".")
        if not sep or not dot or not param:
            raise UserError(f"--set expects RECOGNIZER.PARAM=VALUE, got {item!r}")
        if name not in out:
            raise UserError(f"--set {item!r} names recognizer {name!r}, which is not being run")
        if param in out[name]:
            raise UserError(f"--set {key} given more than once ({key}={json.dumps(out[name][param])}, {item}); "
                            "give each setting once")
        out[name][param] = value(raw)
    return out


def params(items: Sequence[str]) -> dict[str, Any]:
    """``["turn_prob=0.5"]`` -> ``{"turn_prob": 0.5}``.

    Raises:
        UserError: For a malformed item or a parameter given twice.
    """
    out = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise UserError(f"--param expects NAME=VALUE, got {item!r}")
        if key in out:
            raise UserError(f"--param {key} given more than once ({key}={json.dumps(out[key])}, {item}); "
                            "give each parameter once")
        out[key] = value(raw)
    return out


@contextlib.contextmanager
def executor(name: Optional[str], workers: Optional[int], address: Optional[str]) -> Iterator[Any]:
    """The chosen executor, shut down however the block ends: its units not started cancelled, and when the
    block raises (Ctrl-C included), its running units abandoned too (nothing would store their rows)."""
    from grail_bench.harness.executors import make_executor

    chosen = make_executor(name, workers, address)
    try:
        yield chosen
    except BaseException:
        chosen.close(abandon=True)
        raise
    chosen.close()


def open_store(path: Optional[Path], must_exist: bool = False) -> Any:
    """The results store at ``path`` (default: ``$GRAIL_BENCH_STORE`` or the user's data folder).

    Args:
        path: The store's file.
        must_exist: Read an existing store, read-only (the reading commands):
            nothing is created or changed. Otherwise open it for writing
            (created if missing).

    Raises:
        UserError: With ``must_exist``, when there is no store there yet; for
            a file that is not a results store or (writing) cannot be written.
    """
    from grail_bench.harness.store import ResultsStore, default_store_path

    path = path or default_store_path()
    if must_exist and not Path(path).exists():
        raise UserError(f"no results store at {path}; run `grail-bench run` first")
    return ResultsStore(path, read_only=must_exist)


def check_store(path: Optional[Path]) -> Path:
    """Check, before any planning or training, that a run can write its rows to the store at ``path`` (default
    as :func:`open_store`); nothing is created or changed but its folder.

    Raises:
        UserError: Naming the store and why it cannot be written.
    """
    from grail_bench.harness.store import check_store_writable, default_store_path

    return check_store_writable(path or default_store_path())


CARDS_HELP = ("Task cards of your own: a card file (.toml) or a folder of them; repeatable (also: "
              "GRAIL_BENCH_CARDS, a path list). Their tasks take any namespace but GRAIL/.")


def use_cards(paths: Optional[Sequence[Path]]) -> None:
    """Register the tasks of the ``--cards`` given (a broken card is skipped with one line; the others load).

    Raises:
        UserError: For a path that is no card file or folder.
    """
    from grail_bench.task.external import load_cards
    from grail_bench.task.sources import path_cards

    for path in paths or ():
        path_cards(path)  # a mistyped path is an error, not a skipped card
    load_cards(*(paths or ()))


def is_task_path(name: str) -> bool:
    """Whether a ``--task`` value names a problem set's path rather than a task ID: an existing path, or one
    written as a path (a missing one is then said so, not taken for an unknown ID)."""
    from grail_bench.domains.symbolic.dataset import ARCHIVE_SUFFIXES

    return Path(name).exists() or name.startswith(("/", "./", "../", "~")) or name.endswith(ARCHIVE_SUFFIXES)


def named_tasks(names: Sequence[str]) -> list[Any]:
    """The tasks ``--task`` values name: an ID (or a reading command's glob) as given, a path as its problem set's
    tasks, one :class:`~grail_bench.task.GRTask` per group of problems sharing domain, template and hypotheses
    (:mod:`grail_bench.domains.symbolic.problem_set`).

    Raises:
        UserError: For a path that holds no well-formed problem set.
    """
    from grail_bench.domains.symbolic.problem_set import problem_set_tasks

    names = list(dict.fromkeys(names))
    return [t for name in names for t in (problem_set_tasks(Path(name).expanduser()) if is_task_path(name)
                                          else [name])]


def task_filters(names: Optional[Sequence[str]]) -> tuple[Optional[list[str]], list[Any]]:
    """A reading command's ``--task`` values as filters (IDs and globs as given, a problem set's path as its
    tasks' IDs) and the problem sets' tasks, each made known in this process (so that its rows are checked as
    `run` plans them)."""
    from grail_bench.task.registration import remember

    if not names:
        return None, []
    found = named_tasks(names)
    own = [t for t in found if not isinstance(t, str)]
    for task in own:
        remember(task)
    return [t if isinstance(t, str) else t.id for t in found], own


def one_task(name: str, command: str) -> Any:
    """The one task a command taking a single ``--task`` is given: an ID as given, or a problem set's path
    holding one task.

    Raises:
        UserError: For a path that holds no problem set, or one of several tasks.
    """
    found = named_tasks([name])
    if len(found) > 1:
        ids = ", ".join(t.id for t in found)
        raise UserError(f"the problem set {name} holds {len(found)} tasks ({ids}); {command} takes one: give "
                        "the path of one group's problems")
    return found[0]


def task_object(task: Any, task_params: dict[str, Any]) -> Any:
    """The :class:`~grail_bench.task.GRTask` of :func:`one_task`'s answer with ``--param`` overrides applied."""
    from grail_bench.task import make_task

    return make_task(task, **task_params) if isinstance(task, str) else task.with_overrides(**task_params)


def one_line_warnings() -> None:
    """Show grail-bench's own warnings (e.g. a cached model being retrained) as one line on stderr."""
    import warnings

    from grail_bench.core.cache import CacheWarning

    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        if issubclass(category, CacheWarning):
            err_console.print(f"warning: {message}", highlight=False, markup=False, soft_wrap=True)
        else:
            default(message, category, filename, lineno, file, line)

    warnings.showwarning = show
