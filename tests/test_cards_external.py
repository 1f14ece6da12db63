"""Task cards from outside the package: --cards, GRAIL_BENCH_CARDS and the grail_bench.cards entry point."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli.app import app
from grail_bench.core.errors import UserError
from grail_bench.task import cards, external
from grail_bench.task.cards import CardError, card_tasks, parse_card, skipped_cards
from grail_bench.task.external import add_tasks, load_cards, register_card
from grail_bench.task.registration import make_task, shipped_tasks
from grail_bench.task.versions import fingerprint

ROOT = Path(grail_bench.__file__).resolve().parents[1]
TASK = "MyLab/Grid-Optimal-v0"
CARD = """\
domain = "minigrid"

[[task]]
id = "MyLab/Grid-Optimal-v0"
regime = "optimal"
goals = [[7, 1], [7, 7], [7, 3]]
description = "Three goals on the east wall."
"""
BROKEN = 'domain = "minigrid"\n[[task]]\nid = "MyLab/Broken-v0"\nregime = "optimal"\ngoals = [[7, 1]]\n'


@pytest.fixture(autouse=True)
def clean_registry():
    """Every test starts and ends with no card from outside the package registered."""
    before = set(gym.registry)
    yield
    for task_id in list(external.registered()):
        external._drop(task_id)
    external._given.clear()
    external._ambient.cache_clear()
    cards._skipped_external.clear()
    for env_id in set(gym.registry) - before:
        del gym.registry[env_id]


def card_folder(root: Path, broken: bool = False) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "grid.toml").write_text(CARD, encoding="utf-8")
    if broken:
        (root / "broken.toml").write_text(BROKEN, encoding="utf-8")
    return root


def python(code: str, **env: str) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter that imports this checkout, with ``env`` added to the environment."""
    path = os.pathsep.join([*filter(None, [env.pop("PYTHONPATH", "")]), str(ROOT)])
    full = {**os.environ, "PYTHONPATH": path, **env}
    full.pop("GRAIL_BENCH_CARDS", None) if "GRAIL_BENCH_CARDS" not in env else None
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=full)


def install_cards(root: Path, value: str) -> Path:
    """A minimal installed distribution under ``root`` whose package ``mylab_cards`` ships the card, declared
    as the entry point ``mylab = value``; returns the folder to put on the import path."""
    package = root / "mylab_cards"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "grid.toml").write_text(CARD, encoding="utf-8")
    dist = root / "mylab_cards-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: mylab-cards\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[grail_bench.cards]\nmylab = {value}\n")
    return root


