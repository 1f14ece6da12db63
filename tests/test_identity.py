"""A recognizer's identity is part of its results: a changed plugin runs again and its old rows are archived;
``--rerun`` replaces rows; runs on a dataset's demonstrations are a configuration of their own on the boards."""

from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import install_plugin

import grail_bench
from grail_bench.harness.api import request
from grail_bench.harness.planning import fitted_config, plan
from grail_bench.harness.store import ResultsStore, StoreError
from grail_bench.harness.sweep import Interrupted, changed_line, run_sweep
from grail_bench.recognizers.identity import identity, source_hash
from grail_bench.recognizers.registry import register_recognizer, unregister_recognizer

ROOT = Path(__file__).resolve().parents[1]
TASK = "GRAIL/MiniGrid-Biased-v0"


def cli(args: list[str], tmp_path: Path, site: Path) -> subprocess.CompletedProcess:
    """``grail-bench ARGS`` in a new process, with the plugin's folder (and this checkout) on the path."""
    env = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_STORE": str(tmp_path / "store.sqlite"),
           "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}
    return subprocess.run([sys.executable, "-m", "grail_bench", *args], capture_output=True, text=True, env=env,
                          timeout=600, cwd=tmp_path)


def stored(tmp_path: Path) -> list[tuple]:
    """``(config_hash, seed, observability, f1)`` of every stored offline row, sorted."""
    with sqlite3.connect(tmp_path / "store.sqlite") as conn:
        return sorted(conn.execute("SELECT config_hash, seed, observability, f1 FROM results").fetchall())


def test_builtin_recognizers_have_no_identity_so_their_keys_stay():
    task = grail_bench.make_task(TASK)
    assert identity("bc") is None and identity("graql") is None
    planned = plan(task, grail_bench.harness.planning.RecognizerSpec("bc"), task.action_space())
    assert "identity" not in json.loads(planned.config)
    assert set(json.loads(planned.config)) == {"recognizer", "config", "task"}  # as stored before


def on_path(site: Path, monkeypatch) -> None:
    """The plugin's folder first on ``sys.path``, its module not yet imported (another test may have)."""
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.delitem(sys.modules, "toy_recognizer", raising=False)


def test_a_plugin_is_identified_by_its_distribution_version_and_source(tmp_path, monkeypatch):
    site = install_plugin(tmp_path / "site")
    on_path(site, monkeypatch)
    found = identity("toy")
    assert found["distribution"] == "toy-plugin-site" and found["version"] == "0.1"
    assert found["source"] == source_hash("toy_recognizer")  # no RECORD: not a built wheel, its source counts
    module = site / "toy_recognizer.py"
    module.write_text(module.read_text().replace("+ self.config", "- self.config"))
    assert identity("toy")["source"] != found["source"]
    task = grail_bench.make_task(TASK)
    assert fitted_config(task, "toy", {})["identity"] == identity("toy")


def test_a_built_wheel_is_identified_by_its_version_and_an_editable_install_by_its_source(tmp_path, monkeypatch):
    site = install_plugin(tmp_path / "site")
    on_path(site, monkeypatch)
    dist = site / "toy_plugin_site-0.1.dist-info"
    (dist / "RECORD").write_text("toy_recognizer.py,,\nminimal_recognizer.py,,\n")
    assert identity("toy") == {"distribution": "toy-plugin-site", "version": "0.1"}
    (dist / "direct_url.json").write_text(json.dumps({"url": site.as_uri(), "dir_info": {"editable": True}}))
    assert identity("toy")["source"] == source_hash("toy_recognizer")


