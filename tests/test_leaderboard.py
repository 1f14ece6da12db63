"""Leaderboard tables: one row per task and level, best in bold, reported values beside ours."""

from __future__ import annotations

import dataclasses

from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report import leaderboard
from grail_bench.report.boards import placement_counts
from grail_bench.report.reference import Reported
from grail_bench.report.text import markdown


def defaults(task_id):
    """The task parameters a run at the task's defaults records."""
    import grail_bench

    task = grail_bench.make_task(task_id)
    return {**task.params, **task.env_params, "n_demos": task.n_demos, "n_train": task.n_train}


def record(task, rec, scorer, obs, f1, protocol=None, **fields):
    """A stored row of ``task``, under the task's default protocol and rounding unless ``protocol`` says."""
    import grail_bench

    protocol = protocol or grail_bench.make_task(task).protocol_label
    base = dict(task_params=defaults(task), task=task, recognizer=rec, scorer=scorer, observability=obs, f1_mean=f1, f1_std=0.1,
                f1_ci95_low=f1 - 0.1, f1_ci95_high=f1 + 0.1, f1_iqm=f1, f1_values=(f1 - 0.1, f1 + 0.1),
                protocol=protocol, config_hash="abcdef123456", n_seeds=2, seeds=[0, 1], fit_seconds_per_goal=1.0,
                score_us_per_observation=10.0, tie_rate=0.0, accuracy_mean=f1, precision_mean=f1, recall_mean=f1)
    return OfflineRecord(**(base | fields))


def build_boards(records, reference=None, ceiling_samples=2000):
    """The boards of records, with the Bayes ceilings (computed through the leaderboard model, as the CLI does)."""
    return leaderboard.build([], reference, ceiling_samples, records=records).boards


def test_tasks_with_equal_goal_counts_get_their_own_rows():
    records = [record("GRAIL/PandaReach-Gaussian-0.1-v0", "bc", "mse", 0.02, 0.9),
               record("GRAIL/PandaReach-Gaussian-0.3-v0", "bc", "mse", 0.02, 0.6),
               record("GRAIL/PandaReach-Gaussian-0.3-v0", "draco", "wasserstein", 0.02, 0.7)]
    (board,) = build_boards(records)
    assert board.title == "panda_reach / gaussian (subset)" and len(board.rows) == 2
    text = markdown([board], records)
    assert "| PandaReach-Gaussian-0.1 | 4 | 2% | – | **0.90 ± 0.10** | – |" in text  # no ceiling
    assert "| PandaReach-Gaussian-0.3 | 4 | 2% | – | 0.60 ± 0.10 | **0.70 ± 0.10** |" in text


