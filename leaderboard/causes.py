"""What the stores measure behind each MiniGrid cell significantly below the paper, at today's defaults.

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

Usage (prints a Markdown table; about 2 minutes, the suboptimal ceilings are Monte Carlo)::

    .venv/bin/python leaderboard/causes.py [--store leaderboard/results.sqlite]
"""

from __future__ import annotations

import argparse
from statistics import mean

from grail_bench import make_task
from grail_bench.harness.ceiling import bayes_ceiling
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.harness.store import ResultsStore
from grail_bench.report.reference import paper_reference_path, read_reference

TASKS = ("Optimal", "Optimal-4Goals", "Optimal-6Goals", "Suboptimal", "Suboptimal-4Goals", "Suboptimal-6Goals")
LEVELS = (0.1, 0.2, 0.3)
RECOGNIZERS = ("bc", "graql", "gail", "airl")


def fmt(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}"


def margins(fit: FitRow) -> tuple[float, float]:
    """Mean over goals of the own policy's probability of its held-out actions, and of the best other policy's."""
    imitation = fit.parsed().imitation
    own = [row[i] for i, row in enumerate(imitation) if row[i] is not None]
    other = [max(v for j, v in enumerate(row) if j != i and v is not None) for i, row in enumerate(imitation)
             if row[i] is not None]
    return mean(own), mean(other)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--store", default="leaderboard/results.sqlite")
    store = ResultsStore(parser.parse_args().store)
    reference = read_reference(paper_reference_path())
    print("| cell | ours | paper | pairs-only ceiling | goals reached | F1: seeds reaching every goal / others "
          "| own / best other policy's probability of the held-out actions |\n|---|---|---|---|---|---|---|")
    for name in TASKS:
        task = make_task(f"GRAIL/MiniGrid-{name}-v0")
        ceilings = {}
        for recognizer in RECOGNIZERS:
            planned = plan(task, RecognizerSpec(recognizer), task.make_env(task.goals[0]).action_space)
            rows = store.select(MODES["offline"], task=task.id, recognizer=recognizer,
                                config_hash=planned.config_hash, scorer=planned.scorers[0],
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
                    ceilings[level] = bayes_ceiling(task, "subset", level, rounding=task.rounding, pairs_only=True)
                reached = [fits[s].parsed().reached for s in f1 if s in fits]
                goals = [bool(r) for seed in reached for r in seed if r is not None]
                every = [f1[s] for s in f1 if s in fits and all(fits[s].parsed().reached)]
                others = [f1[s] for s in f1 if s in fits and not all(fits[s].parsed().reached)]
                split = (f"{fmt(mean(every)) if every else '–'} ({len(every)}) / "
                         f"{fmt(mean(others)) if others else '–'} ({len(others)})")
                pairs = [margins(fits[s]) for s in f1 if s in fits]
                probabilities = (f"{mean(p[0] for p in pairs):.2f} / {mean(p[1] for p in pairs):.2f}"
                                 if pairs else "–")
                print(f"| {name} {level:.0%} {recognizer} | {mean(f1.values()):.2f} | {reported.text} | "
                      f"{ceilings[level].accuracy:.2f} | {fmt(sum(goals) / len(goals)) if goals else '–'} | {split} | "
                      f"{probabilities} |", flush=True)


if __name__ == "__main__":
    main()
