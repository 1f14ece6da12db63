"""Planning-based recognizers on Pereira et al.'s goal-recognition dataset, problem by problem.

Each archive of the chosen domains and observation levels is loaded through the symbolic domain's loader
(:func:`grail_bench.domains.symbolic.problem.load`), and each recognizer is built with
:func:`grail_bench.recognizers.make_recognizer`, fitted on the problem's hypotheses (``{(i,): []}``: the
planning-based recognizers read no demonstration) with the symbolic domain's env factory, and asked to
``score`` the archive's ``obs.dat`` as an ``actions``-channel trajectory (the observed operators; every
state NaN). Per problem it records whether the true goal (``real_hyp.dat``) is among the top-scoring goals,
how many goals share the top score (the spread) and the seconds of ``fit`` plus ``score``.

    /work/main/.venv/bin/python leaderboard/symbolic_dataset/run.py DATASET [--domains ...] [--levels ...]
        [--sample N] [--seed S] [--node-limit N] [--records FILE]

``DATASET`` is a local copy of https://github.com/pucrs-automated-planning/goal-plan-recognition-dataset
(``git clone``; its layout is ``DOMAIN/LEVEL/*.tar.bz2``). See README.md beside this file.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
from imitation.data.types import Trajectory

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic import DOMAIN
from grail_bench.domains.symbolic.dataset import ARCHIVE_SUFFIXES, problem_name
from grail_bench.domains.symbolic.problem import GRProblem, load
from grail_bench.recognizers import make_recognizer
from grail_bench.task.observation import project

DOMAINS = ("easy-ipc-grid", "logistics", "blocks-world")
LEVELS = (10, 30, 50, 70, 100)
#: The recognizers run, as (column name, registered name, settings); prp's node limit is set from the command line.
RECOGNIZERS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("h_gc", "landmarks", {"heuristic": "completion"}),
    ("h_uniq", "landmarks", {"heuristic": "uniqueness"}),
    ("prp", "prp", {}),
)
#: Scores within this of the best count as tied at the top (h_gc and h_uniq are means and sums of ratios:
#: equal values may differ in the last bits).
TIE_TOLERANCE = 1e-9
NODE_LIMIT_MARK = "node limit"


@dataclass(frozen=True)
class Record:
    """One recognizer on one problem.

    Attributes:
        domain: The dataset's domain folder.
        level: Observation level (percent of the plan's actions observed).
        problem: The archive's name.
        recognizer: Column name (``h_gc``, ``h_uniq``, ``prp``).
        n_goals: Candidate goals.
        n_observed: Observed actions.
        status: ``"ok"``; ``"node-limit"`` (prp's search gave up: counted unsolved, a miss); ``"error"``.
        correct: Whether the true goal is among the top-scoring goals (False unless ``status == "ok"``).
        spread: How many goals share the top score (0 unless ``status == "ok"``).
        seconds: ``fit`` plus ``score``.
        message: The one-line error, if any.
    """

    domain: str
    level: int
    problem: str
    recognizer: str
    n_goals: int
    n_observed: int
    status: str
    correct: bool
    spread: int
    seconds: float
    message: str = ""


def archives(dataset: Path, domain: str, level: int) -> list[Path]:
    """The problem archives of one domain and level, sorted by name.

    Raises:
        UserError: When the folder does not exist.
    """
    folder = dataset / domain / str(level)
    if not folder.is_dir():
        raise UserError(f"{folder} does not exist: DATASET must be a copy of goal-plan-recognition-dataset "
                        "(DOMAIN/LEVEL/*.tar.bz2)")
    return sorted(p for p in folder.iterdir() if p.name.endswith(ARCHIVE_SUFFIXES))


def sample(paths: Sequence[Path], n: int | None, rng: np.random.Generator) -> list[Path]:
    """``n`` of ``paths`` drawn without replacement (all of them when ``n`` is None or not smaller), in order."""
    if n is None or n >= len(paths):
        return list(paths)
    return [paths[i] for i in sorted(rng.choice(len(paths), size=n, replace=False))]


def observed_trajectory(problem: GRProblem) -> Trajectory:
    """``obs.dat`` as the recognizers observe it: its operators on the ``actions`` channel (states NaN)."""
    acts = np.asarray(problem.observed_operators(), dtype=np.int64)
    states = np.zeros((len(acts) + 1, problem.model.n_fluents), dtype=np.int64)
    return project(Trajectory(obs=states, acts=acts, infos=None, terminal=False), "actions")


def top_goals(scores: np.ndarray) -> np.ndarray:
    """Indices of the goals scoring within :data:`TIE_TOLERANCE` of the best."""
    return np.flatnonzero(scores >= scores.max() - TIE_TOLERANCE)


def recognize(path: Path, domain: str, level: int, node_limit: int, columns: Iterable[str]) -> list[Record]:
    """The recognizers of :data:`RECOGNIZERS` named in ``columns`` on one archive.

    Raises:
        UserError: When the archive cannot be loaded, grounded or observed (the caller records it as skipped).
    """
    spec = str(path)
    problem = load(spec)
    real = problem.real_index
    observed = observed_trajectory(problem)
    goals = [(i,) for i in range(len(problem.hypotheses))]
    for goal in goals:  # a hypothesis holding initially has no env: refuse the problem before timing anything
        DOMAIN.make_env(goal, problem=spec).close()
    out = []
    for column, name, settings in RECOGNIZERS:
        if column not in columns:
            continue
        if name == "prp":
            settings = {**settings, "node_limit": node_limit}
        rec = make_recognizer(name, **settings)
        status, message, correct, spread = "ok", "", False, 0
        start = time.perf_counter()
        try:
            rec.fit({g: [] for g in goals}, lambda g: DOMAIN.make_env(g, problem=spec))
            scores = rec.score(observed)
        except UserError as err:
            status, message = ("node-limit" if NODE_LIMIT_MARK in str(err) else "error"), str(err)
        seconds = time.perf_counter() - start
        if status == "ok":
            top = top_goals(np.array([scores[g] for g in goals], dtype=float))
            correct, spread = bool(real in top), len(top)
        out.append(Record(domain, level, problem_name(path), column, len(goals), len(observed.acts), status,
                          correct, spread, seconds, message))
    return out


def run(dataset: Path, domains: Iterable[str], levels: Iterable[int], n_sample: int | None, seed: int,
        node_limit: int, prp_sample: int | None, log: Any = sys.stderr) -> tuple[list[Record], list[dict[str, str]]]:
    """All records, and the problems skipped (``{"domain", "level", "problem", "error"}``), domain by domain
    and level by level.

    Per (domain, level), ``n_sample`` problems are drawn, and ``prp_sample`` of those for prp (whose exact cost
    searches take seconds to minutes a problem), from one generator seeded with ``seed``, in the order given.
    """
    rng = np.random.default_rng(seed)
    records: list[Record] = []
    skipped: list[dict[str, str]] = []
    for domain in domains:
        for level in levels:
            chosen = sample(archives(dataset, domain, level), n_sample, rng)
            with_prp = set(sample(chosen, prp_sample, rng))
            start = time.perf_counter()
            for path in chosen:
                columns = [c for c, _, _ in RECOGNIZERS if c != "prp" or path in with_prp]
                try:
                    records.extend(recognize(path, domain, level, node_limit, columns))
                except UserError as err:
                    skipped.append({"domain": domain, "level": str(level), "problem": path.name, "error": str(err)})
            print(f"{domain} {level}%: {len(chosen)} problems in {time.perf_counter() - start:.1f} s", file=log,
                  flush=True)
    return records, skipped


def summary(records: Sequence[Record]) -> list[dict[str, Any]]:
    """Per (domain, level, recognizer): problems, accuracy (true goal among the top goals, unsolved ones as
    misses), expected accuracy under a uniform choice among the top goals, mean spread over the solved
    problems, mean seconds over all, and how many hit prp's node limit or failed otherwise."""
    groups: dict[tuple[str, int, str], list[Record]] = defaultdict(list)
    for r in records:
        groups[(r.domain, r.level, r.recognizer)].append(r)
    rows = []
    for (domain, level, name), group in groups.items():
        solved = [r for r in group if r.status == "ok"]
        rows.append({
            "domain": domain, "level": level, "recognizer": name, "problems": len(group),
            "accuracy": sum(r.correct for r in solved) / len(group),
            "expected_accuracy": sum(r.correct / r.spread for r in solved) / len(group),
            "spread": float(np.mean([r.spread for r in solved])) if solved else math.nan,
            "seconds": float(np.mean([r.seconds for r in group])),
            "goals": float(np.mean([r.n_goals for r in group])),
            "observed": float(np.mean([r.n_observed for r in group])),
            "node_limit": sum(r.status == "node-limit" for r in group),
            "errors": sum(r.status == "error" for r in group),
        })
    return rows


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as a markdown table, one row per domain and level, the recognizers side by side."""
    names = [column for column, _, _ in RECOGNIZERS]
    by_cell = {(r["domain"], r["level"], r["recognizer"]): r for r in rows}
    cells = sorted({(r["domain"], r["level"]) for r in rows}, key=lambda c: (c[0], c[1]))
    head = ["domain", "level %", "problems", "goals", "observed"]
    for name in names:
        head += [f"{name} acc", f"{name} spread", f"{name} s"]
    head += ["prp problems", "prp unsolved"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for domain, level in cells:
        first = next(by_cell[(domain, level, n)] for n in names if (domain, level, n) in by_cell)
        row = [domain, str(level), str(first["problems"]), f"{first['goals']:.1f}", f"{first['observed']:.1f}"]
        for name in names:
            r = by_cell.get((domain, level, name))
            row += ([f"{100 * r['accuracy']:.1f}", "–" if math.isnan(r["spread"]) else f"{r['spread']:.2f}",
                     f"{r['seconds']:.3f}"] if r else ["", "", ""])
        prp = by_cell.get((domain, level, "prp"))
        row += [str(prp["problems"]), str(prp["node_limit"] + prp["errors"])] if prp else ["0", ""]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="a copy of goal-plan-recognition-dataset (DOMAIN/LEVEL/*.tar.bz2)")
    parser.add_argument("--domains", nargs="+", default=list(DOMAINS))
    parser.add_argument("--levels", nargs="+", type=int, default=list(LEVELS))
    parser.add_argument("--sample", type=int, default=None, help="problems drawn per domain and level (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="seeds the sample")
    parser.add_argument("--prp-sample", type=int, default=5,
                        help="of those, problems prp runs on per domain and level (default 5; 0: none)")
    parser.add_argument("--node-limit", type=int, default=10_000, help="nodes one prp cost search may expand")
    parser.add_argument("--records", type=Path, default=None, help="write every record and skipped problem as JSON")
    args = parser.parse_args(argv)
    try:
        if args.sample is not None and args.sample < 1:
            raise UserError(f"--sample must be a positive integer, got {args.sample}")
        if args.prp_sample < 0:
            raise UserError(f"--prp-sample must be 0 or more, got {args.prp_sample}")
        records, skipped = run(args.dataset, args.domains, args.levels, args.sample, args.seed, args.node_limit,
                               args.prp_sample)
    except UserError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    rows = summary(records)
    if args.records:
        args.records.write_text(json.dumps({"settings": {k: str(v) for k, v in vars(args).items()},
                                            "records": [asdict(r) for r in records], "skipped": skipped,
                                            "summary": rows}, indent=1))
    print(markdown(rows))
    for s in skipped:
        print(f"skipped {s['domain']}/{s['level']}/{s['problem']}: {s['error']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
