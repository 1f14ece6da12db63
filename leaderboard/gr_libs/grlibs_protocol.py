"""gr_libs' own scoring arithmetic (``gr_libs.odgr_executor.run_odgr_problem``), reproduced as it is.

Standard library only, so both virtualenvs import it: ``gr_libs_side.py`` records what gr_libs would report,
and the tests check the two defects it carries (a prefix-matching correctness check, an inference-time average
divided by 4).
"""

from __future__ import annotations

from typing import Any


def grlibs_correct(goal: Any, closest_goal: str) -> bool:
    """gr_libs' own correctness check (``odgr_executor.run_odgr_problem``): a character-wise ``zip``, which
    stops at the shorter string, so a prefix counts as a match ("1" against "11")."""
    return all(a == b for a, b in zip(str(goal), closest_goal))


def grlibs_summary(instances: list[dict[str, Any]]) -> dict[str, Any]:
    """The per-(fraction, consecutive) dict ``run_odgr_problem`` builds, with its formulas: accuracy from its
    check, and ``average_inference_time`` summed over the cell's instances and then divided by
    ``len(results[p][c])``, the number of keys of that dict (4), not the number of instances."""
    results: dict[str, dict[str, dict[str, float]]] = {}
    for inst in instances:
        if inst["actor_failed"]:
            continue
        cell = results.setdefault(str(inst["percentage"]), {}).setdefault(
            "consecutive" if inst["consecutive"] else "non_consecutive",
            {"correct": 0, "num_of_tasks": 0, "accuracy": 0, "average_inference_time": 0},
        )
        cell["average_inference_time"] += inst["inference_seconds"]
        cell["correct"] += int(inst["grlibs_correct"])
        cell["num_of_tasks"] += 1
    for by_cons in results.values():
        for cell in by_cons.values():
            cell["average_inference_time"] /= len(cell)  # gr_libs' divisor: 4 keys
            cell["accuracy"] = cell["correct"] / cell["num_of_tasks"]
    cells = [c for by_cons in results.values() for c in by_cons.values()]
    total_tasks = sum(c["num_of_tasks"] for c in cells)
    if not total_tasks:  # every actor failed: gr_libs' executor would have stopped before this point
        results["total"] = {"total_accuracy": float("nan"), "total_average_inference_time": float("nan")}
        return results
    results["total"] = {
        "total_accuracy": sum(c["correct"] for c in cells) / total_tasks,
        "total_average_inference_time": sum(c["average_inference_time"] for c in cells) / total_tasks,
    }
    return results
