"""A symbolic problem set in the dataset's layout runs as a task of its own, with all of its hypotheses and a name
of its own, and the ``dataset`` protocol scores each problem's own obs.dat against its real_hyp.dat."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_cli_inputs import invoke, refused
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.dataset import file_texts, write_problem
from grail_bench.domains.symbolic.generator import GRID_DOMAIN, builtin_problem, observed, write_dataset
from grail_bench.domains.symbolic.problem import PLACEHOLDER, GRProblem
from grail_bench.domains.symbolic.problem_set import dataset_observations, problem_set_tasks
from grail_bench.harness.modes import ResultRow
from grail_bench.harness.store import ResultsStore
from grail_bench.recognizers import make_recognizer
from grail_bench.stats import metrics

ARMS = 5


def star() -> GRProblem:
    """A robot in the middle of five corridors two cells long; the candidate goals are the corridors' ends, so
    a goal's optimal plan (the only one) passes no other goal's cell: a whole plan says which goal it is."""
    cells = ["c"] + [f"a{i}{j}" for i in range(ARMS) for j in (1, 2)]
    links = [("c", f"a{i}1") for i in range(ARMS)] + [(f"a{i}1", f"a{i}2") for i in range(ARMS)]
    init = [("robot-at", "c")] + [("adjacent", a, b) for x, y in links for a, b in ((x, y), (y, x))]
    facts = "\n    ".join(f"({' '.join(atom)})" for atom in init)
    template = (f"(define (problem star)\n  (:domain grid-navigation)\n  (:objects {' '.join(cells)} - cell)\n"
                f"  (:init\n    {facts})\n  (:goal (and\n    {PLACEHOLDER}\n  )))\n")
    hyps = tuple(((("robot-at", f"a{i}2"),)) for i in range(ARMS))
    return GRProblem("star", GRID_DOMAIN, template, hyps, hyps[0], ())


def write_set(folder: Path, problem: GRProblem, level: int, seed: int = 0, name: str = "star") -> Path:
    """One problem per hypothesis, its obs.dat ``level`` percent of an optimal plan (the generator's draw)."""
    rng = np.random.default_rng(seed)
    for goal in range(len(problem.hypotheses)):
        write_problem(observed(problem, goal, level, rng), folder / f"{name}_hyp-{goal}_{level}.tar.bz2")
    return folder


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> Path:
    return write_set(tmp_path_factory.mktemp("sets") / "star", star(), 100)


def test_a_problem_set_with_five_hypotheses_is_a_task_with_five_goals_and_its_own_name(whole):
    (task,) = problem_set_tasks(whole)
    assert task.id == "symbolic:star" and task.goals == tuple((i,) for i in range(ARMS))
    assert task.protocol == "dataset" and task.observability == (1.0,) and len(task.problems) == ARMS
    (one,) = problem_set_tasks(whole / "star_hyp-3_100.tar.bz2")  # one archive is a set of one problem
    assert one.id == "symbolic:star_hyp-3_100" and len(one.goals) == ARMS
    labels = [label for label, _ in dataset_observations(task)]
    assert labels == list(range(ARMS))  # each problem's real_hyp.dat, in the order of the archives


def test_whole_optimal_plans_are_recognised_and_stored_under_the_sets_name(whole, tmp_path):
    store = tmp_path / "r.sqlite"
    result = CliRunner().invoke(app, ["run", "--task", str(whole), "-r", "landmarks", "-r", "prp", "--seeds", "1",
                                      "--no-progress", "--json", str(tmp_path / "r.json")],
                                env={"COLUMNS": "200", "GRAIL_BENCH_STORE": str(store)})
    output = result.output
    assert result.exit_code == 0, output
    records = json.loads((tmp_path / "r.json").read_text())
    assert {r["recognizer"] for r in records} == {"landmarks", "prp"}
    for r in records:
        assert r["task"] == "symbolic:star" and r["protocol"] == "dataset+actions" and r["observability"] == 1.0
        assert r["accuracy_mean"] == 1.0 and r["confusion"] == np.eye(ARMS, dtype=int).tolist()
    with ResultsStore(store, read_only=True) as rows:
        assert {(r.task, r.n_observations) for r in rows.select(ResultRow)} == {("symbolic:star", ARMS)}
    assert "symbolic:star" in output and "Landmarks" in output  # the run's board shows it (not archived)


def test_the_dataset_protocol_scores_each_obs_dat_as_the_recognizer_does_directly(tmp_path):
    """At 30 % observed, ties and misses occur: the stored accuracy is the recognizer's own answers on each
    problem's obs.dat (expected accuracy, ties shared uniformly), computed here without the harness."""
    folder = write_set(tmp_path / "grid", builtin_problem("grid"), 30, seed=3, name="grid")
    write_set(folder, builtin_problem("grid"), 10, seed=4, name="grid")
    (task,) = problem_set_tasks(folder)
    records = grail_bench.evaluate(task, "landmarks", seeds=1)
    (record,) = records
    rec = make_recognizer("landmarks")
    rec.fit({g: [] for g in task.goals}, task.env_factory())
    hits = []
    for label, observation in dataset_observations(task):
        scores = np.array([rec.score(observation)[g] for g in task.goals])
        hits.append(metrics.prediction(scores)[label])
    assert len(hits) == 6 and record.accuracy_mean == pytest.approx(np.mean(hits))
    assert 0.0 < record.accuracy_mean < 1.0  # the case is not trivial


def test_problems_that_differ_in_their_files_are_tasks_of_their_own(tmp_path):
    folder = write_set(tmp_path / "mixed", builtin_problem("grid"), 100, name="grid")
    write_set(folder, builtin_problem("blocks"), 100, name="blocks")
    tasks = problem_set_tasks(folder)
    assert [(t.id, len(t.goals), len(t.problems)) for t in tasks] == [
        ("symbolic:mixed/blocks", 4, 4), ("symbolic:mixed/grid", 3, 3)]


def test_an_edited_problem_set_runs_again(tmp_path):
    folder = write_set(tmp_path / "star", star(), 100)
    store = ResultsStore(tmp_path / "r.sqlite")
    (task,) = problem_set_tasks(folder)
    first = grail_bench.evaluate(task, "landmarks", seeds=1, store=store)
    write_problem(replace(star(), observations=(("move", "c", "a01"),)), folder / "star_hyp-0_100.tar.bz2")
    (task,) = problem_set_tasks(folder)
    second = grail_bench.evaluate(task, "landmarks", seeds=1, store=store)
    assert first[0].config_hash != second[0].config_hash and len(store.select(ResultRow)) == 2


@pytest.mark.parametrize("make, message", [
    (lambda p: p / "nowhere", "problem set {p}/nowhere does not exist"),
    (lambda p: (p / "empty").mkdir() or p / "empty", "problem set {p}/empty holds no problem"),
    (lambda p: (p / "half").mkdir() or (p / "half" / "domain.pddl").write_text(GRID_DOMAIN) and p / "half",
     "lacks template.pddl, hyps.dat, obs.dat, real_hyp.dat"),
    (lambda p: _with(p, "real_hyp.dat", "(robot-at c)\n"), "real_hyp.dat (robot-at c) is not among hyps.dat"),
    (lambda p: _with(p, "hyps.dat", "(robot-at a02)\n"), "hyps.dat lists 1 hypothesis"),
], ids=["missing", "empty", "lacking-files", "true-goal-unknown", "one-hypothesis"])
def test_a_malformed_problem_set_is_one_line(tmp_path, make, message):
    path = make(tmp_path)
    expected = message.format(p=tmp_path)
    with pytest.raises(UserError, match=None) as err:
        problem_set_tasks(path)
    assert expected in str(err.value) and "\n" not in str(err.value)
    refused(["run", "--task", str(path), "-r", "landmarks", "--no-progress"], tmp_path / "r.sqlite", expected)


def _with(folder: Path, name: str, text: str) -> Path:
    texts = file_texts(replace(star(), observations=(("move", "c", "a01"),)))
    texts[name] = text
    (folder / "p").mkdir()
    for member, body in texts.items():
        (folder / "p" / member).write_text(body)
    return folder / "p"


def test_an_observed_action_the_problem_lacks_is_one_line_naming_the_file(tmp_path):
    path = _with(tmp_path, "obs.dat", "(move c a99)\n")
    refused(["run", "--task", str(path), "-r", "landmarks", "--no-progress"], tmp_path / "r.sqlite",
            f"{path}: obs.dat: (move c a99) is no reachable ground operator")


@pytest.mark.parametrize("args, message", [
    (["run", "-t", "GRAIL/Symbolic-Grid-Optimal-v0", "--param", "problem={set}"],
     "keeps its card's problem ('grid'), not '{set}': run a problem set as a task of its own"),
    (["run", "-t", "GRAIL/Symbolic-Grid-Optimal-v0", "-r", "landmarks", "--protocol", "dataset"],
     "GRAIL/Symbolic-Grid-Optimal-v0 is no problem set: run one as its own task (grail-bench run --task PATH)"),
    (["run", "-t", "{set}", "-r", "landmarks", "--observability", "0.5"], "at level 1; drop --observability"),
    (["run", "-t", "{set}", "-r", "landmarks", "--online"], "scores each observation once, offline; drop --mode online"),
    (["run", "-t", "{set}", "-r", "landmarks", "--channel", "states"], "drop --channel states"),
    (["run", "-t", "{set}", "-r", "bc"], "bc cannot use the actions channel"),
], ids=["param-problem", "card-dataset", "levels", "online", "states", "bc"])
def test_what_a_problem_set_cannot_be_given_is_refused_in_one_line(whole, tmp_path, args, message):
    args = [a.format(set=whole) for a in args]
    refused([*args, "--no-progress"], tmp_path / "r.sqlite", message.format(set=whole))
    with pytest.raises(UserError, match="run a problem set as a task of its own"):
        grail_bench.make_task("GRAIL/Symbolic-Grid-Optimal-v0", problem=str(whole))


def test_the_generators_dataset_layout_runs_level_by_level(tmp_path):
    write_dataset(tmp_path, names=["grid"], levels=[100], seed=0)
    (task,) = problem_set_tasks(tmp_path / "grid" / "100")
    assert task.id == "symbolic:grid/100" and len(task.goals) == 3


def leaderboard(store: Path, *args: str) -> subprocess.CompletedProcess:
    """``grail-bench leaderboard`` in a new process (one that has read no problem set)."""
    root = Path(grail_bench.__file__).resolve().parents[1]
    return subprocess.run([sys.executable, "-m", "grail_bench", "leaderboard", "--store", str(store), *args],
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(root), "COLUMNS": "200"})


