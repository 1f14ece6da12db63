"""The command line: main paths, plugins end to end, and one-line errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import install_plugin
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app

BIN = Path(sys.executable).parent / "grail-bench"


def cli(args, tmp_path, **env):
    full_env = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_STORE": str(tmp_path / "store.sqlite"), **env}
    return subprocess.run([str(BIN), *args], capture_output=True, text=True, env=full_env, timeout=600)


def test_tasks_lists_every_id():
    result = CliRunner().invoke(app, ["tasks"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    assert "GRAIL/ tasks" in result.output  # the title names the prefix every ID shares
    for task_id in grail_bench.task_ids():
        assert task_id in result.output  # full IDs, as --task takes them


def test_python_dash_m_runs_the_command_without_warnings():
    out = subprocess.run([sys.executable, "-m", "grail_bench", "list"], capture_output=True, text=True,
                         env={**os.environ, "COLUMNS": "200"})
    assert out.returncode == 0 and "graql" in out.stdout
    assert "Warning" not in out.stderr, out.stderr


def test_list_does_not_import_torch(tmp_path):
    code = ("import sys\nfrom grail_bench.cli import main\nsys.argv = ['grail-bench', 'list']\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\nassert 'torch' not in sys.modules\nprint('no torch')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"})
    assert out.returncode == 0, out.stderr
    assert "bc" in out.stdout and "graql" in out.stdout and "no torch" in out.stdout


def test_plugin_runs_end_to_end_and_reaches_the_leaderboard(tmp_path):
    site = install_plugin(tmp_path / "site")
    env = {"PYTHONPATH": str(site)}
    out = cli(["list", "recognizers"], tmp_path, **env)
    assert "toy" in out.stdout
    out = cli(["run", "-r", "toy", "--seeds", "2", "--no-progress", "--json", str(tmp_path / "r.json")], tmp_path, **env)
    assert out.returncode == 0, out.stderr
    records = json.loads((tmp_path / "r.json").read_text())
    assert {r["recognizer"] for r in records} == {"toy"}
    assert {r["observability"] for r in records} == {0.2, 0.3, 0.4}
    for key in ("task", "recognizer", "observability", "n_seeds", "f1_mean", "f1_std", "f1_ci95_low", "f1_ci95_high",
                "accuracy_mean", "precision_mean", "recall_mean", "fit_seconds_per_goal", "score_us_per_observation"):
        assert key in records[0]
    assert all(r["f1_mean"] == 1.0 for r in records)  # biased routes are disjoint from the first step
    md = tmp_path / "board" / "LEADERBOARD.md"
    out = cli(["leaderboard", "--markdown", str(md)], tmp_path, **env)
    assert out.returncode == 0, out.stderr
    text = md.read_text()
    # The biased routes part at the first step: both ceilings are 1 and the normalised F1 too.
    assert "| MiniGrid-Biased | 2 | 20% | 1.00 | 1.00 | **1.00 ± 0.00 [1.00]** |" in text and "toy" in text
    assert {r["protocol"] for r in records} == {"prefix"}  # the biased task's default protocol (rounding up)


def test_rerun_reuses_stored_seeds(tmp_path):
    site = install_plugin(tmp_path / "site")
    env = {"PYTHONPATH": str(site)}
    for _ in range(2):
        assert cli(["run", "-r", "toy", "--seeds", "2", "--no-progress"], tmp_path, **env).returncode == 0
    import sqlite3

    n = sqlite3.connect(tmp_path / "store.sqlite").execute("SELECT COUNT(*) FROM results").fetchone()[0]
    assert n == 2 * 3


def test_run_takes_several_tasks(tmp_path):
    site = install_plugin(tmp_path / "site")
    tasks = ["GRAIL/MiniGrid-Biased-v0", "GRAIL/MiniGrid-Optimal-v0"]
    out = cli(["run", "-r", "toy", "-t", tasks[0], "-t", tasks[1], "--seeds", "1", "--no-progress", "--json",
               str(tmp_path / "r.json")], tmp_path, PYTHONPATH=str(site))
    assert out.returncode == 0, out.stderr
    records = json.loads((tmp_path / "r.json").read_text())
    assert {r["task"] for r in records} == set(tasks)
    assert {(r["task"], r["protocol"]) for r in records} == {(tasks[0], "prefix"), (tasks[1], "subset")}  # their own


def test_internal_errors_show_their_traceback(tmp_path):
    site = install_plugin(tmp_path / "site")
    out = cli(["run", "-r", "toy", "--set", "toy.bug=true", "--seeds", "1", "--no-progress"], tmp_path,
              PYTHONPATH=str(site))
    assert out.returncode not in (0, 2)
    assert "Traceback" in out.stderr and "ValueError: an internal error" in out.stderr


@pytest.mark.parametrize(
    "args, message",
    [
        (["leaderboard", "--store", "/nonexistent/results.sqlite"], "no results store at /nonexistent"),
        (["run", "--task", "GRAIL/Nope-v0"], "Nope"),
        (["run", "-r", "nope"], "unknown recognizer 'nope'"),
        (["run", "-r", "bc", "--observability", "0.1,1.5"], "observability 1.5 must be a fraction"),
        (["run", "-r", "bc", "--observability", "lots"], "is not a number"),
        (["run", "-r", "bc", "--protocol", "middle"], "unknown observation protocol 'middle'"),
        (["run", "-r", "bc", "--rounding", "half"], "unknown rounding 'half'"),
        (["ceiling", "-t", "GRAIL/PandaReach-Optimal-v0"], "needs a demonstrator with a known likelihood"),
        (["ceiling", "-t", "GRAIL/MiniGrid-Optimal-v0", "-p", "horizon-subset", "--method", "exact"],
         "cannot enumerate"),
        (["run", "-r", "bc", "--set", "bc.n_epochz=3"], "n_epochz"),
        (["run", "-r", "bc", "--set", "graql.episodes=3"], "not being run"),
        (["run", "-r", "draco", "--set", "draco.sac_steps=300"], "sac_steps applies to algorithm=sac"),
        (["list", "goals"], "cannot list"),
        (["run", "-r", "bc", "--param", "colour=3"], "cannot apply parameter 'colour'"),
        (["run", "-r", "bc", "--param", "n_train=20"], "n_train: must be smaller than n_demos (10)"),
    ],
)
def test_bad_input_gives_one_line_and_exit_2(args, message, tmp_path):
    out = cli(args, tmp_path)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], out.stderr
    assert "Traceback" not in out.stderr


def test_corrupt_store_is_one_line_and_untouched(tmp_path):
    store = tmp_path / "store.sqlite"
    store.write_bytes(b"garbage" * 500)
    before = store.read_bytes()
    for args in (["run", "-r", "bc"], ["leaderboard"]):
        out = cli(args, tmp_path)
        assert out.returncode == 2
        assert out.stderr.count("\n") == 1 and "is not a grail-bench results store" in out.stderr
    assert store.read_bytes() == before


def test_leaderboard_without_results(tmp_path):
    out = cli(["leaderboard"], tmp_path)
    assert out.returncode == 2 and "run `grail-bench run` first" in out.stderr
    assert not (tmp_path / "store.sqlite").exists(), "reading must not create a store"
    from grail_bench.harness.store import ResultsStore

    with ResultsStore(tmp_path / "store.sqlite") as store:
        store.create()
    out = cli(["leaderboard"], tmp_path)
    assert out.returncode == 2 and "no results in" in out.stderr


def test_leaderboard_with_reference(tmp_path):
    site = install_plugin(tmp_path / "site")
    env = {"PYTHONPATH": str(site)}
    assert cli(["run", "-r", "toy", "--seeds", "1", "--no-progress"], tmp_path, **env).returncode == 0
    ref = tmp_path / "ref.csv"
    ref.write_text("# reported\ntask,recognizer,observability,f1\nGRAIL/MiniGrid-Biased-v0,toy,0.2,0.42 ± 0.1\n")
    md = tmp_path / "lb.md"
    out = cli(["leaderboard", "--reference", str(ref), "--markdown", str(md)], tmp_path, **env)
    assert out.returncode == 0, out.stderr
    assert "0.42 ± 0.1" in md.read_text() and "*(paper)*" in md.read_text()
    bad = tmp_path / "bad.csv"
    bad.write_text("task,recognizer,observability,f1\nx,y,notanumber,1\n")
    out = cli(["leaderboard", "--reference", str(bad)], tmp_path, **env)
    assert out.returncode == 2 and "malformed reference row" in out.stderr
    out = cli(["leaderboard", "--reference", str(tmp_path / "missing.csv")], tmp_path, **env)
    assert out.returncode == 2 and "cannot read" in out.stderr


def test_scorers_listed_and_validated(tmp_path):
    out = cli(["list", "scorers"], tmp_path)
    assert out.returncode == 0 and "wasserstein" in out.stdout and "loglik" in out.stdout
    out = cli(["run", "-r", "bc", "--scorer", "nope"], tmp_path)
    assert out.returncode == 2 and "unknown scorer 'nope'" in out.stderr and out.stderr.count("\n") == 1


def test_ablation_table_markdown_and_plot(tmp_path):
    out = cli(["run", "-r", "bc", "--set", "bc.n_epochs=3", "--scorer", "mse", "--scorer", "loglik",
               "--seeds", "1", "-o", "0.3", "--no-progress"], tmp_path)
    assert out.returncode == 0, out.stderr
    assert "BC-GRAIL · n_epochs 3 " in out.stdout and "BC-GRAIL · n_epochs 3 · loglik" in out.stdout  # variants
    png, md = tmp_path / "ablation.png", tmp_path / "ABLATION.md"
    out = cli(["leaderboard", "--ablation", "--plot", str(png), "--markdown", str(md)], tmp_path)
    assert out.returncode == 0, out.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = md.read_text()
    assert "| GRAIL/MiniGrid-Biased-v0 (prefix) | bc | loglik |" in text
    assert "| GRAIL/MiniGrid-Biased-v0 (prefix) | bc | mse |" in text
    narrowed = tmp_path / "MSE.md"
    out = cli(["leaderboard", "--scorer", "mse", "--markdown", str(narrowed)], tmp_path)
    assert out.returncode == 0, out.stderr
    text = narrowed.read_text()
    assert "BC-GRAIL · n_epochs 3" in text and "loglik" not in text


def test_protocols_are_listed(tmp_path):
    out = cli(["protocols"], tmp_path)
    assert out.returncode == 0, out.stderr
    for name in ("subset", "prefix", "horizon-subset", "horizon-prefix"):
        assert name in out.stdout
    assert "leaks" in out.stdout


def test_ceiling_command_matches_the_library(tmp_path):
    from grail_bench.harness.ceiling import bayes_ceiling

    path = tmp_path / "ceiling.json"
    out = cli(["ceiling", "-t", "GRAIL/MiniGrid-Optimal-6Goals-v0", "--protocol", "prefix", "--observability",
               "0.1,0.3", "--param", "route_choice=uniform", "--json", str(path)], tmp_path)
    assert out.returncode == 0, out.stderr
    records = json.loads(path.read_text())
    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0", route_choice="uniform")
    assert [r["accuracy"] for r in records] == [bayes_ceiling(task, "prefix", p).accuracy for p in (0.1, 0.3)]
    assert {r["method"] for r in records} == {"exact"} and f"{records[0]['accuracy']:.3f}" in out.stdout
    assert {r["protocol"] for r in records} == {"prefix"}  # the task's rounding (ceil)
    out = cli(["ceiling", "-t", "GRAIL/MiniGrid-Optimal-6Goals-v0", "--observability", "0.3", "--pairs-only",
               "--json", str(path)], tmp_path)
    assert out.returncode == 0, out.stderr
    assert "Pairs-only ceiling" in out.stdout
    [record] = json.loads(path.read_text())
    assert record["pairs_only"] and record["accuracy"] == bayes_ceiling(task, "subset", 0.3, pairs_only=True).accuracy


def test_protocol_flag_and_deprecated_sampling_alias(tmp_path):
    site = install_plugin(tmp_path / "site")
    env = {"PYTHONPATH": str(site)}
    out = cli(["run", "-r", "toy", "--seeds", "1", "--protocol", "subset", "--rounding", "floor", "--no-progress",
               "--json", str(tmp_path / "a.json")], tmp_path, **env)
    assert out.returncode == 0, out.stderr
    assert {r["protocol"] for r in json.loads((tmp_path / "a.json").read_text())} == {"subset+floor"}
    out = cli(["run", "-r", "toy", "--seeds", "1", "--sampling", "random", "--no-progress",
               "--json", str(tmp_path / "b.json")], tmp_path, **env)
    assert out.returncode == 0, out.stderr
    assert "--sampling is deprecated" in out.stderr
    assert {r["protocol"] for r in json.loads((tmp_path / "b.json").read_text())} == {"subset"}  # task's
    out = cli(["run", "-r", "toy", "--seeds", "1", "--protocol", "subset", "--rounding", "ceil", "--no-progress",
               "--json", str(tmp_path / "c.json")], tmp_path, **env)
    assert {r["protocol"] for r in json.loads((tmp_path / "c.json").read_text())} == {"subset"}
    out = cli(["leaderboard", "--protocol", "subset+floor", "--boards"], tmp_path, **env)
    assert out.returncode == 0 and "(subset+floor)" in out.stdout and "(subset)" not in out.stdout
