"""The door: nothing written is ever half-written, a refused command changes nothing on disk, every cache entry and
stored row read back is checked, and every name reaching Markdown or HTML is escaped by one rule."""

from __future__ import annotations

import dataclasses
import errno
import hashlib
import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from grail_bench.cli.app import app
from grail_bench.core import atomic
from grail_bench.core.atomic import WriteError, write_files, write_text
from grail_bench.core.cache import CacheWarning, cached, cached_state_dict
from grail_bench.core.errors import UserError
from grail_bench.harness.store import ResultRow, ResultsStore, StoreError
from grail_bench.report.escape import html, md

TASK = "GRAIL/MiniGrid-Optimal-v0"


def cli(*args: str):
    return CliRunner().invoke(app, list(args), env={"COLUMNS": "200"})


def one_error_line(result, message: str) -> None:
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and message in lines[0], result.stderr


def listing(folder: Path) -> dict[str, bytes | None]:
    """Every path under ``folder`` (hidden temporaries included) with its bytes (None: a folder)."""
    return {str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes() for p in sorted(folder.rglob("*"))}


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def full_disk(monkeypatch):
    """Every atomic write fails as on a full disk, once its bytes are written (when they are flushed)."""
    def flush(path: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(atomic, "_flush", flush)


def row(seed: int = 0, task: str = TASK, recognizer: str = "bc", scorer: str = "mse", **changes) -> ResultRow:
    return dataclasses.replace(
        ResultRow(task=task, recognizer=recognizer, scorer=scorer, config_hash="abc", seed=seed, observability=0.5,
                  protocol="prefix", accuracy=0.5, precision=0.5, recall=0.5, f1=0.5, n_observations=6, n_ties=0,
                  fit_seconds_per_goal=0.1, score_us_per_observation=10.0, config="{}", versions="{}",
                  confusion="[[3, 0], [1, 2]]"), **changes)


def store_with(path: Path, rows) -> Path:
    with ResultsStore(path) as store:
        store.add(rows)
    return path


# --- 1. nothing half-written --------------------------------------------------------------------------------------


def test_a_full_disk_leaves_the_previous_file_and_no_temporary(tmp_path, full_disk):
    (tmp_path / "old.md").write_text("before")
    with pytest.raises(WriteError, match=f"^no space left on device writing {tmp_path / 'old.md'}$"):
        write_text(tmp_path / "old.md", "after")
    with pytest.raises(WriteError, match="no space left on device writing"):
        write_files({tmp_path / "new" / "deep" / "a.json": "{}", tmp_path / "new" / "b.svg": "<svg/>"})
    assert listing(tmp_path) == {"old.md": b"before"}  # no temporary, no folder the failed write made


def test_files_written_together_replace_nothing_when_one_fails(tmp_path):
    for name in ("a", "b"):
        (tmp_path / name).write_text("old")

    def fail(tmp: Path) -> None:
        tmp.write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(WriteError, match=f"no space left on device writing {tmp_path / 'b'}"):
        write_files({tmp_path / "a": "new", tmp_path / "b": fail})
    assert listing(tmp_path) == {"a": b"old", "b": b"old"}
    assert write_files({tmp_path / "a": "new", tmp_path / "b": b"new"}) == [tmp_path / "a", tmp_path / "b"]
    assert listing(tmp_path) == {"a": b"new", "b": b"new"}
    assert (tmp_path / "a").stat().st_mode & 0o777 == 0o666 & ~_umask()  # as any new file, not a private temp


def _umask() -> int:
    import os

    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_leaderboard_markdown_and_site_on_a_full_disk_are_one_line_and_keep_the_earlier_output(tmp_path,
                                                                                              monkeypatch):
    store = store_with(tmp_path / "s.sqlite", [row(0), row(1)])
    out = tmp_path / "out"
    assert cli("leaderboard", "--store", str(store), "--no-ceiling", "--markdown", str(out / "LB.md"),
               "--html", str(out / "site")).exit_code == 0
    before = listing(out)

    def flush(path: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic, "_flush", flush)
    one_error_line(cli("leaderboard", "--store", str(store), "--no-ceiling", "--markdown", str(out / "LB.md")),
                   f"no space left on device writing {out / 'LB.md'}")
    one_error_line(cli("leaderboard", "--store", str(store), "--no-ceiling", "--html", str(out / "site")),
                   "no space left on device writing")
    assert listing(out) == before


def test_a_full_cache_folder_is_one_line_and_leaves_no_entry(tmp_path, full_disk):
    with pytest.raises(WriteError, match="no space left on device writing .*\\.npz"):
        cached("k", {"a": 1}, lambda: {"w": np.ones(3)}, arrays=True, root=tmp_path)
    assert not [p for p in (tmp_path / "k").iterdir() if p.suffix != ".lock"]


def test_a_store_that_cannot_be_created_leaves_no_file(tmp_path, monkeypatch):
    import os

    def no_room(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    store = ResultsStore(tmp_path / "sub" / "s.sqlite")
    monkeypatch.setattr(os, "link", no_room)
    monkeypatch.setattr(os, "replace", no_room)
    with pytest.raises(StoreError, match=f"^no space left on device writing {tmp_path / 'sub' / 's.sqlite'}$"):
        store.add([row()])
    monkeypatch.undo()
    store.close()
    assert listing(tmp_path) == {}  # no file with no tables to refuse the next run, no folder, no temporary
    assert len(store_with(tmp_path / "sub" / "s.sqlite", [row()]).read_bytes()) > 0


def test_export_to_a_disk_without_room_is_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    import shutil

    from grail_bench.task import export as export_module

    monkeypatch.setattr(export_module.shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 10**9 - 1000, 1000))
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("kept")
    result = cli("export", "-t", "GRAIL/MiniGrid-Biased-v0", "--out", str(out))
    one_error_line(result, "no space left on device writing")
    assert listing(out) == {"mine.txt": b"kept"}


def test_a_dataset_writer_that_crashes_is_one_line_and_leaves_nothing(tmp_path, monkeypatch, capfd):
    import os
    import signal
    import sys
    import types

    from grail_bench.task import export as export_module

    if not hasattr(os, "fork"):
        pytest.skip("the writer runs in this process where the platform cannot fork")

    def crash(*args, **kwargs):  # as HDF5 does on a disk that fills up while it writes
        for _ in range(1000):
            print("HDF5-DIAG: Error detected in HDF5 (errno = 28, No space left on device)", file=sys.stderr)
        os.kill(os.getpid(), signal.SIGSEGV)

    monkeypatch.setattr(export_module, "minari_module", lambda: types.SimpleNamespace(create_dataset_from_buffers=crash))
    out = tmp_path / "out"
    result = cli("export", "-t", "GRAIL/MiniGrid-Biased-v0", "--out", str(out))
    one_error_line(result, f"no space left on device writing {out}")
    assert "HDF5-DIAG" not in capfd.readouterr().err
    assert not out.exists()


# --- 2. a refused command changes nothing --------------------------------------------------------------------------


def old_schema_store(tmp_path: Path) -> Path:
    path = store_with(tmp_path / "old.sqlite", [row(0), row(1)])
    conn = sqlite3.connect(path)
    conn.execute("ALTER TABLE results DROP COLUMN ties")
    conn.execute("PRAGMA user_version = 7")
    conn.commit()
    conn.close()
    return path


def test_an_old_store_opened_for_writing_is_migrated_only_by_rows_written(tmp_path):
    path = old_schema_store(tmp_path)
    before = sha(path)
    with ResultsStore(path) as store:  # a command that reads, plans and is refused before it writes
        assert [r.seed for r in store.rows()] == [0, 1]
    assert sha(path) == before and sorted(p.name for p in tmp_path.iterdir()) == ["old.sqlite"]
    with ResultsStore(path) as store:
        assert store.add([row(2)]) == 1
    with ResultsStore(path, read_only=True) as store:
        assert [r.seed for r in store.rows()] == [0, 1, 2]  # migrated in place, every row kept
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] > 7