def test_a_problem_sets_rows_read_elsewhere_are_named_by_their_settings_and_checked_given_its_path(whole, tmp_path):
    folder = shutil.copytree(whole, tmp_path / "star")
    store = ResultsStore(tmp_path / "r.sqlite")
    (task,) = problem_set_tasks(folder)
    for settings in ({}, {"heuristic": "uniqueness"}):
        grail_bench.evaluate(task, ("landmarks", settings), seeds=1, store=store)
    store.close()
    named = "1 named variants and 0 archived configurations"
    unread = leaderboard(store.path)  # without the set: its task cannot be planned again, its rows are not archived
    assert unread.returncode == 0, unread.stderr
    assert unread.stdout.count("not loaded here") == 1 and named in unread.stdout
    assert "the problem set symbolic:star (give --task PATH to check it)" in unread.stdout
    assert re.search(r"strata: symbolic\s*$", unread.stdout, re.M)  # its domain, as when the set is read
    given = leaderboard(store.path, "--task", str(folder))  # with it: checked as a run plans it
    assert given.returncode == 0, given.stderr
    assert "not loaded here" not in given.stdout and named in given.stdout and "symbolic:star" in given.stdout
    write_problem(replace(star(), observations=(("move", "c", "a01"),)), folder / "star_hyp-0_100.tar.bz2")
    edited = leaderboard(store.path, "--task", str(folder))  # another set under its name: run by an earlier one
    assert edited.returncode == 0 and "0 named variants and 2 archived configurations" in edited.stdout


