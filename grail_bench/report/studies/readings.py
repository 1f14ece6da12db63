"""Which readings of the paper's MiniGrid demonstrators can its optimal and suboptimal tables come from?

For each route reading and rounding, the pairs-only ceiling of every paper cell (``grail-bench ceiling
--pairs-only``: the best accuracy of scoring the observed pairs with per-goal policies, as all four of the
paper's recognizers score) and the paper cells significantly above it. The test is one-sided binomial, alpha
0.05: 10 seeds x 3 test demonstrations x K goals, each named right with probability at most the ceiling (plus
two standard errors where it is a Monte Carlo estimate), the paper's mean taken 0.005 low for its rounding.

Route readings: ``uniform`` (a shortest path drawn per demonstration), ``fixed`` (one per goal, straight
ahead first), and two more fixed rules built from the biased regime's heading orders: ``turn-first`` (north or
south first) and ``mixed`` (the Biased cards' rule: north first above the start row, east first below).

``grail-bench study readings`` prints the table (about 2 minutes, no training: the suboptimal ceilings are
Monte Carlo).
"""

from __future__ import annotations

import math
from typing import Sequence

from scipy import stats

from grail_bench.harness.ceiling import bayes_ceiling
from grail_bench.report.reference import paper_reference_path, read_reference
from grail_bench.task import GRTask, make_task
from grail_bench.task.observation import level_text
from grail_bench.report.studies import check_tasks

TASKS = {"Optimal": 2, "Optimal-4Goals": 4, "Optimal-6Goals": 6,
         "Suboptimal": 2, "Suboptimal-4Goals": 4, "Suboptimal-6Goals": 6}  # short name -> goals
LEVELS = (0.1, 0.2, 0.3)
RECOGNIZERS = ("bc", "graql", "gail", "airl")
ROUTES = ("uniform", "fixed", "turn-first", "mixed")
ROUNDINGS = ("ceil", "floor")
HEADINGS = {"turn-first": ("NE", "SE"), "mixed": ("NE", "ES")}  # for goals above, below the start row
HEADER = ("| route, rounding | pairs-only ceilings at 10 / 20 / 30 % (2, 4, 6 goals; optimal, then suboptimal) "
          "| paper cells above |\n|---|---|---|")


def task_id(name: str) -> str:
    """The task ID of a short name (``Optimal-4Goals`` -> ``GRAIL/MiniGrid-Optimal-4Goals-v0``)."""
    return f"GRAIL/MiniGrid-{name}-v0"


TASK_IDS = tuple(task_id(name) for name in TASKS)


def reading(name: str, route: str) -> GRTask | None:
    """The task under a route reading, or None where the regime cannot express it."""
    if route in ("uniform", "fixed"):
        return make_task(task_id(name), route_choice=route)
    if name.startswith("Suboptimal"):
        return None  # the biased regime's heading orders have no turn insertions
    biased = make_task(f"GRAIL/MiniGrid-Biased{name.removeprefix('Optimal')}-v0")
    above, below = HEADINGS[route]
    return biased.with_overrides(routes=[above if goal[1] < 4 else below for goal in biased.goals])


def above_ceiling(paper_mean: float, n: int, ceiling: float) -> bool:
    """Whether a paper mean over ``n`` observations is significantly above ``ceiling``."""
    hits = math.ceil((paper_mean - 0.005) * n - 1e-9)
    return stats.binom.sf(hits - 1, n, min(1.0, ceiling)) < 0.05


def run(tasks: Sequence[str] = TASK_IDS, samples: int = 2000) -> str:
    """Each route reading and rounding against the paper's cells, as a Markdown table.

    Args:
        tasks: The paper's optimal and suboptimal MiniGrid tasks to read (default: all six), in the table's order.
        samples: Monte Carlo samples of each pairs-only ceiling that cannot be enumerated.

    Returns:
        One row per route reading and rounding, after the header.

    Raises:
        UserError: For a task outside the six.
    """
    check_tasks("readings", tasks, TASK_IDS)
    names = dict(zip(TASK_IDS, TASKS))
    reference = read_reference(paper_reference_path())
    lines = [HEADER]
    for route in ROUTES:
        for rounding in ROUNDINGS:
            cells, above, total = [], [], 0
            for name in (names[t] for t in tasks):
                task = reading(name, route)
                if task is None:
                    continue
                ceilings = [bayes_ceiling(task, "subset", level, rounding=rounding, pairs_only=True, samples=samples)
                            for level in LEVELS]
                cells.append(" / ".join(f"{c.accuracy:.2f}" for c in ceilings))
                for c in ceilings:
                    for recognizer in RECOGNIZERS:
                        paper_mean = reference[(task_id(name), recognizer, c.observability)].mean_std[0]
                        total += 1
                        if above_ceiling(paper_mean, 30 * TASKS[name], c.accuracy + 2 * c.stderr):
                            above.append(f"{name} {level_text(c.observability)} {recognizer}")
            listed = f": {', '.join(above)}" if above else ""
            lines.append(f"| {route}, {rounding} | {'; '.join(cells)} | {len(above)} of {total}{listed} |")
    return "\n".join(lines) + "\n"
