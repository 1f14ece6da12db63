"""``grail-bench reproduce``: run a profile's grid, then write the paper's tables, figures and a manifest.

A profile (``grail_bench/report/profiles/*.toml``, or any TOML file of that shape)
lists sections (``minigrid``, ``panda``, ``online``, ``open-set``), each with
tasks, recognizers, scorers, optional task parameters and a mode (``offline``,
the paper's protocol, by default; ``online`` or ``open-set`` for the studies
beyond it), plus the seeds and recognizer configs shared by all, and task
lists several sections share (a ``[tasks]`` table; ``tasks = "minigrid"``). A section
with ``vary`` is a budget study: one recognizer hyperparameter (``vary =
{param = "total_timesteps", values = [...]}``) or the training demonstrations
per goal (``vary = {task_param = "n_train", values = [...], test = 3}``) takes
each value in turn, optionally at its own ``observability`` levels and
``seeds``; a scaling study (``vary = {tasks = "n_goals"}``) runs its tasks,
one per goal count, and fits each method's fit-cost exponent. Those sections
write ``BUDGETS.md`` and ``budgets.png`` instead of joining the paper's tables. A
shift sweep (``vary = {shift = [{test_slip = 0.0}, {test_slip = 0.1}]}``, or the name of a list of the
profile's ``[shifts]`` table, ``shift = "slip"``) runs its tasks under each table of test parameters in turn
(docs/concepts/shifts.md) and joins the tables: each shifted task is a named variant of its own, and a table
that shifts nothing is the task itself; sections that set test parameters (a shift sweep, or fixed ones) also
write ``SHIFTS.md`` and a figure per family, ``shifts-<family>.png`` (F1 against each shift of the dynamics) and
``REGIMES.md`` and ``regimes.png`` (the cross-regime grid; :mod:`grail_bench.report.shifts`).
A unit two sections share runs once. A section's ``config`` sets hyperparameters of all
its recognizers (e.g. ``config = {algorithm = "sac"}`` for a DRACO variant); its ``protocol`` and
``rounding`` (e.g. ``protocol = "prefix"``, ``rounding = "floor"``) replace each task's default, and its
``noise`` and ``channel`` set the observation model (``noise = 0.2``, ``channel = "actions"``). The grid runs
through :func:`grail_bench.harness.sweep.run_sweep` (resumable through the
store), then :func:`write_outputs` renders everything (tables, figures, the web
page) from the store alone, so the outputs never depend on which units ran now.
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
from dataclasses import dataclass, field
from datetime import datetime
from importlib import metadata, resources
from pathlib import Path
from typing import Any, Mapping, Sequence

from grail_bench.core import provenance
from grail_bench.core.atomic import write_text
from grail_bench.core.errors import UserError
from grail_bench.core.paths import cache_dir
from grail_bench.core.seeding import seed_list
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.executors import Executor
from grail_bench.harness.modes import MODES, Row, get_mode
from grail_bench.harness.planning import Planned, RecognizerSpec
from grail_bench.harness.store import ResultsStore
from grail_bench.harness.sweep import Request, SweepSummary, plan_request
from grail_bench.report import leaderboard, plots
from grail_bench.report.boards import own_scorer_records, short_name
from grail_bench.report.configs import config_key
from grail_bench.report.html import write_site
from grail_bench.report.reference import paper_reference_path, read_reference
from grail_bench.report.rows import BudgetCurve, BudgetPoint, calibration_rows
from grail_bench.report.shifts import Family, drawn, family, figure_stems, regime_cells, shift_curves
from grail_bench.report.summary import domain_summaries, profile_figure_data, profiles_markdown
from grail_bench.report.tables import (budgets_markdown, calibration_markdown, mode_markdown, regimes_markdown,
                                       shifts_markdown)
from grail_bench.report.text import markdown
from grail_bench.stats.verdict import plateau, scaling_exponent
from grail_bench.task import find_task, make_task
from grail_bench.task.model import test_defaults
from grail_bench.task.observation import ObservationSpec, check_noise, parse_observability
from grail_bench.task.versions import fingerprint

PROFILES = ("quick", "paper", "support", "breadth", "open-questions")


@dataclass(frozen=True)
class Vary:
    """A budget study: one parameter taking each of several values.

    Attributes:
        param: A recognizer hyperparameter, the task parameter ``n_train``, ``n_goals`` (a scaling study) or
            ``shift`` (a shift sweep).
        values: The values, in increasing order (a scaling study's are its tasks' goal counts; a shift sweep's
            are tables of test parameters).
        of: ``"recognizer"``, ``"task"``, ``"tasks"`` (the section's tasks are the values) or ``"test"``.
        test: With ``n_train``, the test demonstrations kept per goal (``n_demos = n_train + test``).
        name: A shift sweep's family: the name of the profile's ``[shifts]`` list it takes (``slip``), else None.
    """

    param: str
    values: tuple[Any, ...]
    of: str = "recognizer"
    test: int = 3
    name: str | None = None

    @classmethod
    def parse(cls, raw: Mapping[str, Any], where: str, shifts: Mapping[str, Any] | None = None) -> Vary:
        """From a section's ``vary`` table.

        Args:
            raw: The table.
            where: Where it stands, for errors.
            shifts: The profile's named lists of test-parameter tables (its ``[shifts]`` table), which
                ``shift = "name"`` names.

        Raises:
            UserError: Unless it names one parameter and at least two values.
        """
        if not isinstance(raw, Mapping) or sum(k in raw for k in ("param", "task_param", "tasks", "shift")) != 1:
            raise UserError(f"{where}: vary needs param (a recognizer's) or task_param (n_train), and values; "
                            "or tasks = \"n_goals\"; or shift (a list of tables of test parameters)")
        if "shift" in raw:
            tables = name = raw["shift"]
            if isinstance(tables, str):
                if tables not in (shifts or {}):
                    raise UserError(f"{where}: vary names the shift list {tables!r}, which the profile's [shifts] "
                                    f"table lacks (it has {', '.join(shifts or {}) or 'none'})")
                tables = (shifts or {})[tables]
            if not isinstance(tables, list) or len(tables) < 2 or not all(isinstance(t, Mapping) for t in tables):
                raise UserError(f"{where}: vary's shift needs at least two tables of test parameters "
                                "([{test_slip = 0.0}, {test_slip = 0.1}])")
            return cls("shift", tuple(dict(t) for t in tables), "test", name=name if isinstance(name, str) else None)
        if "tasks" in raw:
            if raw["tasks"] != "n_goals":
                raise UserError(f"{where}: vary's tasks must be \"n_goals\" (the section's tasks by goal count)")
            return cls("n_goals", (), "tasks")
        values = raw.get("values")
        if not isinstance(values, list) or len(values) < 2:
            raise UserError(f"{where}: vary needs at least two values")
        if "task_param" in raw:
            if raw["task_param"] != "n_train" or not all(isinstance(v, int) and v >= 1 for v in values):
                raise UserError(f"{where}: vary's task_param must be n_train, with positive integer values")
            test = raw.get("test", 3)
            if not isinstance(test, int) or test < 1:
                raise UserError(f"{where}: vary's test must be a positive integer")
            return cls("n_train", tuple(values), "task", test)
        return cls(str(raw["param"]), tuple(values))


@dataclass(frozen=True)
class Section:
    """One part of a profile (a domain's grid, a mode's study, or a budget study)."""

    name: str
    tasks: tuple[str, ...]
    recognizers: tuple[str, ...]
    scorers: tuple[str, ...] = ()
    params: Mapping[str, Any] = field(default_factory=dict)
    mode: str = "offline"
    vary: Vary | None = None
    observability: tuple[float, ...] = ()
    seeds: int | None = None
    config: Mapping[str, Any] = field(default_factory=dict)  # hyperparameters for every recognizer of the section
    protocol: str | None = None  # None: each task's default
    rounding: str | None = None  # None: each task's default
    noise: float = 0.0  # the share of observed steps made spurious
    channel: str = "pairs"  # what is observed: pairs, states or actions

    def requests(self, seeds: int, config: Mapping[str, Mapping[str, Any]]) -> list[Request]:
        """This section's requests: its protocol, rounding and levels where it sets them, else each task's."""
        out = []
        for task_id in self.tasks:
            for params, configs in self._variants(config):
                task = make_task(task_id, **params)
                levels = (self.observability or task.observability) if get_mode(self.mode).takes_levels else ()
                specs = tuple(RecognizerSpec(r, c, self.scorers) for r, c in configs)
                observation = ObservationSpec.resolve(
                    self.protocol or task.protocol, self.rounding or task.rounding, levels, noise=self.noise,
                    channel=self.channel, action_space=task.action_space() if self.noise else None)
                out.append(Request(task.id, specs, tuple(seed_list(self.seeds or seeds)), observation, params, self.mode,
                                   task=task))
        return out

    def shift_family(self, requests: Sequence[Request]) -> str | None:
        """The shift family of this section (its ``[shifts]`` list's name, else its test parameters' names), None
        where it sets no test parameter (:mod:`grail_bench.report.shifts`)."""
        if self.vary is not None and self.vary.of == "test" and self.vary.name:
            return self.vary.name
        names = sorted({k for r in requests for k in _test_overrides(r)})
        return "+".join(names) if names else None

    @property
    def study(self) -> bool:
        """Whether this section is a budget or scaling study (``BUDGETS.md``), not part of the tables."""
        return self.vary is not None and self.vary.of != "test"

    def _variants(self, config: Mapping[str, Mapping[str, Any]]) -> list[tuple[dict[str, Any], list]]:
        """``(task parameters, [(recognizer, hyperparameters), ...])`` of each request per task."""
        base = [(r, {**config.get(r, {}), **self.config}) for r in self.recognizers]
        if self.vary is None or self.vary.of == "tasks":
            return [(dict(self.params), base)]
        if self.vary.of == "test":
            return [({**self.params, **table}, base) for table in self.vary.values]
        if self.vary.of == "task":
            return [({**self.params, "n_train": v, "n_demos": v + self.vary.test}, base) for v in self.vary.values]
        return [(dict(self.params), [(r, {**c, self.vary.param: v}) for r, c in base for v in self.vary.values])]

    def value_of(self, record: Any) -> Any:
        """The studied parameter's value in a record of this section."""
        if self.vary.of == "tasks":
            return len(make_task(record.task).goals)
        if self.vary.of == "task":
            return record.task_params.get(self.vary.param)
        return record.recognizer_config.get(self.vary.param)

    def label(self, task: str) -> str:
        """What one curve of this study is over: its task, or a scaling study's tasks."""
        if self.vary is not None and self.vary.of == "tasks":
            return f"{short_name(self.tasks[0])} .. {short_name(self.tasks[-1])}"
        return task


@dataclass(frozen=True)
class Profile:
    """A named grid: sections, seeds and recognizer configs."""

    name: str
    description: str
    seeds: int
    sections: tuple[Section, ...]
    config: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def requests(self, only: Sequence[str] = (), recognizers: Sequence[str] = (),
                 seeds: int | None = None) -> list[Request]:
        """The sweep's requests: each section's protocol, rounding and levels (else the task's; online: no
        levels), every section unless ``only``, every recognizer of those sections unless ``recognizers``, each
        section's seeds unless ``seeds`` (then seeds ``0 .. seeds - 1`` of every section)."""
        unknown = set(only) - {s.name for s in self.sections}
        if unknown:
            raise UserError(f"profile {self.name!r} has no section {sorted(unknown)[0]!r}; it has "
                            f"{', '.join(s.name for s in self.sections)}")
        if seeds is not None and seeds < 1:
            raise UserError(f"--seeds must be at least 1, got {seeds}")
        requests = _distinct([r if seeds is None else dataclasses.replace(r, seeds=tuple(seed_list(seeds)))
                              for section in self.sections if not only or section.name in only
                              for r in section.requests(self.seeds, self.config)])
        if not recognizers:
            return requests
        chosen = {spec.name for r in requests for spec in r.specs}
        missing = sorted(set(recognizers) - chosen)
        if missing:
            raise UserError(f"no section of profile {self.name!r} chosen runs recognizer {missing[0]!r}; they run "
                            f"{', '.join(sorted(chosen))}")
        narrowed = [dataclasses.replace(r, specs=tuple(s for s in r.specs if s.name in recognizers))
                    for r in requests]
        return [r for r in narrowed if r.specs]

    def grid_requests(self, only: Sequence[str] = ()) -> list[Request]:
        """The requests of the sections that are not budget studies (the paper's tables and the modes')."""
        return _distinct([r for s in self.sections if not s.study and (not only or s.name in only)
                          for r in s.requests(self.seeds, self.config)])

    def studies(self, only: Sequence[str] = ()) -> list[tuple[Section, list[Request]]]:
        """The budget-study sections (with ``vary``) to write, with their requests."""
        return [(s, s.requests(self.seeds, self.config)) for s in self.sections
                if s.study and (not only or s.name in only)]


def _distinct(requests: Sequence[Request]) -> list[Request]:
    """The requests without repeats: a request for the same task (by fingerprint: a shift sweep's unshifted
    value is the task itself), recognizers, seeds, observation and mode as an earlier one is dropped."""
    seen: set[tuple[Any, ...]] = set()
    out = []
    for r in requests:
        key = (r.task_id, fingerprint(r.task), repr(r.specs), r.seeds, repr(r.observation), r.mode)
        if key not in seen:
            seen.add(key)
            out.append(r)
    return out


def load_profile(name_or_path: str) -> Profile:
    """A shipped profile by name (``quick``, ``paper``) or a TOML file of the same shape.

    A section lists its tasks, or names one of the lists of the profile's ``[tasks]`` table; a shift sweep's
    ``vary = {shift = "slip"}`` names one of the lists of its ``[shifts]`` table.

    Raises:
        UserError: For an unknown name, an unreadable file or a malformed profile.
    """
    try:
        if name_or_path in PROFILES:
            text = resources.files("grail_bench.report").joinpath(f"profiles/{name_or_path}.toml").read_text("utf-8")
            name = name_or_path
        else:
            path = Path(name_or_path)
            if not path.is_file():
                raise UserError(f"unknown profile {name_or_path!r}; choose {', '.join(PROFILES)} or a TOML file")
            text, name = path.read_text(encoding="utf-8"), path.stem
        data = tomllib.loads(text)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"cannot read profile {name_or_path}: {exc}") from None
    try:
        task_lists = _task_lists(data.get("tasks", {}))
        shifts = data.get("shifts", {})
        if not isinstance(shifts, dict):
            raise TypeError("[shifts] must map a name to a list of tables of test parameters")
        sections = tuple(Section(
            s["name"], _section_tasks(s, task_lists, f"profile {name_or_path}"), tuple(s["recognizers"]),
            tuple(s.get("scorers", ())),
            dict(s.get("params", {})), str(s.get("mode", "offline")),
            Vary.parse(s["vary"], f"profile {name_or_path}: section {s['name']!r}", shifts) if "vary" in s else None,
            parse_observability(s["observability"]) if "observability" in s else (),
            int(s["seeds"]) if "seeds" in s else None, dict(s.get("config", {})),
            _optional_name(s, "protocol"), _optional_name(s, "rounding"), float(s.get("noise", 0.0)),
            str(s.get("channel", "pairs"))) for s in data["section"])
        seeds = int(data["seeds"])
        config = {k: dict(v) for k, v in data.get("config", {}).items()}
    except UserError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"profile {name_or_path}: malformed ({type(exc).__name__}: {exc})") from None
    if not sections:
        raise UserError(f"profile {name_or_path}: needs at least one [[section]]")
    for count, where in [(seeds, "seeds"), *((s.seeds, f"section {s.name!r}: seeds") for s in sections)]:
        try:
            seed_list(count if count is not None else 1)
        except UserError as exc:
            raise UserError(f"profile {name_or_path}: {where}: {exc}") from None
    for section in sections:
        if section.vary is not None and section.vary.of == "tasks" and len(section.tasks) < 2:
            raise UserError(f"profile {name_or_path}: section {section.name!r} varies its tasks; list two or more")
        if section.protocol is not None or section.rounding is not None or section.noise or section.channel != "pairs":
            try:
                ObservationSpec.resolve(section.protocol or "subset", section.rounding or "ceil",
                                        channel=section.channel)
                check_noise(section.noise)
            except UserError as exc:
                raise UserError(f"profile {name_or_path}: section {section.name!r}: {exc}") from None
        if section.mode not in MODES:
            raise UserError(f"profile {name_or_path}: section {section.name!r} has mode {section.mode!r}; "
                            f"choose one of {', '.join(MODES)}")
        for field_name, values in (("tasks", section.tasks), ("recognizers", section.recognizers)):
            if not values or not all(isinstance(v, str) for v in values):
                raise UserError(f"profile {name_or_path}: section {section.name!r} needs {field_name} as a list of "
                                "names")
    return Profile(name, str(data.get("description", "")), seeds, sections, config)


