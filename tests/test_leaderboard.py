"""Leaderboard tables: one row per task and level, best in bold, reported values beside ours; canonical
configurations on the main boards, named variants apart, archived ones in the archive."""

from __future__ import annotations

import dataclasses

from conftest import offline_record

from grail_bench.report import leaderboard
from grail_bench.report.boards import placement_counts
from grail_bench.report.reference import Reported
from grail_bench.report.text import markdown


def defaults(task_id):
    """The task parameters a run at the task's defaults records."""
    import grail_bench

    task = grail_bench.make_task(task_id)
    return {**task.params, **task.env_params, "n_demos": task.n_demos, "n_train": task.n_train}


def built(records, reference=None, ceiling_samples=None):
    """The leaderboard model of records (main boards, variants, archive)."""
    return leaderboard.build([], reference, ceiling_samples, records=records)


def build_boards(records, reference=None, ceiling_samples=2000):
    """The boards of records, with the Bayes ceilings (computed through the leaderboard model, as the CLI does)."""
    return leaderboard.build([], reference, ceiling_samples, records=records).boards


def test_tasks_with_equal_goal_counts_get_their_own_rows():
    records = [offline_record("GRAIL/PandaReach-Gaussian-0.1-v0", "bc", 0.02, 0.9, scorer="mse"),
               offline_record("GRAIL/PandaReach-Gaussian-0.3-v0", "bc", 0.02, 0.6, scorer="mse"),
               offline_record("GRAIL/PandaReach-Gaussian-0.3-v0", "draco", 0.02, 0.7, scorer="wasserstein")]
    (board,) = build_boards(records)
    assert board.title == "panda_reach / gaussian (subset)" and len(board.rows) == 2
    assert board.columns == ["BC-GRAIL", "DRACO"]  # named as the paper names the methods
    text = markdown([board], records)
    assert "| PandaReach-Gaussian-0.1 | 4 | 2% | – | **0.90 ± 0.10** | – |" in text  # no ceiling
    assert "| PandaReach-Gaussian-0.3 | 4 | 2% | – | 0.60 ± 0.10 | **0.70 ± 0.10** |" in text


