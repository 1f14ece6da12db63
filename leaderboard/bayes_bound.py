"""Bayes-optimal accuracy on the optimal MiniGrid tasks: what no recognizer can beat.

With a fixed start and shortest paths drawn uniformly per goal, the best any
recognizer can do from the first ceil(p * T) actions is to pick the goal with
the largest joint probability of that prefix. Run with the suite installed:

    python leaderboard/bayes_bound.py
"""

from __future__ import annotations

import math
from collections import defaultdict

import grail_bench
from grail_bench.demos.minigrid import all_shortest_paths

LEVELS = (0.1, 0.2, 0.3)


def bayes_accuracy(task_id: str, level: float) -> float:
    """Expected accuracy of the Bayes-optimal recognizer at one observability level."""
    task = grail_bench.make_task(task_id)
    env = task.make_env()
    base = env.unwrapped
    joint: dict[tuple, dict] = defaultdict(lambda: defaultdict(float))  # prefix -> goal -> P(goal, prefix)
    for goal in task.goals:
        paths = all_shortest_paths(base.model, (*base.start, base.start_dir), goal)
        for path in paths:
            k = max(1, math.ceil(level * len(path)))
            joint[tuple(path[:k])][goal] += 1 / len(task.goals) / len(paths)
    return sum(max(by_goal.values()) for by_goal in joint.values())


if __name__ == "__main__":
    print("| task | " + " | ".join(f"{p:.0%}" for p in LEVELS) + " |")
    print("|---|" + "---|" * len(LEVELS))
    for task_id in ("GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Optimal-4Goals-v0", "GRAIL/MiniGrid-Optimal-6Goals-v0"):
        print(f"| {task_id} | " + " | ".join(f"{bayes_accuracy(task_id, p):.2f}" for p in LEVELS) + " |")