def _task_lists(table: Any) -> dict[str, tuple[str, ...]]:
    """A profile's named task lists (its ``[tasks]`` table: a name, then a list of task IDs).

    Raises:
        TypeError: For a table that does not map names to lists.
    """
    if not isinstance(table, dict) or not all(isinstance(v, list) for v in table.values()):
        raise TypeError("[tasks] must map a name to a list of task IDs")
    return {name: tuple(ids) for name, ids in table.items()}


def _section_tasks(section: Mapping[str, Any], task_lists: Mapping[str, tuple[str, ...]],
                   where: str) -> tuple[str, ...]:
    """A section's tasks: its own list, or the profile's task list it names (``tasks = "minigrid"``).

    Raises:
        UserError: For a name the profile's ``[tasks]`` table lacks.
    """
    tasks = section["tasks"]
    if not isinstance(tasks, str):
        return tuple(tasks)
    if tasks not in task_lists:
        raise UserError(f"{where}: section {section.get('name')!r} names the task list {tasks!r}, which its [tasks] "
                        f"table lacks (it has {', '.join(task_lists) or 'none'})")
    return task_lists[tasks]


def _optional_name(section: Mapping[str, Any], key: str) -> str | None:
    """A section's optional name-valued field (``protocol``, ``rounding``), or None where it has none.

    Raises:
        TypeError: For a value that is not a string.
    """
    value = section.get(key)
    if value is not None and not isinstance(value, str):
        raise TypeError(f"{key} must be a name, got {value!r}")
    return value