def test_a_current_store_opened_for_writing_is_unchanged_until_rows_are_written(tmp_path):
    path = store_with(tmp_path / "s.sqlite", [row(0)])
    conn = sqlite3.connect(path)
    conn.execute("PRAGMA journal_mode=DELETE")  # e.g. a store copied from elsewhere
    conn.close()
    before = sha(path)
    with ResultsStore(path) as store:
        assert store.completed(TASK, "bc", "mse", "abc", "prefix") == {(0, 0.5)}
    assert sha(path) == before and sorted(p.name for p in tmp_path.iterdir()) == ["s.sqlite"]


def test_a_refused_run_leaves_an_old_store_byte_identical_and_creates_none(tmp_path):
    path = old_schema_store(tmp_path)
    before = sha(path)
    refused = ["run", "-t", TASK, "-r", "bc", "--set", "bc.n_epochs=-5", "--seeds", "1", "--no-progress"]
    one_error_line(cli(*refused, "--store", str(path)), "n_epochs")  # refused once the store is open
    assert sha(path) == before
    one_error_line(cli(*refused, "--store", str(tmp_path / "new" / "s.sqlite")), "n_epochs")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.sqlite"]  # no store file, no folder


def test_a_refused_command_leaves_no_out_folder(tmp_path):
    one_error_line(cli("reproduce", "--only", "nosuch", "--out", str(tmp_path / "a" / "out"), "--no-progress"),
                   "no section 'nosuch'")
    one_error_line(cli("inspect", "-t", "GRAIL/Nope-v0", "--out", str(tmp_path / "b")), "Nope")
    assert list(tmp_path.iterdir()) == []


