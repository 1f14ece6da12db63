"""``grail-bench reproduce``: run a profile's grid, then write the paper's tables, figures and a manifest.

A profile (``grail_bench/profiles/*.toml``, or any TOML file of that shape)
lists sections (``minigrid``, ``panda``, ``online``, ``open-set``), each with
tasks, recognizers, scorers, optional task parameters and a mode (``offline``,
the paper's protocol, by default; ``online`` or ``open-set`` for the studies
beyond it), plus the seeds and recognizer configs shared by all. The grid runs
through :func:`grail_bench.evaluation.sweep.run_sweep` (resumable through the
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

from grail_bench import provenance
from grail_bench.errors import UserError
from grail_bench.evaluation.runner import RecognizerSpec
from grail_bench.evaluation.sweep import MODES, Request, SweepSummary
from grail_bench.store import OnlineRow, OpenSetRow, ResultRow

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
        from grail_bench.evaluation.protocol import get_protocol
        from grail_bench.task import make_task

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
                levels = () if section.mode == "online" else tuple(task.observability)
                out.append(Request(task.id, specs, tuple(range(self.seeds)), levels, get_protocol(task.protocol).name,
                                   "ceil", dict(section.params), section.mode))
        return out


def load_profile(name_or_path: str) -> Profile:
    """A shipped profile by name (``quick``, ``paper``) or a TOML file of the same shape.

    Raises:
        UserError: For an unknown name, an unreadable file or a malformed profile.
    """
    try:
        if name_or_path in PROFILES:
            text = resources.files("grail_bench").joinpath(f"profiles/{name_or_path}.toml").read_text("utf-8")
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
    return Profile(name, str(data.get("description", "")), seeds, sections, config)


def manifest(argv: Sequence[str], profile: Profile, only: Sequence[str], executor: Any, started: datetime,
             summary: SweepSummary, commit: str | None) -> dict[str, Any]:
    """What produced a reproduction: command, code, packages, machine, time, executor and model counts.

    ``commit`` is the code's commit when the run started (:func:`grail_bench.provenance.git_commit`).
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


def reference_path() -> Path:
    """The paper's reported values shipped with grail-bench (see the CSV's header)."""
    return Path(str(resources.files("grail_bench").joinpath("paper_reported.csv")))


def write_outputs(rows: Sequence[ResultRow | OnlineRow | OpenSetRow], profile: Profile, requests: Sequence[Request],
                  out: Path, meta: dict[str, Any]) -> list[Path]:
    """Tables, figures, the web page (``site/``) and the manifest into ``out``; returns the files written.

    The paper's tables and figures come from the offline rows; the online rows add ONLINE.md and
    online.png, the open-set rows OPEN_SET.md. Only rows of the requests' tasks, protocols and modes count.
    """
    from grail_bench import figures
    from grail_bench.evaluation.runner import aggregate
    from grail_bench.leaderboard import build_boards, markdown, read_reference
    from grail_bench.site import write_site

    out.mkdir(parents=True, exist_ok=True)
    wanted = {(r.task_id, r.label, MODES[r.mode]) for r in requests}
    rows = [r for r in rows if (r.task, r.protocol, type(r)) in wanted]
    offline, online, open_set = ([r for r in rows if type(r) is kind] for kind in (ResultRow, OnlineRow, OpenSetRow))
    reference = read_reference(reference_path())
    title = f"grail-bench reproduce: {profile.name}"
    written: list[Path] = []
    if offline:
        records = aggregate(offline)
        paper_scorers = figures.own_scorer_records(records)
        boards = build_boards(paper_scorers, reference)
        written.append(out / "TABLES.md")
        written[-1].write_text(markdown(boards, paper_scorers, ci=True, title=title), encoding="utf-8")
        written += figures.write_all(records, out, models=model_sizes(records))
    written += write_studies(online, open_set, out)
    written += write_site(offline, out / "site", reference, title=title, online=online, open_set=open_set)
    (out / "manifest.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    written.append(out / "manifest.json")
    return written


def write_studies(online: Sequence[OnlineRow], open_set: Sequence[OpenSetRow], out: Path,
                  ceiling_samples: int = 2000) -> list[Path]:
    """ONLINE.md and online.png (with the Bayes ceilings) and OPEN_SET.md, for the kinds of rows given."""
    from grail_bench import reports
    from grail_bench.evaluation.online import aggregate_online
    from grail_bench.evaluation.open_set import aggregate_open_set

    written = []
    if online:
        records = aggregate_online(online)
        written.append(out / "ONLINE.md")
        written[-1].write_text(reports.markdown_table(reports.online_grid(records), reports.ONLINE_TITLE,
                                                      reports.ONLINE_INTRO), encoding="utf-8")
        written.append(reports.online_plot(records, out / "online.png",
                                           reports.online_ceilings(records, ceiling_samples)))
    if open_set:
        records = aggregate_open_set(open_set)
        written.append(out / "OPEN_SET.md")
        written[-1].write_text(reports.markdown_table(reports.open_set_grid(records), reports.OPEN_SET_TITLE,
                                                      reports.OPEN_SET_INTRO), encoding="utf-8")
    return written


def model_sizes(records: list[dict[str, Any]]) -> dict[tuple[str, str], float]:
    """Mean bytes of one goal's stored model, per (domain, recognizer), from the model cache.

    Only recognizers and domains present in ``records`` count; the cache's
    sidecars say which recognizer and domain each model belongs to.
    """
    from grail_bench.paths import cache_dir
    from grail_bench.task import make_task

    domains = set()
    for task_id in {r["task"] for r in records}:
        try:
            domains.add(make_task(task_id).domain)
        except Exception:  # noqa: BLE001 - a task whose card is gone has no models to size
            continue
    recognizers = {r["recognizer"] for r in records}
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