def manifest(argv: Sequence[str], profile: Profile, only: Sequence[str], executor: Any, started: datetime,
             summary: SweepSummary, commit: str | None, recognizers: Sequence[str] = (),
             seeds: int | None = None) -> dict[str, Any]:
    """What produced a reproduction: command, code, packages, machine, time, executor and model counts.

    ``commit`` is the code's commit when the run started (:func:`grail_bench.core.provenance.git_commit`).
    """
    packages = sorted({(d.metadata["Name"], d.version) for d in metadata.distributions() if d.metadata["Name"]})
    return {
        "command": list(argv),
        "profile": profile.name,
        "only": list(only),
        "recognizers": list(recognizers),
        "seeds": seeds,  # None: each section's own
        "git_commit": commit,
        **provenance.machine(),
        "executor": executor.name,
        "workers": executor.workers,
        "started": started.isoformat(timespec="seconds"),
        "finished": provenance.now(),
        "sweep": {"units": summary.units, "skipped (already stored)": summary.skipped, "rows": summary.rows,
                  "models trained": summary.trained, "models reused from the cache": summary.reused,
                  "models a run without reuse would train": summary.naive, "seconds": round(summary.seconds, 1)},
        "packages": dict(packages),
    }


Plans = Sequence[tuple[Request, list[Planned]]]


