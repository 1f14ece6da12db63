"""gr_libs' own accuracy figures beside grail-bench's on the same goal sets, as a Markdown table.

gr_libs never published a results table; for a while its repository carried per-level accuracy summaries
(``reported.csv``: copied verbatim, with the commit they come from). Their candidate goal sets are grail-bench's
L1-L5 cards and their protocol is gr_libs' own (``int(p * T)`` pairs; ``non_consecutive`` an ordered random subset,
grail-bench's ``subset``; ``consecutive`` the first pairs, ``prefix``). What differs: gr_libs observes its own RL
agents (on MiniGrid the recognizer's own Q-learner; TD3 on PointMaze; PPO and SAC on PandaReach), a handful of
sequences per level and run, over an unstated number of runs; grail-bench observes its demonstrators (the optimal
regime here) on every goal of a set, over its seeds. So the table is a reference, not a replication. Each
grail-bench cell is the canonical configuration's mean accuracy over its stored seeds.

    .venv/bin/python leaderboard/gr_libs/reported.py --store leaderboard/results.sqlite
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path

from grail_bench.core.errors import UserError
from grail_bench.harness.modes.offline import aggregate
from grail_bench.harness.store import ResultsStore
from grail_bench.report.configs import configuration, method_of

REPORTED = Path(__file__).with_name("reported.csv")
#: gr_libs' env names and the grail-bench cards of the same layout (optimal regime; ``-L1``..``-L4`` added per level).
TASKS = {"MiniGrid-SimpleCrossingS13N4": "GRAIL/MiniGrid-SimpleCrossing-Optimal",
         "MiniGrid-LavaCrossingS9N2": "GRAIL/MiniGrid-LavaCrossing-Optimal",
         "PointMaze-FourRoomsEnvDense-11x11": "GRAIL/PointMaze-FourRooms-Optimal",
         "PointMaze-ObstaclesEnvDense-11x11": "GRAIL/PointMaze-Obstacles-Optimal",
         "PandaMyReachDense": "GRAIL/PandaReach-GrLibs-Optimal"}
#: gr_libs' recognizer names and grail-bench's registered ones.
RECOGNIZERS = {"Graql": "graql", "ExpertBasedGraml": "graml", "Draco": "draco", "GCDraco": "gc-draco",
               "GCGraml": "gc-graml"}
ORDERINGS = {"non_consecutive": ("subset+floor", "non-consecutive (ordered subset)"),
             "consecutive": ("prefix+floor", "consecutive (prefix)")}


def task_id(env: str, level: str) -> str:
    """The grail-bench card of gr_libs' ``env`` at ``level`` (L5 is the unsuffixed ID)."""
    return f"{TASKS[env]}-v0" if level == "L5" else f"{TASKS[env]}-{level}-v0"


def reported() -> list[dict[str, str]]:
    """gr_libs' figures (``reported.csv``, comment lines skipped)."""
    with REPORTED.open() as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def measured(store: Path, figures: list[dict[str, str]]) -> dict[tuple[str, str, str, float], tuple[float, int]]:
    """Per (task, recognizer, protocol, fraction) of ``figures``: the canonical configuration's mean accuracy and its
    seeds."""
    tasks = sorted({task_id(r["env"], r["level"]) for r in figures})
    recognizers = sorted(set(RECOGNIZERS.values()))
    with ResultsStore(store, read_only=True) as db:
        rows = db.rows(task=tasks, recognizer=recognizers)
    return {(r.task, r.recognizer, r.protocol, round(r.observability, 6)): (r.accuracy_mean, r.n_seeds)
            for r in aggregate(rows) if configuration(r).canonical}


def table(figures: list[dict[str, str]], ours: dict[tuple[str, str, str, float], tuple[float, int]], ordering: str,
          fractions: tuple[float, ...]) -> str:
    """Markdown: a row per layout, level and method of gr_libs' ``figures``, each fraction's cell
    ``gr_libs / grail-bench`` (``ours``: :func:`measured`)."""
    theirs: dict[tuple[str, str, str], dict[float, str]] = defaultdict(dict)
    for r in figures:
        if r["ordering"] == ordering and float(r["fraction"]) in fractions:
            theirs[(r["env"], r["level"], r["recognizer"])][float(r["fraction"])] = r["mean"]
    protocol, title = ORDERINGS[ordering]
    head = " | ".join(f"{round(f * 100)} %" for f in fractions)
    lines = [f"Accuracy, {title}: gr_libs' reported mean / grail-bench's mean (seeds)", "",
             f"| layout | level | method | {head} |", "|---|---|---|" + "---|" * len(fractions)]
    for (env, level, rec), by_fraction in sorted(theirs.items()):
        name = RECOGNIZERS[rec]
        cells = []
        for f in fractions:
            got = ours.get((task_id(env, level), name, protocol, round(f, 6)))
            mine = "–" if got is None else f"{got[0]:.2f} ({got[1]})"
            cells.append(f"{float(by_fraction[f]):.2f} / {mine}" if f in by_fraction else "–")
        lines.append(f"| {env} | {level} | {method_of(name)[0]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--store", type=Path, default=Path("leaderboard/results.sqlite"))
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.3, 0.5, 1.0])
    args = parser.parse_args()
    figures = reported()
    try:
        ours = measured(args.store, figures)
    except UserError as exc:
        raise SystemExit(f"error: {exc}") from None
    for ordering in ORDERINGS:
        print(table(figures, ours, ordering, tuple(args.fractions)), end="\n\n")


if __name__ == "__main__":
    main()