def test_reported_values_sit_beside_the_papers_scorer_only():
    records = [record("GRAIL/MiniGrid-Optimal-v0", "bc", "mse", 0.1, 0.5),
               record("GRAIL/MiniGrid-Optimal-v0", "bc", "wasserstein", 0.1, 0.4)]
    reference = {("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1): Reported("0.73 ± 0.33", (0.49, 0.90))}
    (board,) = build_boards(records, reference, ceiling_samples=None)
    text = markdown([board], records)
    assert "| MiniGrid-Optimal | 2 | 10% | – | **0.50 ± 0.10 =** | 0.73 ± 0.33 [0.49, 0.90] | 0.40 ± 0.10 |" \
        in text
    assert text.count("*(paper)*") == 2  # the header note and one column
    assert placement_counts([board]) == {"inside": 1, "above": 0, "below": 0}


def test_paper_values_only_on_the_tasks_default_protocol_and_ceilings_normalise():
    fixed = {**defaults("GRAIL/MiniGrid-Optimal-v0"), "route_choice": "fixed"}
    records = [record("GRAIL/MiniGrid-Optimal-v0", "bc", "mse", 0.1, 0.3, protocol="prefix"),
               record("GRAIL/MiniGrid-Optimal-v0", "bc", "mse", 0.1, 0.95),
               record("GRAIL/MiniGrid-Optimal-v0", "bc", "mse", 0.1, 0.9, task_params=fixed)]
    reference = {("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1): Reported("0.73 ± 0.33", (0.49, 0.90))}
    boards = build_boards(records, reference, ceiling_samples=50)
    assert [b.title for b in boards] == ["minigrid / optimal (prefix)", "minigrid / optimal (subset)"]
    text = markdown(boards, records)
    # Prefix at 10 % with every demonstration's route drawn uniformly (the default): ceiling 2/3 exactly, so
    # 0.30 normalises to (0.3 - 0.5) / (2/3 - 0.5) = -1.2; no paper value under another protocol. Both goals'
    # paths are 11 actions long, so the count of pairs says nothing: the pairs-only ceiling is the same.
    assert "| MiniGrid-Optimal | 2 | 10% | 0.67 | 0.67 | **0.30 ± 0.10 [-1.20]** |\n" in text
    # The paper's values sit beside the task's default reading only (subset, uniform routes: ceiling 0.97).
    assert "| MiniGrid-Optimal | 2 | 10% | 0.97 | 0.97 | **0.95 ± 0.10 ▲ [0.96]** | 0.73 ± 0.33 [0.49, 0.90] |" in text
    # One fixed route per goal, 11 pairs of which the first 5 (the eastward run) are shared, and
    # ceil(0.1 * 11) = 2 pairs observed: both fall in the shared run with probability C(5, 2) / C(11, 2) = 2/11,
    # a coin flip then, so the ceiling is 1 - 1/11 = 10/11 and 0.90 normalises to 0.4 / (10/11 - 0.5) = 0.98.
    assert '| MiniGrid-Optimal (route_choice="fixed") | 2 | 10% | 0.91 | 0.91 | **0.90 ± 0.10 [0.98]** | – |' in text
    assert placement_counts(boards) == {"inside": 0, "above": 1, "below": 0}


def test_boards_show_the_pairs_only_ceiling_beside_the_bayes_one():
    fixed = {**defaults("GRAIL/MiniGrid-Optimal-4Goals-v0"), "route_choice": "fixed"}
    records = [record("GRAIL/MiniGrid-Optimal-4Goals-v0", "bc", "mse", 0.1, 0.3, protocol="prefix",
                      task_params=fixed)]
    (board,) = build_boards(records, ceiling_samples=50)
    # The first 2 pairs of the 11-action paths or the first 1 of the 9-action ones, all "forward": the count
    # tells long from short (Bayes 0.5), the pairs nothing (pairs-only: a draw among all 4 goals, 0.25).
    assert '| MiniGrid-Optimal-4Goals (route_choice="fixed") | 4 | 10% | 0.50 | 0.25 | **0.30 ± 0.10 [0.20]** |' \
        in markdown([board], records)
    (no_ceilings,) = build_boards(records, ceiling_samples=None)
    assert not no_ceilings.pairs_only and "pairs-only" not in markdown([no_ceilings], records).split("## ")[1]


def test_ceilings_use_the_task_parameters_of_the_run():
    plain = record("GRAIL/MiniGrid-Suboptimal-v0", "bc", "mse", 0.2, 0.9, protocol="prefix")
    no_turns = dataclasses.replace(plain, task_params={**plain.task_params, "route_choice": "uniform",
                                                       "turn_prob": 0.0})
    (board,) = build_boards([no_turns], ceiling_samples=50)
    (ceiling,) = board.ceilings.values()
    assert ceiling.method == "exact" and round(ceiling.accuracy, 2) == 0.75  # as the optimal task
    mixed = [no_turns, dataclasses.replace(plain, recognizer="graql",
                                           task_params={**plain.task_params, "route_choice": "uniform",
                                                        "turn_prob": 0.5})]
    (board,) = build_boards(mixed, ceiling_samples=50)
    # Runs with other parameters (readings) get rows of their own, each with its own ceiling.
    assert [row[4] for row in board.rows] == ["turn_prob=0.0", "turn_prob=0.5"]  # uniform routes: the default
    assert len(board.ceilings) == 2 and round(board.ceilings[board.rows[0]].accuracy, 2) == 0.75
    assert "| MiniGrid-Suboptimal (turn_prob=0.0) | 2 | 20% | 0.75 |" in markdown([board], mixed)


def test_a_recognizer_run_with_two_configurations_gets_a_column_per_setting():
    task = "GRAIL/PandaReach-Gaussian-0.1-v0"
    default = record(task, "draco", "wasserstein", 0.02, 0.5, recognizer_config={"sac_steps": 15000})
    longer = record(task, "draco", "wasserstein", 0.02, 0.8, config_hash="0123456789ab",
                    recognizer_config={"sac_steps": 60000})
    (board,) = build_boards([default, longer], ceiling_samples=None)
    assert board.columns == ["draco/wasserstein sac_steps=15000", "draco/wasserstein sac_steps=60000"]
    # Same recognizer settings, different task parameters: only the hash tells the runs apart.
    same = dataclasses.replace(longer, recognizer_config={"sac_steps": 15000})
    (board,) = build_boards([default, same], ceiling_samples=None)
    assert board.columns == ["draco/wasserstein [012345]", "draco/wasserstein [abcdef]"]


def test_paper_values_sit_beside_the_default_configuration_only_so_no_cell_counts_twice():
    from grail_bench.recognizers.registry import build
    from grail_bench.report.boards import verdict_counts

    task = "GRAIL/MiniGrid-Optimal-v0"
    default = record(task, "gail", "mse", 0.1, 0.5, recognizer_config=dict(build("gail").config))
    longer = record(task, "gail", "mse", 0.1, 0.9, config_hash="0123456789ab",
                    recognizer_config={**build("gail").config, "total_timesteps": 160000})
    reference = {(task, "gail", 0.1): Reported("0.64 ± 0.28", (0.44, 0.84))}
    (board,) = build_boards([default, longer], reference, ceiling_samples=None)
    assert list(board.reported) == [(*board.rows[0], "gail/mse total_timesteps=20000")]
    assert sum(verdict_counts([board]).values()) == 1
    # Without a run at the default configuration every configuration is compared.
    (board,) = build_boards([longer], reference, ceiling_samples=None)
    assert len(board.reported) == 1
    # A run stored before the task had parameters reads as their implicit values (here the defaults): it
    # shares the default row, and the paper's value stays beside the default configuration alone.
    legacy = dataclasses.replace(longer, task_params={}, config_hash="fedcba987654")
    (board,) = build_boards([default, legacy], reference, ceiling_samples=None)
    assert len(board.rows) == 1 and len(board.reported) == 1
    assert sum(verdict_counts([board]).values()) == 1


def test_runs_table_shows_ranking_metrics_averaged_over_levels():
    records = [record("GRAIL/MiniGrid-Optimal-v0", "bc", "mse", lv, 0.5, top2_mean=t, mean_rank_mean=m)
               for lv, t, m in ((0.1, 0.8, 1.6), (0.3, 1.0, 1.2))]
    records.append(record("GRAIL/MiniGrid-Optimal-v0", "graql", "kl", 0.1, 0.5))  # stored before: no ranking
    boards = build_boards(records, ceiling_samples=None)
    text = markdown(boards, records)
    assert "| GRAIL/MiniGrid-Optimal-v0 | bc/mse | 2 | 1.00 | 10 | 0.0% | 0.90 | 1.40 | – |" in text
    assert "| GRAIL/MiniGrid-Optimal-v0 | graql/kl | 2 | 1.00 | 10 | 0.0% | – | – | – |" in text


def test_profiles_gaps_and_calibration_are_written_from_the_ceilings(tmp_path):
    from grail_bench.report.reproduce import write_robust
    from grail_bench.report.summary import TAUS, domain_summaries
    from grail_bench.stats.metrics import reliability_bins

    task = "GRAIL/MiniGrid-Optimal-v0"
    good = [record(task, "bc", "mse", lv, 0.95, f1_values=(0.9, 1.0)) for lv in (0.1, 0.2, 0.3)]
    weak = [record(task, "graql", "kl", lv, 0.6, f1_values=(0.5, 0.7)) for lv in (0.1, 0.2, 0.3)]
    posterior = [record(task, "bc", "loglik", 0.1, 0.9, reliability=reliability_bins([0.9, 0.9], [True, False]))]
    board = leaderboard.build([], None, 50, records=good + weak + posterior)
    (summary,) = domain_summaries(board.boards, reps=200)
    assert summary.profile_strata == 3 and set(summary.gaps) == {"bc/mse", "graql/kl"}  # own scorers only
    assert summary.gaps["bc/mse"].point < summary.gaps["graql/kl"].point  # nearer the ceiling
    point, low, high = summary.profiles["graql/kl"]  # F1 0.5 is chance: normalised 0, not above 0
    assert len(point) == len(TAUS) and point[0] == 0.5 and all(lo <= p <= hi for p, lo, hi in zip(point, low, high))
    written = {p.name for p in write_robust(board, tmp_path, reps=200)}
    assert {"PROFILES.md", "performance_profiles.png", "CALIBRATION.md", "reliability.png"} <= written
    text = (tmp_path / "CALIBRATION.md").read_text()
    assert "| minigrid | bc/loglik | 1 |" in text and "| 0.40 |" in text  # ECE: |0.5 - 0.9|
    assert "## minigrid (3 strata)" in (tmp_path / "PROFILES.md").read_text()