def _owned(rows: Sequence[Any], requests: Sequence[Request], plans: Plans = (), scorers: bool = False) -> list[Any]:
    """The rows that belong to the requests (their tasks, protocols, modes, recognizers and configurations).

    Args:
        plans: What a sweep planned (``run_sweep(...).planned``); a request it lacks is planned here.
        scorers: Only the rows of the scorers the requests ask for (a configuration another section scores
            under more scorers shares its rows).
    """
    def planned(request: Request) -> list[Planned]:
        found = next((p for r, p in plans if r == request), None)
        return found if found is not None else plan_request(request, ResultsStore(":memory:"))[0]

    owners: dict[tuple[str, str, str], list[tuple[Request, Planned]]] = {}
    for request in requests:
        for p in planned(request):
            owners.setdefault((request.task_id, p.name, p.config_hash), []).append((request, p))
    return [row for row in rows
            if any(r.owns(row, [p]) and (not scorers or row.scorer in p.labels)
                   for r, p in owners.get((row.task, row.recognizer, row.config_hash), ()))]


def write_outputs(rows: Sequence[Row], profile: Profile, out: Path, meta: dict[str, Any], only: Sequence[str] = (),
                  site: bool = True, progress: bool = False, fits: Sequence[FitRow] = (),
                  executor: Executor | None = None, plans: Plans = (), ceiling_samples: int = 2000) -> list[Path]:
    """Tables, figures, the web page (``site/``, unless ``site`` is False) and the manifest into ``out``.

    The paper's tables and figures come from the offline rows of the grid's sections (``TABLES.md``: the main
    boards of canonical configurations, then the named variants, such as a profile's reduced budgets, and the
    archived configurations, every cell with its 95 % bootstrap interval); every other mode with
    rows adds its table (``ONLINE.md``, ``OPEN_SET.md``) and the online runs their figure (``online.png``);
    budget studies write ``BUDGETS.md`` and ``budgets.png``; sections that set test parameters write
    ``SHIFTS.md`` and ``shifts-<family>.png`` (shifted dynamics) and ``REGIMES.md`` and ``regimes.png`` (the
    cross-regime grid, :func:`write_shifts`). Only the rows the profile's requests own count
    (other configurations in a shared store do not); ``fits`` are the stored fit diagnostics. Ceilings missing
    from the cache are computed on ``executor`` (default: in this process); ``plans`` are what the sweep
    planned (``run_sweep(...).planned``), so the requests are not planned again; ``ceiling_samples`` are the Monte
    Carlo samples of a ceiling not computed exactly. Returns the files written.
    """
    grid = _owned(rows, profile.grid_requests(only), plans)
    by_mode = {name: [r for r in grid if type(r) is mode.row] for name, mode in MODES.items()}
    offline = by_mode.pop("offline")
    reference = read_reference(paper_reference_path())
    owned_fits = [f for f in fits if any((f.task, f.recognizer, f.config_hash) == (r.task, r.recognizer, r.config_hash)
                                         for r in offline)]
    board = leaderboard.build(offline, reference, ceiling_samples, studies=by_mode, progress=progress,
                              fits=owned_fits, executor=executor)
    title = f"grail-bench reproduce: {profile.name}"
    written: list[Path] = []
    if offline:
        written.append(out / "TABLES.md")
        write_text(written[-1], markdown(board.boards, board.records, ci=True, title=title, fits=board.fits,
                                         variants=board.variants, archive=board.archive))
        written += plots.write_all(board.records, out, models=model_sizes(board.records))
        written += write_robust(board, out)
        written += write_shifts(board, shift_families(rows, profile, only, plans), out, title)
    written += write_studies(board, out)
    written += write_budgets(rows, profile.studies(only), out, title, plans)
    if site:
        written += write_site(board, out / "site", title=title)
    write_text(out / "manifest.json", json.dumps(meta, indent=2) + "\n")
    written.append(out / "manifest.json")
    return written


