"""What the store measures behind each MiniGrid cell significantly below the paper, at today's defaults.

For every optimal and suboptimal cell where a recognizer's default configuration is significantly lower than
the paper (two-sided Welch test of its seeds against the paper's mean and std, alpha 0.05, as LEADERBOARD.md
counts), the evidence already stored, with no training:

- the pairs-only ceiling (``grail-bench ceiling --pairs-only``): the best accuracy of scoring the observed
  pairs with per-goal policies, i.e. how much room the recognizer's form leaves;
- from the fit diagnostics (``fits`` table), the share of goals whose greedy rollout reaches its goal, and the
  cell's F1 over the seeds whose policies all reach their goals against the other seeds;
- from the imitation matrix (mean probability each goal's policy gives the actions of each goal's held-out
  demonstrations), the own goal's probability and the highest of another goal's policy on the same actions:
  a per-pair scorer separates goals only by that margin.

``grail-bench study causes --store leaderboard/results.sqlite`` prints the table (about 2 minutes: the
suboptimal ceilings are Monte Carlo).
"""

from __future__ import annotations

from statistics import mean
from typing import Sequence

from grail_bench.harness.ceiling import Ceiling, bayes_ceiling
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.harness.store import ResultsStore
from grail_bench.report.escape import md
from grail_bench.report.reference import paper_reference_path, read_reference
from grail_bench.task import make_task
from grail_bench.task.observation import level_text
from grail_bench.report.studies import check_tasks

TASKS = tuple(f"GRAIL/MiniGrid-{name}-v0" for name in (
    "Optimal", "Optimal-4Goals", "Optimal-6Goals", "Suboptimal", "Suboptimal-4Goals", "Suboptimal-6Goals"))
LEVELS = (0.1, 0.2, 0.3)
RECOGNIZERS = ("bc", "graql", "gail", "airl")
HEADER = ("| cell | ours | paper | pairs-only ceiling | goals reached | F1: seeds reaching every goal / others "
          "| own / best other policy's probability of the held-out actions |\n|---|---|---|---|---|---|---|")


def fmt(value: float | None) -> str:
    """Two decimals, or a dash for no value."""
    return "–" if value is None else f"{value:.2f}"


def margins(fit: FitRow) -> tuple[float, float]:
    """Mean over goals of the own policy's probability of its held-out actions, and of the best other policy's."""
    imitation = fit.parsed().imitation
    own = [row[i] for i, row in enumerate(imitation) if row[i] is not None]
    other = [max(v for j, v in enumerate(row) if j != i and v is not None) for i, row in enumerate(imitation)
             if row[i] is not None]
    return mean(own), mean(other)


def run(store: ResultsStore, tasks: Sequence[str] = TASKS, samples: int = 2000) -> str:
    """The cells below the paper with their stored evidence, as a Markdown table.

    Args:
        store: The results store holding the default configurations' offline rows and fit diagnostics.
        tasks: The paper's optimal and suboptimal MiniGrid tasks to examine (default: all six).
        samples: Monte Carlo samples of each pairs-only ceiling that cannot be enumerated.

    Returns:
        One row per cell (task, level, recognizer) significantly below the paper, after the header.

    Raises:
        UserError: For a task outside the six.
    """
    check_tasks("causes", tasks, TASKS)
    reference = read_reference(paper_reference_path())
    lines = [HEADER]
    for task_id in tasks:
        task, name = make_task(task_id), task_id.removeprefix("GRAIL/MiniGrid-").removesuffix("-v0")
        ceilings: dict[float, Ceiling] = {}
        for recognizer in RECOGNIZERS:
            planned = plan(task, RecognizerSpec(recognizer), task.make_env(task.goals[0]).action_space)
            rows = store.select(MODES["offline"], task=task.id, recognizer=recognizer,
                                config_hash=planned.config_hash, scorer=planned.labels[0],
                                protocol=task.protocol_label)
            fits = {f.seed: f for f in store.select(FitRow, task=task.id, recognizer=recognizer,
                                                    config_hash=planned.config_hash, mode="offline")}
            for level in LEVELS:
                f1 = {r.seed: r.f1 for r in rows if abs(r.observability - level) < 1e-9}
                reported = reference[(task.id, recognizer, level)]
                verdict = reported.verdict(list(f1.values()))
                if verdict is None or verdict.verdict != "lower":
                    continue
                if level not in ceilings:
                    ceilings[level] = bayes_ceiling(task, "subset", level, rounding=task.rounding, pairs_only=True,
                                                    samples=samples)
                lines.append(_cell(f"{name} {level_text(level)} {recognizer}", f1, reported.text, ceilings[level], fits))
    return "\n".join(lines) + "\n"


def _cell(label: str, f1: dict[int, float], paper: str, ceiling: Ceiling, fits: dict[int, FitRow]) -> str:
    """One table row: a cell's F1 over seeds beside the paper's, its ceiling and its seeds' fit evidence."""
    reached = [fits[s].parsed().reached for s in f1 if s in fits]
    goals = [bool(r) for seed in reached for r in seed if r is not None]
    every = [f1[s] for s in f1 if s in fits and all(fits[s].parsed().reached)]
    others = [f1[s] for s in f1 if s in fits and not all(fits[s].parsed().reached)]
    split = (f"{fmt(mean(every)) if every else '–'} ({len(every)}) / "
             f"{fmt(mean(others)) if others else '–'} ({len(others)})")
    pairs = [margins(fits[s]) for s in f1 if s in fits]
    probabilities = f"{mean(p[0] for p in pairs):.2f} / {mean(p[1] for p in pairs):.2f}" if pairs else "–"
    return (f"| {md(label)} | {mean(f1.values()):.2f} | {paper} | {ceiling.accuracy:.2f} | "
            f"{fmt(sum(goals) / len(goals)) if goals else '–'} | {split} | {probabilities} |")
