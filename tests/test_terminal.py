"""What a researcher sees in an 80-column terminal: whole names, whole defaults, legends; and the typed rows."""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import pytest
import typer.main
from conftest import offline_record
from rich.console import Console
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.harness.modes import MODES
from grail_bench.report.rows import BudgetCurve, BudgetPoint
from grail_bench.report.rows import TimingRow, timing_rows
from grail_bench.report.tables import budgets_markdown, diagnostics_table, mode_table, tasks_table, timing_table
from grail_bench.task import make_task

NARROW = {"COLUMNS": "80"}


def invoke(*args: str):
    result = CliRunner().invoke(app, list(args), env=NARROW)
    assert result.exit_code == 0, result.output
    return result.output


def assert_fits(output: str, width: int = 80) -> None:
    assert "…" not in output
    assert max(len(line) for line in output.splitlines()) <= width


def test_tasks_at_80_columns_name_every_task_whole():
    output = invoke("tasks")
    assert_fits(output)
    assert "GRAIL/ tasks" in output
    for task_id in grail_bench.task_ids():
        assert task_id in output  # the full ID, as --task takes it


def test_list_at_80_columns_names_every_recognizer_scorer_and_task_whole():
    from grail_bench.recognizers.registry import available_recognizers
    from grail_bench.recognizers.scoring import available_scorers

    output = invoke("list")
    assert_fits(output)
    names = {line.split("│")[1].strip() for line in output.splitlines() if line.startswith("│")}
    assert set(available_recognizers()) <= names and set(available_scorers()) <= names
    for task_id in grail_bench.task_ids():
        assert task_id in names


def test_the_wide_layout_is_kept_where_it_fits():
    tasks = [make_task(t) for t in grail_bench.task_ids()]
    output = render(tasks_table(tasks), 220)
    assert "demos/goal (train/test)" in output.splitlines()[2]  # one column per field: the plain layout


def render(renderable, width: int) -> str:
    console = Console(width=width, record=True, color_system=None)
    with console.capture() as capture:
        console.print(renderable)
    return capture.get()


@pytest.mark.parametrize("command", ["run", "reproduce", "leaderboard"])
def test_help_at_80_columns_shows_every_default_whole(command):
    output = invoke(command, "--help")
    assert_fits(output)
    click_command = typer.main.get_command(app).commands[command]
    defaults = [str(p.default) for p in click_command.params
                if getattr(p, "show_default", False) and p.default not in (None, False, ()) and not p.is_flag]
    assert defaults  # run: the seeds (its default task is in the help text: -t is repeatable)
    lines = [line.strip("│ ") for line in output.splitlines()]
    for default in defaults:
        assert any(default in line for line in lines), default


def test_mode_table_at_80_columns_stacks_values_and_explains_the_brackets():
    record = SimpleNamespace(task="GRAIL/PandaReach-Gaussian-0.1-12Goals-v0", protocol="subset", observability=0.02,
                             recognizer="demonstrator", scorer="loglik", n_seeds=3, auroc_mean=0.7,
                             auroc_ci95_low=0.6, auroc_ci95_high=0.8, f1_mean=0.5, f1_ci95_low=0.4, f1_ci95_high=0.6,
                             accuracy_mean=0.5, unknown_recall_mean=0.2, false_alarm_mean=0.1)
    output = render(mode_table([record], MODES["open-set"]), 80)
    assert_fits(output)
    assert "PandaReach-Gaussian-0.1-12Goals-v0" in output and "demonstrator/loglik" in output
    assert "0.50 [0.40, 0.60]" in output
    assert "percentile bootstrap" in " ".join(output.split())  # the legend under the table