# --- the other commands taking --task ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mixed(tmp_path_factory) -> Path:
    """A folder of two tasks: problems of the grid and of blocks."""
    folder = write_set(tmp_path_factory.mktemp("sets") / "mixed", builtin_problem("grid"), 100, name="grid")
    return write_set(folder, builtin_problem("blocks"), 100, name="blocks")


def test_tasks_and_list_show_a_problem_sets_tasks_given_its_path(whole, mixed, tmp_path):
    code, output = invoke(["tasks", "--task", str(whole)], tmp_path / "r.sqlite")
    assert code == 0 and "symbolic:star" in output and "GRAIL/" not in output, output  # its tasks only
    code, output = invoke(["list", "tasks", "-t", str(mixed), "-t", "GRAIL/Symbolic-Grid-Optimal-v0", "-d", "symbolic"],
                          tmp_path / "r.sqlite")
    assert code == 0, output
    assert {"symbolic:mixed/blocks", "symbolic:mixed/grid", "GRAIL/Symbolic-Grid-Optimal-v0"} <= set(output.split())
    assert "GRAIL/Symbolic-Blocks-Optimal-v0" not in output


def test_inspect_and_ceiling_take_a_problem_sets_path(whole, tmp_path):
    code, output = invoke(["inspect", "--task", str(whole), "-r", "landmarks"], tmp_path / "r.sqlite")
    assert code == 0 and "dataset+actions: 100% F1 1.00" in output, output  # each problem's own obs.dat
    code, output = invoke(["ceiling", "--task", str(whole), "-p", "subset", "-o", "0.5", "--json",
                           str(tmp_path / "c.json")], tmp_path / "r.sqlite")
    assert code == 0 and "symbolic:star" in output, output
    (ceiling,) = json.loads((tmp_path / "c.json").read_text())
    assert ceiling["task"] == "symbolic:star" and ceiling["chance"] == pytest.approx(1 / ARMS)
    assert ceiling["accuracy"] == 1.0  # half of a corridor's only plan names its end