# --- 3. accepted, yet wrong ------------------------------------------------------------------------------------------


def _scored_with(monkeypatch, fn):
    from grail_bench.recognizers import make_recognizer
    from grail_bench.recognizers.scoring import PolicyOutput, Scorer

    recognizer = make_recognizer("bc")
    recognizer.goals = [(1, 1), (2, 2)]
    bad = Scorer("bad", fn, (frozenset({"probs"}),), "a plugin's mistake")
    output = PolicyOutput(probs=np.full((2, 3, 4), 0.25))
    monkeypatch.setattr(recognizer, "_scored", lambda observed, scorer: (bad, output, np.zeros(3, dtype=int)))
    return recognizer


@pytest.mark.parametrize("fn, message", [
    (lambda out, acts: np.zeros(17), r"shape \(17,\).*expected \(2,\)"),
    (lambda out, acts: np.array(["0.5", "0.1"]), "must return numbers"),
    (lambda out, acts: np.zeros((2, 3)), r"shape \(2, 3\)"),
])
def test_a_scorer_returning_the_wrong_scores_is_refused_not_stored_as_ties(monkeypatch, fn, message):
    recognizer = _scored_with(monkeypatch, fn)
    with pytest.raises(UserError, match=message):
        recognizer.score(None)
    with pytest.raises(UserError, match=message):
        recognizer.score_prefixes(None)


def test_a_scorer_returning_one_score_per_goal_is_kept(monkeypatch):
    recognizer = _scored_with(monkeypatch, lambda out, acts: np.array([0.1, 0.9]))
    assert recognizer.score(None) == {(1, 1): 0.1, (2, 2): 0.9}


@pytest.mark.parametrize("fraction", [0, 2, -0.5, float("nan")])
def test_observing_outside_0_1_is_refused(fraction):
    from grail_bench.core.trajectory import Trajectory
    from grail_bench.task.observation import observe

    traj = Trajectory(obs=np.zeros((4, 2)), acts=np.zeros(3, dtype=int))
    with pytest.raises(UserError):
        observe(traj, fraction)


# --- 4. every read checked ---------------------------------------------------------------------------------------------


def forge(model: Path, write) -> None:
    """Replace a cache entry's model file and forge its sidecar's checksum to match."""
    write(model)
    meta = model.with_suffix(".json")
    info = json.loads(meta.read_text())
    info["sha256"] = sha(model)
    meta.write_text(json.dumps(info))


def test_demo_cache_entries_that_do_not_fit_together_are_regenerated_with_one_warning(tmp_path):
    from grail_bench.task import demo_cache

    good = {"obs": np.zeros((5, 2)), "acts": np.zeros(3, dtype=np.int64), "lengths": np.array([1, 2]),
            "success": np.array([False, True, True])}
    calls = []

    def generate():
        calls.append(1)
        return good

    def entry():
        return cached("demos", {"k": 1}, generate, arrays=True, root=tmp_path,
                      check=lambda a: demo_cache.check(a, 2)).state

    entry()
    model = tmp_path / "demos" / next(p.name for p in (tmp_path / "demos").glob("*.npz"))
    for damage, reason in [({"lengths": np.array([-1, 4])}, "negative length"),
                           ({"obs": np.zeros((9, 2))}, "do not match its lengths"),
                           ({"extra": np.zeros(1)}, "not obs, acts"),
                           ({"obs": np.full((5, 2), np.nan)}, "holds NaN")]:
        forge(model, lambda path: np.savez(open(path, "wb"), **(good | damage)))
        with pytest.warns(CacheWarning) as seen:
            arrays = entry()
        assert len(seen) == 1 and str(model) in str(seen[0].message) and reason in str(seen[0].message)
        assert all(np.array_equal(arrays[k], good[k]) for k in good)
    assert len(calls) == 5  # generated once, then again for each damaged entry