def test_timing_and_diagnostics_tables_fit_80_columns():
    records = [SimpleNamespace(recognizer="demonstrator", scorer="occupancy", fit_seconds_per_goal=1.5,
                               score_us_per_observation=120.0)]
    assert "demonstrator" in render(timing_table(records), 80)
    goals = [(-0.05, -0.1, 0.25), (0.025, 0.1, 0.15), (0.1, -0.1, 0.05)]
    diagnostics = SimpleNamespace(goals=goals, imitation=[[0.9, 0.1, 0.2], [0.3, 0.8, 0.1], [0.2, 0.2, 0.7]],
                                  reached=[True, False, None], rollout_length=[12, None, 30],
                                  demo_length=[11.0, 12.5, 29.0], agreement_train=[0.9, 0.8, 0.7],
                                  agreement_held_out=[0.85, 0.75, float("nan")])
    output = render(diagnostics_table(diagnostics, "demonstrator on PandaReach, seed 0"), 80)
    assert_fits(output)
    assert "(-0.05,-0.1,0.25)" in output and "(0.025,0.1,0.15)" in output


TASK = "GRAIL/MiniGrid-Optimal-v0"


def test_a_timing_row_holds_its_configurations_label_and_means_over_levels():
    seeds = (0.4, 0.5, 0.6)
    records = [offline_record(TASK, "bc", 0.1, seeds, fit_seconds_per_goal=2.0, score_us_per_observation=100.0,
                              tie_rate=0.1, top2_mean=0.8, mean_rank_mean=1.5, set_precision_mean=0.5,
                              set_recall_mean=1.0, set_spread_mean=2.0),
               offline_record(TASK, "bc", 0.3, seeds, fit_seconds_per_goal=2.0, score_us_per_observation=300.0,
                              tie_rate=0.3, top2_mean=1.0, mean_rank_mean=1.0)]
    fits = {(TASK, "bc", records[0].config_hash): SimpleNamespace(reached=[1, 0], rolled_out=[1, 1])}
    (row,) = timing_rows(records, fits)
    assert row == TimingRow(task=TASK, column="BC-GRAIL", recognizer="bc", seeds=3, fit_seconds_per_goal=2.0,
                            score_us_per_observation=200.0, tie_rate=pytest.approx(0.2), top2=0.9, mean_rank=1.25,
                            set_precision=None, set_recall=None, set_spread=None, reached="1/2")
    with pytest.raises(dataclasses.FrozenInstanceError):
        row.seeds = 4  # type: ignore[misc]


def test_budget_curves_are_typed_and_stay_flat_json():
    curve = BudgetCurve("budget-bc", "n_epochs", TASK, "bc", "subset", 0.3,
                        (BudgetPoint(10, 2, 0.5, 0.0, 1.0, 0.2), BudgetPoint(40, 2, 0.9, 0.8, 1.0, 0.7)), plateau=40)
    data = json.loads(json.dumps(curve.to_dict()))
    assert data["plateau"] == 40 and "exponent" not in data and "scaling" not in data
    assert data["points"][1] == {"value": 40, "n_seeds": 2, "f1_mean": 0.9, "f1_ci95_low": 0.8, "f1_ci95_high": 1.0,
                                 "fit_seconds_per_goal": 0.7}
    text = budgets_markdown([curve], "quick")
    assert "| 40 (plateau) | 2 | 0.90 | [0.80, 1.00] | 0.70 |" in text
    assert "percentile bootstrap" in text


def test_a_budget_study_with_one_measured_value_names_no_plateau():
    curve = BudgetCurve("budget-gc-draco", "sac_steps", TASK, "gc-draco", "subset", 0.3,
                        (BudgetPoint(30000, 3, 0.2, 0.1, 0.3, 40.0),))
    text = budgets_markdown([curve], "breadth")
    assert "Plateau: not determined (only one value has rows)." in text
    assert "| 30000 | 3 | 0.20 | [0.10, 0.30] | 40.00 |" in text and "(plateau)" not in text


def test_the_leaderboard_says_how_its_intervals_are_made_only_where_it_shows_them():
    from grail_bench.report.tables import runs_markdown

    records = [offline_record(TASK, "bc", 0.1, (0.4, 0.5, 0.6), fit_seconds_per_goal=2.0,
                              score_us_per_observation=100.0)]
    with_intervals = " ".join(runs_markdown(records, intervals=True))
    assert "percentile bootstrap" in with_intervals and "within [0, 1]" in with_intervals
    assert "percentile bootstrap" not in " ".join(runs_markdown(records))
    assert f"| {TASK} | BC-GRAIL | 3 | 2.00 | 100 | 0.0% |" in "\n".join(runs_markdown(records))