@pytest.mark.slow
def test_a_changed_plugin_runs_again_says_so_once_and_its_old_rows_are_archived(tmp_path):
    site = install_plugin(tmp_path / "site")
    args = ["run", "-r", "toy", "--seeds", "1", "--no-progress"]
    first = cli(args, tmp_path, site)
    assert first.returncode == 0, first.stderr
    assert "changed since" not in first.stdout + first.stderr
    old = stored(tmp_path)
    assert len(old) == 3 and {r[3] for r in old} == {1.0}

    module = site / "toy_recognizer.py"  # the scores inverted: the wrong goal wins
    module.write_text(module.read_text().replace("return {g: (sum(", "return {g: -(sum("))
    second = cli(args, tmp_path, site)
    assert second.returncode == 0, second.stderr
    assert second.stdout.count(changed_line("toy")) == 1, second.stdout
    rows = stored(tmp_path)
    assert len(rows) == 6 and set(old) <= set(rows)  # the old rows kept
    assert {r[3] for r in rows if r not in old} == {0.0}  # the new code's F1

    md = tmp_path / "board.md"
    board = cli(["leaderboard", "--no-ceiling", "--markdown", str(md)], tmp_path, site)
    assert board.returncode == 0, board.stderr
    text = md.read_text()
    assert f"toy · archived {old[0][0][:6]}" in text  # the old configuration, archived
    assert "## Archive" in text and "an earlier source" in text  # what differs, where no setting does

    dist = site / "toy_plugin_site-0.1.dist-info"  # a new version, the same source
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-plugin-site\nVersion: 0.2\n")
    third = cli(args, tmp_path, site)
    assert third.returncode == 0, third.stderr
    assert third.stdout.count(changed_line("toy")) == 1 and len(stored(tmp_path)) == 9
    again = cli(args, tmp_path, site)  # nothing changed since: nothing runs, nothing said
    assert again.returncode == 0 and "changed since" not in again.stdout and len(stored(tmp_path)) == 9


MODULE = '''
import numpy as np


class Lookup:
    """Scores a goal by the share of observed states seen in its demonstrations."""

    name = "lookup"
    default_scorer = "default"
    sign = 1.0

    def exposes(self, action_space):
        return frozenset()

    def fit(self, demos, env_factory, *, seed, cache_key=None):
        self.seen = {g: {tuple(np.asarray(o).tolist()) for t in ts for o in t.obs} for g, ts in demos.items()}

    def score(self, observed, scorer=None):
        obs = [tuple(np.asarray(o).tolist()) for o in observed.obs]
        return {g: self.sign * sum(o in s for o in obs) / len(obs) for g, s in self.seen.items()}
'''