def test_cards_flag_registers_a_folder_of_another_namespace(tmp_path):
    folder = card_folder(tmp_path / "cards")
    result = CliRunner().invoke(app, ["tasks", "--cards", str(folder), "-t", "MyLab/*"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert TASK in result.output and "(7,3)" in result.output
    env = gym.make(TASK)  # registered with gymnasium like the shipped tasks
    assert env.unwrapped.task.goals == ((7, 1), (7, 7), (7, 3))
    env.close()


def test_load_cards_is_the_python_api_and_gym_make_finds_the_task(tmp_path):
    (task,) = grail_bench.load_cards(card_folder(tmp_path) / "grid.toml")
    assert task.id == TASK and TASK in grail_bench.task_ids()
    assert make_task(TASK, n_demos=12).n_demos == 12
    assert gym.make(TASK).unwrapped.task.id == TASK
    assert load_cards(tmp_path / "grid.toml") == [task]  # loading it again changes nothing


def test_the_environment_variable_registers_cards_on_import(tmp_path):
    folder = card_folder(tmp_path / "cards")
    other = tmp_path / "other.toml"
    other.write_text(CARD.replace("Grid-Optimal", "Other-Optimal"), encoding="utf-8")
    out = python("import gymnasium as gym, grail_bench\n"
                 f"print(gym.make({TASK!r}).unwrapped.task.goals, 'MyLab/Other-Optimal-v0' in grail_bench.task_ids())",
                 GRAIL_BENCH_CARDS=os.pathsep.join([str(folder), str(other)]))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "((7, 1), (7, 7), (7, 3)) True" and out.stderr == ""


@pytest.mark.parametrize("value", ["mylab_cards", "mylab_cards:grid.toml"])
def test_an_installed_package_ships_cards_through_the_entry_point(tmp_path, value):
    site = install_cards(tmp_path / "site", value)
    out = python(f"import gymnasium as gym, grail_bench\nprint(gym.make({TASK!r}).unwrapped.task.goals)",
                 PYTHONPATH=str(site))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "((7, 1), (7, 7), (7, 3))" and out.stderr == ""


def test_an_entry_point_naming_nothing_is_one_line(tmp_path):
    site = install_cards(tmp_path / "site", "mylab_cards:absent.toml")
    out = python("import grail_bench; print(len(grail_bench.task_ids()) > 50)", PYTHONPATH=str(site))
    assert out.returncode == 0 and out.stdout.strip() == "True", out.stderr
    assert out.stderr.count("\n") == 1 and "entry point mylab = mylab_cards:absent.toml" in out.stderr


def test_a_malformed_card_from_outside_is_one_line_and_breaks_nothing(tmp_path):
    folder = card_folder(tmp_path / "cards", broken=True)
    quiet = python("import gymnasium", GRAIL_BENCH_CARDS=str(folder))
    assert quiet.returncode == 0 and quiet.stdout == "" and quiet.stderr == ""
    out = python(f"import gymnasium as gym, grail_bench\nprint(gym.make({TASK!r}).unwrapped.task.id)",
                 GRAIL_BENCH_CARDS=str(folder))
    assert out.returncode == 0 and out.stdout.strip() == TASK, out.stderr
    (line,) = out.stderr.splitlines()
    assert str(folder / "broken.toml") in line and "task[0].goals" in line
    # the same through --cards: the good card's task runs, the broken card is one line, the command succeeds
    result = CliRunner().invoke(app, ["tasks", "--cards", str(folder)], env={"COLUMNS": "200"})
    assert result.exit_code == 0 and TASK in result.output and "GRAIL/MiniGrid-Biased-v0" in result.output
    assert f"skipped the broken task card {folder / 'broken.toml'}: task[0].goals" in result.output
    with pytest.raises(UserError, match=r"unknown task 'MyLab/Broken-v0'.*broken\.toml"):
        make_task("MyLab/Broken-v0")
    with pytest.raises(CardError, match=r"broken\.toml: task\[0\]\.goals: expected a list of at least two goals"):
        load_cards(folder, strict=True)


def test_a_mistyped_cards_path_is_an_error(tmp_path):
    result = CliRunner().invoke(app, ["tasks", "--cards", str(tmp_path / "nope")])
    assert result.exit_code == 2
    assert f"{tmp_path / 'nope'}: no such task card or folder of cards" in result.output


@pytest.mark.parametrize(("task_id", "why"), [
    ("GRAIL/MiniGrid-Biased-v0", "the GRAIL/ namespace is grail-bench's own"),
    ("GRAIL/Mine-v0", "the GRAIL/ namespace is grail-bench's own"),
    ("phys2d/CartPole-v1", "is already a gymnasium env"),
])
def test_no_card_shadows_a_shipped_task_or_another_env(tmp_path, task_id, why):
    card = tmp_path / "clash.toml"
    card.write_text(CARD.replace(TASK, task_id), encoding="utf-8")
    assert load_cards(card) == []
    assert why in skipped_cards()[str(card)]
    with pytest.raises(CardError, match=why):
        load_cards(card, strict=True)
    assert make_task("GRAIL/MiniGrid-Biased-v0").goals == shipped_tasks()["GRAIL/MiniGrid-Biased-v0"].goals


def test_one_id_in_two_cards_keeps_the_first(tmp_path):
    first, second = card_folder(tmp_path / "a") / "grid.toml", card_folder(tmp_path / "b") / "grid.toml"
    load_cards(first)
    assert load_cards(second) == []
    assert skipped_cards()[str(second)] == f"task id {TASK!r} is already defined by {first}"
    assert make_task(TASK).source == str(first)


def test_an_edited_card_loaded_again_replaces_its_tasks(tmp_path):
    card = card_folder(tmp_path) / "grid.toml"
    load_cards(card)
    card.write_text(CARD.replace("[7, 3]]", "[7, 5]]"), encoding="utf-8")
    load_cards(card)
    assert make_task(TASK).goals[-1] == (7, 5)


def test_bounds_apply_to_cards_from_outside(tmp_path):
    card = tmp_path / "big.toml"
    card.write_text(CARD + "n_demos = 100000\n", encoding="utf-8")
    with pytest.raises(CardError, match=r"big\.toml: task\[0\]\.n_demos: 100000 is out of range"):
        load_cards(card, strict=True)
    many = ", ".join(f"[{i}, 1]" for i in range(1001))
    card.write_text(CARD.replace("[[7, 1], [7, 7], [7, 3]]", f"[{many}]"), encoding="utf-8")
    with pytest.raises(CardError, match=r"task\[0\]\.goals: 1001 goals is out of range"):
        load_cards(card, strict=True)
    card.write_text(CARD + "env = { max_steps = 100000000 }\n", encoding="utf-8")
    with pytest.raises(CardError, match=r"task\[0\]\.env\.max_steps: .*out of range"):
        load_cards(card, strict=True)


def _own_goal_set(domain: str) -> tuple[dict, list]:
    """A card of ``domain`` with a goal set of its own: a shipped optimal task's goals, one fewer and reordered."""
    base = next(t for t in shipped_tasks().values() if t.domain == domain and t.regime == "optimal")
    goals = [list(g) for g in reversed(base.goals[: max(2, len(base.goals) - 1)])]
    card = {"domain": domain, "task": [{"id": f"MyLab/{domain.replace('_', '')}-Own-v0", "regime": "optimal", "goals": goals,
                                        "env": dict(base.env_params)}]}
    return card, goals


@pytest.mark.parametrize("domain", sorted({t.domain for t in shipped_tasks().values()}))
def test_a_card_sets_its_own_goal_set_in_every_domain(domain):
    card, goals = _own_goal_set(domain)
    (task,) = register_card(card, f"{domain}.toml")  # what a loader of a dataset of problems can call
    assert [list(g) for g in make_task(task.id).goals] == goals
    assert len(fingerprint(task)) == 12  # not in tasks/versions.toml: fingerprinted all the same


def test_tasks_built_by_code_register_and_clash_like_cards(tmp_path):
    (task,) = card_tasks({"domain": "minigrid", "task": [{"id": TASK, "regime": "optimal", "goals": [[7, 1], [7, 7]]}]},
                         "built")
    assert add_tasks([task], "my loader") == [task] and make_task(TASK).goals == ((7, 1), (7, 7))
    with pytest.raises(CardError, match=rf"other loader: task id '{TASK}' is already defined by my loader"):
        add_tasks([task], "other loader")


SYMBOLIC = """\
domain = "symbolic"

[[task]]
id = "MyLab/Blocks-Two-v0"
regime = "optimal"
goals = [[3], [1]]
env = { problem = "blocks.tar.bz2" }
"""


def test_a_symbolic_card_reads_its_problem_from_beside_it(tmp_path, monkeypatch):
    from grail_bench.domains.symbolic.dataset import write_problem
    from grail_bench.domains.symbolic.generator import builtin_problem

    for folder in ("a", "b"):
        write_problem(builtin_problem("blocks"), tmp_path / folder / "blocks.tar.bz2")
        (tmp_path / folder / "card.toml").write_text(SYMBOLIC, encoding="utf-8")
    monkeypatch.chdir(tmp_path)  # not the card's folder
    (task,) = load_cards(tmp_path / "a" / "card.toml", strict=True)
    assert task.env_params["problem"] == str(tmp_path / "a" / "blocks.tar.bz2") and task.goals == ((3,), (1,))
    assert gym.make("MyLab/Blocks-Two-v0").unwrapped.goal_index == 3
    (moved,) = parse_card(SYMBOLIC, "card.toml", tmp_path / "b")
    assert fingerprint(moved) == fingerprint(task)  # the same card in another folder is the same task


def test_goals_are_no_parameter_but_a_card(tmp_path):
    with pytest.raises(UserError, match=r"cannot take goals as a parameter: a goal set defines a task.*--cards"):
        make_task("GRAIL/MiniGrid-Optimal-v0", goals=[[7, 1], [7, 3]])


@pytest.mark.parametrize("command", [["ceiling", "-o", "0.3", "--samples", "200"], ["inspect", "-r", "demonstrator"]])
def test_commands_that_take_a_task_take_cards(tmp_path, command):
    folder = card_folder(tmp_path / "cards")
    result = CliRunner().invoke(app, [command[0], "--cards", str(folder), "-t", TASK, *command[1:]],
                                env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert TASK in result.output


def test_local_workers_know_the_cards_given_to_the_driver(tmp_path):
    from grail_bench.harness.executors import LocalExecutor

    load_cards(card_folder(tmp_path))
    executor = LocalExecutor(2)
    try:
        found = dict(executor.map_unordered(make_task, [TASK, TASK]))
    finally:
        executor.close()
    assert found[TASK].goals == ((7, 1), (7, 7), (7, 3))


def test_ray_workers_get_the_cards_in_their_environment(tmp_path, monkeypatch):
    from grail_bench.harness.executors import _cards_env

    monkeypatch.setenv("GRAIL_BENCH_CARDS", str(tmp_path / "elsewhere"))
    load_cards(card_folder(tmp_path / "cards"))
    assert _cards_env() == {"GRAIL_BENCH_CARDS": os.pathsep.join([str(tmp_path / "elsewhere"),
                                                                  str(tmp_path / "cards")])}


def test_a_missing_path_in_the_environment_variable_is_one_line(tmp_path):
    out = python("import grail_bench; print(len(grail_bench.task_ids()) > 50)",
                 GRAIL_BENCH_CARDS=str(tmp_path / "nope"))
    assert out.returncode == 0 and out.stdout.strip() == "True", out.stderr
    assert out.stderr == f"grail-bench: skipped the task card {tmp_path / 'nope'}: no such task card or folder of " \
                         "cards\n"


@pytest.mark.slow
def test_a_run_on_an_own_goal_set_is_labelled_with_its_own_id(tmp_path):
    folder = card_folder(tmp_path / "cards")
    store, records = tmp_path / "r.sqlite", tmp_path / "r.json"
    out = subprocess.run([sys.executable, "-m", "grail_bench", "run", "--cards", str(folder), "-t", TASK, "-r",
                          "demonstrator", "--seeds", "1", "-o", "0.5", "--no-progress", "--store", str(store),
                          "--json", str(records)],
                         capture_output=True, text=True, timeout=600,
                         env={**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "200"})
    assert out.returncode == 0, out.stderr
    rows = json.loads(records.read_text())
    assert {r["task"] for r in rows} == {TASK} and all(0 <= r["f1_mean"] <= 1 for r in rows)
    board = CliRunner().invoke(app, ["leaderboard", "--store", str(store), "--markdown", str(tmp_path / "b.md")],
                               env={"COLUMNS": "200"})
    assert board.exit_code == 0 and board.output.count("not loaded here") == 1  # said once, not silent
    assert f"the cards of {TASK} (give --cards PATH or GRAIL_BENCH_CARDS)" in board.output
    text = (tmp_path / "b.md").read_text()  # named by the recognizer's settings: canonical, never archived
    assert "| Demonstrator (perfect imitation) (reference) |" in text and "archived" not in text
    from grail_bench.harness.store import ResultsStore

    load_cards(folder)
    with ResultsStore(store) as opened:
        assert {(r.task, r.task_fingerprint) for r in opened.rows()} == {(TASK, fingerprint(make_task(TASK)))}