@pytest.mark.parametrize("damage, reason", [
    ("nan", "holds NaN"), ("shape", "size mismatch"), ("sidecar", "sidecar is malformed"),
    ("seconds", "training time is malformed"), ("truncated", "cannot be read"),
])
def test_model_cache_entries_are_checked_and_retrained_with_one_warning(tmp_path, damage, reason):
    import torch

    def train():
        return torch.nn.Linear(3, 2).state_dict()

    def load():
        return cached_state_dict("m", {"k": 1}, train, root=tmp_path, check=torch.nn.Linear(3, 2).load_state_dict)

    load()
    model = next((tmp_path / "m").glob("*.pt"))
    meta = model.with_suffix(".json")
    if damage == "nan":
        forge(model, lambda p: torch.save({"weight": torch.full((2, 3), float("nan")), "bias": torch.zeros(2)}, p))
    elif damage == "shape":
        forge(model, lambda p: torch.save(torch.nn.Linear(5, 2).state_dict(), p))
    elif damage == "sidecar":
        meta.write_text("[1, 2]")
    elif damage == "seconds":
        meta.write_text(json.dumps(json.loads(meta.read_text()) | {"train_seconds": "slow"}))
    else:
        forge(model, lambda p: p.write_bytes(model.read_bytes()[:40]))
    with pytest.warns(CacheWarning) as seen:
        state, _ = load()
    assert len(seen) == 1 and str(model) in str(seen[0].message) and reason in str(seen[0].message)
    assert state["weight"].shape == (2, 3) and not torch.isnan(state["weight"]).any()
    load()  # the retrained entry is whole again: no warning


@pytest.mark.parametrize("sql, problem", [
    ("UPDATE results SET f1 = 'high' WHERE seed = 1", "f1 is 'high', not a number"),
    ("UPDATE results SET confusion = '[[3, 0], [1' WHERE seed = 1", "confusion is not valid JSON"),
    ("UPDATE results SET confusion = '[[3, 0]]' WHERE seed = 1", "confusion is not a square matrix"),
    ("UPDATE results SET f1 = NULL WHERE seed = 1", "f1 is NULL"),
])
def test_a_hand_edited_row_is_one_line_naming_it_and_no_row_is_lost(tmp_path, sql, problem):
    path = store_with(tmp_path / "s.sqlite", [row(0), row(1), row(2)])
    conn = sqlite3.connect(path)
    conn.execute(sql)
    conn.commit()
    conn.close()
    named = f"table results, row (task '{TASK}', recognizer 'bc', seed 1): {problem}"
    with ResultsStore(path, read_only=True) as store, pytest.raises(StoreError, match=named.replace("(", r"\(")
                                                                                              .replace(")", r"\)")
                                                                                              .replace("[", r"\[")):
        store.rows()
    one_error_line(cli("leaderboard", "--store", str(path), "--no-ceiling"), named)
    with ResultsStore(path) as store:  # a run over it: refused in one line, nothing written or lost
        with pytest.raises(StoreError, match="seed 1"):
            store.completed(TASK, "bc", "mse", "abc", "prefix")
    assert sqlite3.connect(path).execute("SELECT COUNT(*) FROM results").fetchone()[0] == 3


# --- 5. one escaping rule -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("text, markdown", [
    ("<script>alert(1)</script>", "&lt;script&gt;alert(1)&lt;/script&gt;"),
    ("A & B", "A & B"),
    ("&lt;b&gt;", "&amp;lt;b&amp;gt;"),
    ("a|b", "a\\|b"),
    ("[x](javascript:y)", "\\[x\\](javascript:y)"),
    ("*bold* `code`", "\\*bold\\* \\`code\\`"),
    ("two\nlines", "two lines"),
])
def test_markdown_shows_a_name_as_it_is(text, markdown):
    assert md(text) == markdown


def test_html_escapes_text_and_attributes():
    assert html("<b a=\"1\">'&'</b>") == "&lt;b a=&#34;1&#34;&gt;&#39;&amp;&#39;&lt;/b&gt;"


def test_a_script_task_and_scorer_name_are_escaped_in_every_markdown_table(tmp_path):
    from conftest import offline_record

    from grail_bench.harness.modes import MODES
    from grail_bench.report import leaderboard
    from grail_bench.report.claims import ClaimResult, claims_markdown
    from grail_bench.report.rows import ablation_rows
    from grail_bench.report.tables import ablation_markdown, mode_markdown
    from grail_bench.report.text import markdown

    evil = "GRAIL/<script>x</script>&Co-v0"
    records = [dataclasses.replace(offline_record(TASK, "bc", 0.1, 0.5, scorer=s), task=evil, scorer=f"<b>{s}</b>")
               for s in ("mse", "kl")]
    board = leaderboard.build([], records=records, ceiling_samples=None)
    claim = ClaimResult("<script>c</script>", "<i>s</i>", "<script>cfg</script>", "<m>", 0.5, 0.4, 0.6, "holds")
    texts = {"leaderboard": markdown(board.boards, board.records, variants=board.variants, archive=board.archive,
                                     claims=[claim]),
             "claims": claims_markdown([claim]),
             "ablation": ablation_markdown(ablation_rows(records)),
             "mode": mode_markdown(records, MODES["offline"])}
    for name, text in texts.items():
        assert "<script>" not in text and "<b>" not in text and "<i>" not in text and "<m>" not in text, name
        assert "&amp;" not in text, name  # & as it is
    assert "&lt;script&gt;x&lt;/script&gt;&Co-v0" in texts["leaderboard"].split("## Runs")[1]