def budget_points(rows: Sequence[Any], studies: Sequence[tuple[Section, list[Request]]],
                  plans: Plans = ()) -> list[BudgetCurve]:
    """Per study section, task and recognizer: the studied values with F1 over seeds and fit seconds per goal
    (``plans``: what the sweep planned, see :func:`_owned`).

    A budget study also gets its plateau; a scaling study (``n_goals``) the exponent of the whole fit's
    seconds against the goal count instead.
    """
    out = []
    for section, requests in studies:
        records = MODES["offline"].aggregate([r for r in _owned(rows, requests, plans) if isinstance(r, MODES["offline"].row)])
        groups: dict[tuple[str, str, str], list[Any]] = {}
        for r in own_scorer_records(records):
            groups.setdefault((section.label(r.task), r.recognizer, r.protocol), []).append(r)
        for (task, recognizer, protocol), group in sorted(groups.items()):
            for level in sorted({r.observability for r in group}):
                points = sorted(((section.value_of(r), r) for r in group if r.observability == level),
                                key=lambda vr: vr[0])
                curve = BudgetCurve(section.name, section.vary.param, task, recognizer, protocol, level,
                                    tuple(BudgetPoint(v, r.n_seeds, r.f1.mean, *r.f1.ci95,
                                                      r.fit_seconds_per_goal) for v, r in points))
                if section.vary.of == "tasks":
                    sizes = [v for v, _ in points]
                    costs = [v * r.fit_seconds_per_goal for v, r in points]
                    curve = dataclasses.replace(curve, scaling=True, exponent=scaling_exponent(sizes, costs)
                                                if len(set(sizes)) > 1 else None)
                else:
                    curve = dataclasses.replace(curve, plateau=plateau([(v, r.f1.mean, r.f1.ci95[0])
                                                                        for v, r in points])
                                                if len(points) > 1 else None)
                out.append(curve)
    return out