@pytest.mark.parametrize("args, message", [
    (["export", "-t", "{set}", "--out", "{tmp}/out"], "the problem set {set} has no such ID"),
    (["study", "off-route", "-t", "{set}"], "study off-route takes task IDs, not a problem set's path ({set})"),
    (["ceiling", "-t", "{set}"], "the dataset protocol of symbolic:star (each problem's own obs.dat) has no Bayes "
                                 "ceiling; give --protocol subset or prefix"),
    (["inspect", "-t", "{mixed}", "-r", "landmarks"],
     "the problem set {mixed} holds 2 tasks (symbolic:mixed/blocks, symbolic:mixed/grid); inspect takes one"),
    (["ceiling", "-t", "{tmp}/nowhere"], "problem set {tmp}/nowhere does not exist"),
    (["tasks", "-t", "{tmp}/nowhere.tar.bz2"], "problem set {tmp}/nowhere.tar.bz2 does not exist"),
], ids=["export", "study", "ceiling-dataset", "inspect-several", "ceiling-missing", "tasks-missing"])
def test_a_problem_sets_path_where_a_command_cannot_take_it_is_one_line(whole, mixed, tmp_path, args, message):
    names = {"set": whole, "mixed": mixed, "tmp": tmp_path}
    refused([a.format(**names) for a in args], tmp_path / "r.sqlite", message.format(**names))
    assert not (tmp_path / "out").exists() and not (tmp_path / "r.sqlite").exists()


def test_a_problem_sets_env_is_the_tasks_own(whole):
    """A set's task is no gymnasium ID; its env is made from the task."""
    (task,) = problem_set_tasks(whole)
    env = task.make_env(task.goals[2])
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and env.unwrapped.task is task
    env.close()
