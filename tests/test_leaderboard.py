"""Leaderboard tables: one row per task and level, best in bold, reported values beside ours."""

from __future__ import annotations

from grail_bench.leaderboard import build_boards, markdown


def record(task, rec, scorer, obs, f1):
    return {"task": task, "recognizer": rec, "scorer": scorer, "observability": obs, "f1_mean": f1, "f1_std": 0.1,
            "config_hash": "abcdef123456", "n_seeds": 2, "fit_seconds_per_goal": 1.0,
            "score_us_per_observation": 10.0, "tie_rate": 0.0}


def test_tasks_with_equal_goal_counts_get_their_own_rows():
    records = [record("GRAIL/PandaReach-Gaussian-0.1-v0", "bc", "mse", 0.02, 0.9),
               record("GRAIL/PandaReach-Gaussian-0.3-v0", "bc", "mse", 0.02, 0.6),
               record("GRAIL/PandaReach-Gaussian-0.3-v0", "draco", "wasserstein", 0.02, 0.7)]
    (board,) = build_boards(records)
    assert board.title == "panda_reach / gaussian" and len(board.rows) == 2
    text = markdown([board], records)
    assert "| PandaReach-Gaussian-0.1 | 4 | 2% | **0.90 ± 0.10** | – |" in text
    assert "| PandaReach-Gaussian-0.3 | 4 | 2% | 0.60 ± 0.10 | **0.70 ± 0.10** |" in text


def test_reported_values_sit_beside_the_papers_scorer_only():
    records = [record("GRAIL/MiniGrid-Optimal-v0", "bc", "mse", 0.1, 0.5),
               record("GRAIL/MiniGrid-Optimal-v0", "bc", "wasserstein", 0.1, 0.4)]
    (board,) = build_boards(records, {("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1): "0.73 ± 0.33"})
    text = markdown([board], records)
    assert "| MiniGrid-Optimal | 2 | 10% | **0.50 ± 0.10** | 0.73 ± 0.33 | 0.40 ± 0.10 |" in text
    assert text.count("*(paper)*") == 2  # the header note and one column