def test_reported_values_sit_beside_the_canonical_configuration_only():
    records = [offline_record("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1, 0.5, scorer="mse"),
               offline_record("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1, 0.4, scorer="wasserstein")]
    reference = {("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1): Reported("0.73 ± 0.33", (0.49, 0.90))}
    board = built(records, reference)
    text = markdown(board.boards, records, variants=board.variants)
    assert "| MiniGrid-Optimal | 2 | 10% | – | **0.50 ± 0.10 =** | 0.73 ± 0.33 [0.49, 0.90] |\n" in text
    # Another scorer is a named variant, in its own board, with no reported value beside it.
    assert "## Variants" in text and "### minigrid: BC-GRAIL variants" in text
    assert "| task | goals | obs | ceiling | BC-GRAIL · wasserstein |" in text
    assert "| MiniGrid-Optimal | 2 | 10% | – | **0.40 ± 0.10** |" in text
    assert text.count("*(paper)*") == 2  # the header note and one column
    assert placement_counts(board.boards) == {"inside": 1, "above": 0, "below": 0}


def test_paper_values_only_on_the_tasks_default_protocol_and_ceilings_normalise():
    fixed = {**defaults("GRAIL/MiniGrid-Optimal-v0"), "route_choice": "fixed"}
    records = [offline_record("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1, 0.3, scorer="mse", protocol="prefix"),
               offline_record("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1, 0.95, scorer="mse"),
               offline_record("GRAIL/MiniGrid-Optimal-v0", "bc", 0.1, 0.9, scorer="mse", task_params=fixed)]
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
    records = [offline_record("GRAIL/MiniGrid-Optimal-4Goals-v0", "bc", 0.1, 0.3, scorer="mse", protocol="prefix",
                      task_params=fixed)]
    (board,) = build_boards(records, ceiling_samples=50)
    # The first 2 pairs of the 11-action paths or the first 1 of the 9-action ones, all "forward": the count
    # tells long from short (Bayes 0.5), the pairs nothing (pairs-only: a draw among all 4 goals, 0.25).
    assert '| MiniGrid-Optimal-4Goals (route_choice="fixed") | 4 | 10% | 0.50 | 0.25 | **0.30 ± 0.10 [0.20]** |' \
        in markdown([board], records)
    (no_ceilings,) = build_boards(records, ceiling_samples=None)
    assert not no_ceilings.pairs_only and "pairs-only" not in markdown([no_ceilings], records).split("## ")[1]


def test_ceilings_use_the_task_parameters_of_the_run():
    task = "GRAIL/MiniGrid-Suboptimal-v1"
    no_turns = offline_record(task, "bc", 0.2, 0.9, scorer="mse", protocol="prefix",
                      task_params={**defaults(task), "route_choice": "uniform", "turn_prob": 0.0})
    (board,) = build_boards([no_turns], ceiling_samples=50)
    (ceiling,) = board.ceilings.values()
    assert ceiling.method == "exact" and round(ceiling.accuracy, 2) == 0.75  # as the optimal task
    mixed = [no_turns, offline_record(task, "graql", 0.2, 0.9, scorer="kl", protocol="prefix",
                              task_params={**defaults(task), "route_choice": "uniform", "turn_prob": 0.5})]
    (board,) = build_boards(mixed, ceiling_samples=50)
    # Runs with other parameters (readings) get rows of their own, each with its own ceiling.
    assert [row.reading for row in board.rows] == ["turn_prob=0.0", "turn_prob=0.5"]  # uniform routes: the default
    assert len(board.ceilings) == 2 and round(board.ceilings[board.rows[0]].accuracy, 2) == 0.75
    assert "| MiniGrid-Suboptimal (turn_prob=0.0) | 2 | 20% | 0.75 |" in markdown([board], mixed)


def test_a_method_run_in_several_configurations_keeps_its_canonical_column_and_names_the_others():
    task = "GRAIL/PandaReach-Gaussian-0.1-v0"
    default = offline_record(task, "draco", 0.02, 0.5, scorer="wasserstein")
    longer = offline_record(task, "draco", 0.02, 0.8, scorer="wasserstein", settings={"ppo_steps": 300000})
    board = built([default, longer])
    (main,) = board.boards
    (variants,) = board.variants
    assert main.columns == ["DRACO"] and variants.columns == ["DRACO · ppo_steps 300 000"]
    assert variants.title == "panda_reach: DRACO variants" and not board.archive
    # Same settings on other task parameters: the same column, a row per reading of the parameters.
    other = offline_record(task, "draco", 0.02, 0.7, scorer="wasserstein",
                   task_params={**defaults(task), "noise_std": 0.2} if "noise_std" in defaults(task) else
                   {**defaults(task), "n_demos": defaults(task)["n_demos"] + 1})
    (main,) = built([default, other]).boards
    assert main.columns == ["DRACO"] and len(main.rows) == 2 and {r.reading for r in main.rows} != {""}


def test_paper_values_sit_beside_the_canonical_configuration_so_no_cell_counts_twice():
    from grail_bench.report.boards import verdict_counts

    task = "GRAIL/MiniGrid-Optimal-v0"
    default = offline_record(task, "gail", 0.1, 0.5, scorer="mse")
    longer = offline_record(task, "gail", 0.1, 0.9, scorer="mse", settings={"total_timesteps": 160000})
    reference = {(task, "gail", 0.1): Reported("0.64 ± 0.28", (0.44, 0.84))}
    board = built([default, longer], reference)
    (main,) = board.boards
    assert list(main.reported) == [(main.rows[0], "GAIL-GRAIL")]
    assert sum(verdict_counts(board.boards).values()) == 1
    assert [b.columns for b in board.variants] == [["GAIL-GRAIL · total_timesteps 160 000"]]
    assert not any(b.reported for b in board.variants)
    # A run stored under a configuration today's code would hash otherwise (here: before the task had
    # parameters) is archived: out of the boards, listed with what differs.
    legacy = dataclasses.replace(default, task_params={}, config_hash="fedcba987654",
                                 f1=dataclasses.replace(default.f1, mean=0.1))
    board = built([default, legacy], reference)
    (main,) = board.boards
    assert len(main.rows) == 1 and main.cell(main.rows[0], "GAIL-GRAIL").f1.mean == 0.5
    (entry,) = board.archive
    assert entry.config.label == "GAIL-GRAIL · archived fedcba" and entry.rows == 2 and entry.tasks == (task,)
    text = markdown(board.boards, board.records, archive=board.archive)
    assert "| GAIL-GRAIL | GAIL-GRAIL · archived fedcba | none | MiniGrid-Optimal-v0 | 0, 1 | 2 | `fedcba987654` |" \
        in text


def test_demonstrator_is_a_reference_after_the_methods_never_the_best():
    task = "GRAIL/MiniGrid-Optimal-v0"
    records = [offline_record(task, "bc", 0.1, 0.6, scorer="mse"),
               offline_record(task, "demonstrator", 0.1, 0.99, scorer="mse"),
               offline_record(task, "graql", 0.1, 0.5, scorer="kl")]
    (main,) = built(records).boards
    assert main.columns == ["BC-GRAIL", "GRAQL", "Demonstrator (perfect imitation)"]
    assert main.methods == ["BC-GRAIL", "GRAQL"] and main.best(main.rows[0]) == 0.6
    text = markdown([main], records)
    assert "| Demonstrator (perfect imitation) (reference) |" in text
    assert "| **0.60 ± 0.10** | 0.50 ± 0.10 | 0.99 ± 0.10 |" in text


def test_markdown_escapes_markup_in_names():
    task = "GRAIL/MiniGrid-Optimal-v0"
    odd = [dataclasses.replace(offline_record(task, "bc", 0.1, 0.5, scorer="mse"), recognizer=name, scorer="default")
           for name in ("<!--<script>", "</script>", "a|b & <b>")]
    board = built(odd)
    text = markdown(board.boards, board.records, variants=board.variants).split("## Runs")[0]
    assert "<script>" not in text and "</script>" not in text and "<!--" not in text and "<b>" not in text
    assert "&lt;!--&lt;script&gt;" in text and "&lt;/script&gt;" in text and "a\\|b & &lt;b&gt;" in text
    assert "&amp;" not in text  # a plain & is shown as it is


def test_runs_table_shows_ranking_metrics_averaged_over_levels():
    records = [offline_record("GRAIL/MiniGrid-Optimal-v0", "bc", lv, 0.5, scorer="mse", top2_mean=t, mean_rank_mean=m)
               for lv, t, m in ((0.1, 0.8, 1.6), (0.3, 1.0, 1.2))]
    records.append(offline_record("GRAIL/MiniGrid-Optimal-v0", "graql", 0.1, 0.5, scorer="kl"))  # stored before:
    # no ranking
    boards = build_boards(records, ceiling_samples=None)
    text = markdown(boards, records)
    assert "| GRAIL/MiniGrid-Optimal-v0 | BC-GRAIL | 2 | 1.00 | 10 | 0.0% | 0.90 | 1.40 | – |" in text
    assert "| GRAIL/MiniGrid-Optimal-v0 | GRAQL | 2 | 1.00 | 10 | 0.0% | – | – | – |" in text


def test_profiles_gaps_and_calibration_are_written_from_the_ceilings(tmp_path):
    from grail_bench.report.reproduce import write_robust
    from grail_bench.report.summary import TAUS, domain_summaries
    from grail_bench.stats.metrics import reliability_bins

    task = "GRAIL/MiniGrid-Optimal-v0"
    good = [offline_record(task, "bc", lv, (0.9, 1.0), scorer="mse") for lv in (0.1, 0.2, 0.3)]
    weak = [offline_record(task, "graql", lv, (0.5, 0.7), scorer="kl") for lv in (0.1, 0.2, 0.3)]
    posterior = [offline_record(task, "bc", 0.1, 0.9, scorer="loglik",
                                reliability=reliability_bins([0.9, 0.9], [True, False]))]
    board = leaderboard.build([], None, 50, records=good + weak + posterior)
    (summary,) = domain_summaries(board.boards, reps=200)
    assert summary.profile_strata == 3 and set(summary.gaps) == {"BC-GRAIL", "GRAQL"}  # canonical only
    assert summary.gaps["BC-GRAIL"].point < summary.gaps["GRAQL"].point  # nearer the ceiling
    point, low, high = summary.profiles["GRAQL"]  # F1 0.5 is chance: normalised 0, not above 0
    assert len(point) == len(TAUS) and point[0] == 0.5 and all(lo <= p <= hi for p, lo, hi in zip(point, low, high))
    written = {p.name for p in write_robust(board, tmp_path, reps=200)}
    assert {"PROFILES.md", "performance_profiles.png", "CALIBRATION.md", "reliability.png"} <= written
    text = (tmp_path / "CALIBRATION.md").read_text()
    assert "loglik" in text and "| 0.40 |" in text  # ECE: |0.5 - 0.9|
    assert "## minigrid (3 strata)" in (tmp_path / "PROFILES.md").read_text()


def test_rows_of_a_task_not_loaded_here_are_named_by_their_settings_never_archived_for_that():
    """A user's own task whose card (or problem set) this process has not loaded cannot be planned again: its rows
    are canonical or a named variant as their settings say, archived only where the settings themselves are no
    longer today's (a setting refused, or one added since); a shipped task no longer known stays archived."""
    from grail_bench.report.configs import configuration, not_loaded

    def on(task, record):
        return dataclasses.replace(record, task=task)

    default = offline_record("GRAIL/MiniGrid-Optimal-v0", "gail", 0.1, 0.5, scorer="mse")
    longer = offline_record("GRAIL/MiniGrid-Optimal-v0", "gail", 0.1, 0.9, scorer="mse",
                            settings={"total_timesteps": 160000})
    older = offline_record("GRAIL/MiniGrid-Optimal-v0", "gail", 0.1, 0.5, scorer="mse", drop="total_timesteps")
    refused = dataclasses.replace(default, recognizer_config={**default.recognizer_config, "no_such_setting": 1})
    for task in ("MyLab/Gone-v0", "symbolic:my-problems"):
        assert not_loaded(task)
        assert configuration(on(task, default)).label == "GAIL-GRAIL"
        assert configuration(on(task, default)).canonical
        assert configuration(on(task, longer)).label == "GAIL-GRAIL · total_timesteps 160 000"
        assert configuration(on(task, older)).kind == "archived"  # a setting added since: not today's settings
        assert configuration(on(task, refused)).kind == "archived"
    assert not not_loaded("GRAIL/Gone-v0") and configuration(on("GRAIL/Gone-v0", default)).kind == "archived"
    assert not not_loaded("GRAIL/MiniGrid-Optimal-v0")
    board = built([on("MyLab/Gone-v0", default), on("MyLab/Gone-v0", longer)])
    assert not board.archive and [b.columns for b in board.boards] == [["GAIL-GRAIL"]]