def write_budgets(rows: Sequence[Any], studies: Sequence[tuple[Section, list[Request]]], out: Path,
                  title: str, plans: Plans = ()) -> list[Path]:
    """``BUDGETS.md``, ``budgets.png`` and ``budgets.json`` of the budget studies (nothing without one)."""
    curves = budget_points(rows, studies, plans)
    if not curves:
        return []
    written = [out / "BUDGETS.md", out / "budgets.json"]
    write_text(written[0], budgets_markdown(curves, title))
    write_text(written[1], json.dumps([c.to_dict() for c in curves], indent=1) + "\n")
    return written + plots.save(plots.budgets(curves), out, "budgets")


def shift_families(rows: Sequence[Any], profile: Profile, only: Sequence[str] = (),
                   plans: Plans = ()) -> list[Family]:
    """The families of the profile's sections that set test parameters (:mod:`grail_bench.report.shifts`): each
    with its tables in the profile's order and the configurations its sections' rows are of (``plans``: what the
    sweep planned, see :func:`_owned`)."""
    tables: dict[str, list[tuple[dict[str, Any], dict[str, Any]]]] = {}
    configs: dict[str, set[Any]] = {}
    for section in profile.sections:
        if section.study or (only and section.name not in only):
            continue
        requests = section.requests(profile.seeds, profile.config)
        name = section.shift_family(requests)
        if name is None:
            continue
        tables.setdefault(name, []).extend((_test_overrides(r), r.task.test_params) for r in requests)
        owned = _owned(rows, requests, plans, scorers=True)
        configs.setdefault(name, set()).update(config_key(row) for row in owned)
    return [family(name, tables[name], configs[name]) for name in tables]