@pytest.fixture
def lookup(tmp_path, monkeypatch):
    """A recognizer from a module on the path (no distribution), registered in this process as ``lookup``."""
    folder = tmp_path / "mods"
    folder.mkdir()
    (folder / "lookup_recognizer.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(folder))
    register_recognizer("lookup", "lookup_recognizer:Lookup")
    import lookup_recognizer

    yield lookup_recognizer.Lookup
    unregister_recognizer("lookup")
    sys.modules.pop("lookup_recognizer", None)


def f1s(store: ResultsStore) -> dict[tuple, float]:
    return {(r.seed, r.observability): r.f1 for r in store.rows(recognizer="lookup")}


def test_rerun_replaces_the_rows_and_an_interrupted_one_keeps_the_old(tmp_path, lookup, monkeypatch):
    assert identity("lookup") == {"distribution": None, "version": None, "source": source_hash("lookup_recognizer")}
    req = request(TASK, ["lookup"], seeds=2)
    with ResultsStore(tmp_path / "s.sqlite") as store:
        run_sweep([req], store)
        before = f1s(store)
        assert len(before) == 6 and set(before.values()) == {1.0}

        monkeypatch.setattr(lookup, "sign", -1.0)  # other scores, the same source: the same units
        assert run_sweep([req], store).done == 0 and f1s(store) == before

        original = lookup.fit

        def fit_then_stop(self, demos, env_factory, *, seed, cache_key=None):
            if seed == 1:
                raise KeyboardInterrupt
            return original(self, demos, env_factory, seed=seed, cache_key=cache_key)

        monkeypatch.setattr(lookup, "fit", fit_then_stop)
        with pytest.raises(Interrupted):
            run_sweep([req], store, rerun=True)
        interrupted = f1s(store)
        assert len(interrupted) == 6
        assert {v for (seed, _), v in interrupted.items() if seed == 0} == {0.0}  # seed 0 finished: replaced
        assert {v for (seed, _), v in interrupted.items() if seed == 1} == {1.0}  # seed 1 did not: kept

        monkeypatch.setattr(lookup, "fit", original)
        summary = run_sweep([req], store, rerun=True)
        assert summary.done == 2 and summary.rows == 6
        after = f1s(store)
        assert after.keys() == before.keys() and set(after.values()) == {0.0}
        assert len(store.rows()) == 6


def test_add_outputs_runs_again_only_the_units_stored_without_outputs(tmp_path, lookup):
    req = request(TASK, ["lookup"], seeds=3)
    path = tmp_path / "s.sqlite"
    with ResultsStore(path) as store:
        run_sweep([req], store)
        before = f1s(store)
    with sqlite3.connect(path) as conn:  # seed 1 as stored before the store kept outputs
        assert conn.execute("DELETE FROM outputs WHERE seed = 1").rowcount == 3
    with ResultsStore(path) as store:
        assert run_sweep([req], store).done == 0  # a plain run finds every unit stored
        summary = run_sweep([req], store, add_outputs=True)
        assert (summary.done, summary.skipped, summary.rows) == (1, 2, 3)
        assert f1s(store) == before and len(store.rows()) == 9
        with sqlite3.connect(path) as conn:
            assert sorted(conn.execute("SELECT seed, count(*) FROM outputs GROUP BY seed")) == [(0, 3), (1, 3), (2, 3)]
        assert run_sweep([req], store, add_outputs=True).done == 0  # nothing left: resumable


def test_a_failed_replacing_write_keeps_the_stored_rows(tmp_path):
    from dataclasses import replace

    with ResultsStore(tmp_path / "s.sqlite") as store:
        run_sweep([request(TASK, [("graql", {"episodes": 50})], seeds=1, observability="0.2,0.3")], store)
        rows = store.rows()
        broken = [replace(rows[0], f1=0.5), replace(rows[1], seed=None)]  # the second cannot be stored
        with pytest.raises(StoreError):
            store.add(broken, replace=True)
        assert store.rows() == rows


def test_runs_on_a_datasets_demonstrations_are_a_configuration_on_the_boards(tmp_path, lookup):
    from typer.testing import CliRunner

    from grail_bench.cli import app
    from grail_bench.report import leaderboard
    from grail_bench.report.text import markdown
    from grail_bench.task.export import export

    out = tmp_path / "my-demos"
    export(grail_bench.make_task(TASK), [0], out)
    with ResultsStore(tmp_path / "s.sqlite") as store:
        run_sweep([request(TASK, ["lookup"], seeds=1, task_params={"demos": str(out)})], store)
        run_sweep([request(TASK, ["lookup"], seeds=1)], store)  # and on the generator's
        rows = store.rows()
    board = leaderboard.build(rows, ceiling_samples=None)
    assert not board.archive
    labels = {c.label: c for c in board.configs.values()}
    assert set(labels) == {"lookup", "lookup · demos my-demos"}
    assert labels["lookup · demos my-demos"].canonical and labels["lookup · demos my-demos"].dataset == "my-demos"
    (main,) = board.boards
    assert main.columns == ["lookup", "lookup · demos my-demos"]
    assert all(main.cell(row, "lookup · demos my-demos") is not None for row in main.rows)
    text = markdown(board.boards, board.records, variants=board.variants, archive=board.archive)
    assert "lookup · demos my-demos" in text and "lookup · archived" not in text

    result = CliRunner().invoke(app, ["leaderboard", "--store", str(tmp_path / "s.sqlite"), "--no-ceiling",
                                      "--boards"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "lookup · demos my-demos" in result.stdout and "archived" not in result.stdout
