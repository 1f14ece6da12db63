"""Tests of the comparison's own arithmetic: gr_libs' scoring reproduced as it is, and RESULTS.md's cells.

    .venv/bin/python -m pytest -q leaderboard/gr_libs/test_protocol.py      (grail-bench's virtualenv)
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from grlibs_protocol import grlibs_correct, grlibs_summary  # noqa: E402
from report import cell, check_disagreements, gr_libs_accuracy  # noqa: E402


def instance(goal: tuple, predicted: str, p: float = 0.5, consecutive: bool = True, seconds: float = 1.0,
             failed: str | None = None) -> dict:
    return {"goal": list(goal), "percentage": p, "consecutive": consecutive, "actor_failed": failed,
            "predicted": predicted, "correct": predicted == str(goal),
            "grlibs_correct": grlibs_correct(goal, predicted), "inference_seconds": seconds}


def test_grlibs_check_matches_a_prefix_as_on_parking() -> None:
    # Parking's goals are strings: "1" against a prediction of "11" passes gr_libs' check.
    assert grlibs_correct("1", "11")
    assert grlibs_correct("11", "1")
    assert not grlibs_correct("1", "21")


def test_grlibs_check_is_exact_on_the_crossing_goals() -> None:
    goals = [(11, 1), (11, 11), (1, 11), (5, 9), (6, 1), (11, 3), (11, 5)]
    for g in goals:
        for h in goals:
            assert grlibs_correct(g, str(h)) == (g == h)


def test_grlibs_inference_time_is_divided_by_4_whatever_the_count() -> None:
    cells = [instance((11, 1), "(11, 1)", seconds=1.0) for _ in range(3)]
    results = grlibs_summary(cells)
    assert results["0.5"]["consecutive"]["average_inference_time"] == pytest.approx(3 / 4)  # true mean: 1.0
    assert results["total"]["total_average_inference_time"] == pytest.approx(1 / 4)
    assert results["total"]["total_accuracy"] == 1.0


def test_failed_actors_are_left_out_of_both_summaries() -> None:
    run = {"instances": [instance((11, 1), "(11, 1)"), instance((11, 11), "(11, 1)"),
                         instance((1, 11), "", failed="ValueError: probabilities contain NaN")]}
    assert gr_libs_accuracy([run])[(0.5, True)] == [0.5]
    assert grlibs_summary(run["instances"])["0.5"]["consecutive"]["num_of_tasks"] == 2
    assert check_disagreements([run]) == 0


def test_cell_shows_mean_and_interval_over_runs() -> None:
    assert cell([]) == "-"
    assert cell([0.5]) == "0.50"
    text = cell([0.0, 1.0, 0.5, 0.5])
    assert text.startswith("0.50 [") and text.endswith("]")


def test_every_reported_figure_names_a_registered_card_and_recognizer() -> None:
    import gymnasium as gym

    from grail_bench.recognizers import available_recognizers  # importing grail_bench registers its cards
    from reported import RECOGNIZERS, reported, task_id

    figures = reported()
    assert len(figures) == 500 and {r["fraction"] for r in figures} == {"0.3", "0.5", "0.7", "0.9", "1"}
    registered = set(gym.registry)
    for r in figures:
        card = task_id(r["env"], r["level"])
        assert card in registered, card
        assert RECOGNIZERS[r["recognizer"]] in available_recognizers()