def _test_overrides(request: Request) -> dict[str, Any]:
    """The test parameters a request sets, as the profile wrote them (an unshifted table's too)."""
    test = test_defaults(request.task.spec)
    return {k: v for k, v in request.overrides.as_dict().items() if k in test}


def write_shifts(board: leaderboard.Leaderboard, families: Sequence[Family], out: Path, title: str) -> list[Path]:
    """``SHIFTS.md`` (every configuration), per family of shifted dynamics ``shifts-<family>.png`` and ``.svg``
    (F1 against the shift, its canonical configurations: :func:`grail_bench.report.shifts.drawn`) and
    ``REGIMES.md``, ``regimes.png`` and ``.svg`` (the cross-regime grid), where the families have rows; nothing
    otherwise."""
    written: list[Path] = []
    curves = shift_curves(board.records, board.configs, board.ceilings, families)
    if curves:
        written.append(write_text(out / "SHIFTS.md", shifts_markdown(curves, title)))
        shown = drawn(curves)
        for name, stem in figure_stems(c.family for c in curves).items():
            written += plots.save(plots.shifts([c for c in shown if c.family == name]), out, stem)
    cells = regime_cells(board.records, board.configs, board.ceilings, families)
    if cells:
        written.append(write_text(out / "REGIMES.md", regimes_markdown(cells, title)))
        written += plots.save(plots.regimes(cells), out, "regimes")
    return written


