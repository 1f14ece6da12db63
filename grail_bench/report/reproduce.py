"""``grail-bench reproduce``: run a profile's grid, then write the paper's tables, figures and a manifest.

A profile (``grail_bench/report/profiles/*.toml``, or any TOML file of that shape)
lists sections (``minigrid``, ``panda``, ``online``, ``open-set``), each with
tasks, recognizers, scorers, optional task parameters and a mode (``offline``,
the paper's protocol, by default; ``online`` or ``open-set`` for the studies
beyond it), plus the seeds and recognizer configs shared by all. The grid runs
through :func:`grail_bench.harness.sweep.run_sweep` (resumable through the
store), then :func:`write_outputs` renders everything (tables, figures, the web
page) from the store alone, so the outputs never depend on which units ran now.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from datetime import datetime
from importlib import metadata, resources
from pathlib import Path
from typing import Any, Mapping, Sequence

from grail_bench.core import provenance
from grail_bench.core.errors import UserError
from grail_bench.core.paths import cache_dir
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES, Row, get_mode
from grail_bench.harness.planning import RecognizerSpec
from grail_bench.harness.sweep import Request, SweepSummary
from grail_bench.report import leaderboard, plots
from grail_bench.report.boards import build_boards, own_scorer_records
from grail_bench.report.html import write_site
from grail_bench.report.reference import paper_reference_path, read_reference
from grail_bench.report.text import markdown, mode_markdown
from grail_bench.task import find_task, make_task
from grail_bench.task.observation import ObservationSpec

PROFILES = ("quick", "paper")


@dataclass(frozen=True)
class Section:
    """One domain's part of a profile."""

    name: str
    tasks: tuple[str, ...]
    recognizers: tuple[str, ...]
    scorers: tuple[str, ...] = ()
    params: Mapping[str, Any] = field(default_factory=dict)
    mode: str = "offline"


@dataclass(frozen=True)
class Profile:
    """A named grid: sections, seeds and recognizer configs."""

    name: str
    description: str
    seeds: int
    sections: tuple[Section, ...]
    config: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def requests(self, only: Sequence[str] = ()) -> list[Request]:
        """The sweep's requests: each task's default protocol and levels (online: none), every section unless
        ``only``."""
        unknown = set(only) - {s.name for s in self.sections}
        if unknown:
            raise UserError(f"profile {self.name!r} has no section {sorted(unknown)[0]!r}; it has "
                            f"{', '.join(s.name for s in self.sections)}")
        out = []
        for section in self.sections:
            if only and section.name not in only:
                continue
            specs = tuple(RecognizerSpec(r, dict(self.config.get(r, {})), section.scorers)
                          for r in section.recognizers)
            for task_id in section.tasks:
                task = make_task(task_id, **dict(section.params))
                levels = tuple(task.observability) if get_mode(section.mode).takes_levels else ()
                out.append(Request(task.id, specs, tuple(range(self.seeds)),
                                   ObservationSpec.resolve(task.protocol, "ceil", levels), dict(section.params),
                                   section.mode))
        return out


def load_profile(name_or_path: str) -> Profile:
    """A shipped profile by name (``quick``, ``paper``) or a TOML file of the same shape.

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
        sections = tuple(Section(s["name"], tuple(s["tasks"]), tuple(s["recognizers"]), tuple(s.get("scorers", ())),
                                 dict(s.get("params", {})), str(s.get("mode", "offline"))) for s in data["section"])
        seeds = int(data["seeds"])
        config = {k: dict(v) for k, v in data.get("config", {}).items()}
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"profile {name_or_path}: malformed ({type(exc).__name__}: {exc})") from None
    if seeds < 1 or not sections:
        raise UserError(f"profile {name_or_path}: needs seeds >= 1 and at least one [[section]]")
    for section in sections:
        if section.mode not in MODES:
            raise UserError(f"profile {name_or_path}: section {section.name!r} has mode {section.mode!r}; "
                            f"choose one of {', '.join(MODES)}")
        for field_name, values in (("tasks", section.tasks), ("recognizers", section.recognizers)):
            if not values or not all(isinstance(v, str) for v in values):
                raise UserError(f"profile {name_or_path}: section {section.name!r} needs {field_name} as a list of "
                                "names")
    return Profile(name, str(data.get("description", "")), seeds, sections, config)


def manifest(argv: Sequence[str], profile: Profile, only: Sequence[str], executor: Any, started: datetime,
             summary: SweepSummary, commit: str | None) -> dict[str, Any]:
    """What produced a reproduction: command, code, packages, machine, time, executor and model counts.

    ``commit`` is the code's commit when the run started (:func:`grail_bench.core.provenance.git_commit`).
    """
    packages = sorted({(d.metadata["Name"], d.version) for d in metadata.distributions() if d.metadata["Name"]})
    return {
        "command": list(argv),
        "profile": profile.name,
        "only": list(only),
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


def write_outputs(rows: Sequence[Row], profile: Profile, requests: Sequence[Request], out: Path,
                  meta: dict[str, Any], site: bool = True, progress: bool = False,
                  fits: Sequence[FitRow] = ()) -> list[Path]:
    """Tables, figures, the web page (``site/``, unless ``site`` is False) and the manifest into ``out``.

    The paper's tables and figures come from the offline rows; every other mode with rows adds its table
    (``ONLINE.md``, ``OPEN_SET.md``) and the online runs their figure (``online.png``). Only rows of the
    requests' tasks, protocols and modes count; ``fits`` are the stored fit diagnostics. Returns the files
    written.
    """
    out.mkdir(parents=True, exist_ok=True)
    wanted = {(r.task_id, r.label, MODES[r.mode].row) for r in requests}
    rows = [r for r in rows if (r.task, r.protocol, type(r)) in wanted]
    by_mode = {name: [r for r in rows if type(r) is mode.row] for name, mode in MODES.items()}
    offline = by_mode.pop("offline")
    reference = read_reference(paper_reference_path())
    board = leaderboard.build(offline, reference, studies=by_mode, progress=progress, fits=fits)
    title = f"grail-bench reproduce: {profile.name}"
    written: list[Path] = []
    if offline:
        own = own_scorer_records(board.records)
        paper_boards = build_boards(own, reference, board.ceilings)
        written.append(out / "TABLES.md")
        written[-1].write_text(markdown(paper_boards, own, ci=True, title=title, fits=board.fits), encoding="utf-8")
        written += plots.write_all(board.records, out, models=model_sizes(board.records))
    written += write_studies(board, out)
    if site:
        written += write_site(board, out / "site", title=title)
    (out / "manifest.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    written.append(out / "manifest.json")
    return written


def write_studies(board: leaderboard.Leaderboard, out: Path) -> list[Path]:
    """Each other mode's Markdown table (ONLINE.md, OPEN_SET.md) and the online figure (online.png)."""
    written = []
    for name, study in board.studies.items():
        written.append(out / f"{name.upper().replace('-', '_')}.md")
        written[-1].write_text(mode_markdown(study.records, study.mode), encoding="utf-8")
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