def write_robust(board: leaderboard.Leaderboard, out: Path, reps: int = 2000) -> list[Path]:
    """``PROFILES.md`` and ``performance_profiles.png`` (domains with Bayes ceilings), ``CALIBRATION.md`` and
    ``reliability.png`` (recognizers with a posterior): reporting beyond means."""
    summaries = domain_summaries(board.boards, reps)
    written = [write_text(out / "PROFILES.md", profiles_markdown(summaries))]
    data = profile_figure_data(summaries)
    if data:
        written += plots.save(plots.profiles(data), out, "performance_profiles")
    calibration = calibration_rows(board.records)
    if calibration:
        written.append(out / "CALIBRATION.md")
        write_text(written[-1], calibration_markdown(calibration))
        written += plots.save(plots.reliability(calibration), out, "reliability")
    return written


def write_studies(board: leaderboard.Leaderboard, out: Path) -> list[Path]:
    """Each other mode's Markdown table (ONLINE.md, OPEN_SET.md) and the online figure (online.png)."""
    written = []
    for name, study in board.studies.items():
        written.append(out / f"{name.upper().replace('-', '_')}.md")
        write_text(written[-1], mode_markdown(study.records, study.mode))
        if name == "online":
            written.append(plots.save_png(plots.online(study.records, study.curves), out / "online.png"))
    return written


def model_sizes(records: Sequence[Any]) -> dict[tuple[str, str], float]:
    """Mean bytes of one goal's stored model, per (domain, recognizer), from the model cache.

    Only recognizers and domains present in ``records`` count; the cache's
    sidecars say which recognizer and domain each model belongs to.
    """
    domains = {task.domain for task in (find_task(t) for t in {r.task for r in records}) if task is not None}
    recognizers = {r.recognizer for r in records}
    sizes: dict[tuple[str, str], list[int]] = {}
    for sidecar in cache_dir().glob("policy-*/*.json"):
        try:
            key = json.loads(sidecar.read_text(encoding="utf-8"))["key"]
            domain = json.loads(key["env"])["domain"]
            model = next(p for p in sidecar.parent.glob(sidecar.stem + ".*") if p.suffix in (".pt", ".npz"))
        except (OSError, ValueError, KeyError, TypeError, StopIteration):
            continue
        if key.get("recognizer") in recognizers and domain in domains:
            sizes.setdefault((domain, key["recognizer"]), []).append(model.stat().st_size)
    return {k: sum(v) / len(v) for k, v in sorted(sizes.items())}
