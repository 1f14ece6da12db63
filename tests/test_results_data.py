"""Results as data: the published format (export, import, schema), its determinism and round trip."""

from __future__ import annotations

import dataclasses
import gzip
import json
from pathlib import Path

import pytest
from test_site import fit_rows, online_rows, open_set_rows, rows
from typer.testing import CliRunner

from grail_bench.cli import app
from grail_bench.harness import published
from grail_bench.harness.schema import row_tables
from grail_bench.harness.store import ResultsStore
from grail_bench.report import leaderboard
from grail_bench.report.html import write_site
from grail_bench.report.text import markdown

runner = CliRunner()


def all_rows(path: Path) -> dict[str, list]:
    with ResultsStore(path, read_only=True) as store:
        return {kind.__name__: store.select(kind) for kind in row_tables()}


@pytest.fixture()
def store(tmp_path: Path) -> Path:
    """A store of offline rows on two domains (provenance on some), online and open-set rows and fit diagnostics."""
    path = tmp_path / "original.sqlite"
    with ResultsStore(path) as s:
        s.add([*rows(3), *online_rows(), *open_set_rows()])
        s.add(fit_rows())
    return path


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def lines_of(folder: Path) -> set[str]:
    """Every line of every published file (decompressed), prefixed by its file's name without ``.gz``."""
    out = set()
    for p in folder.rglob("*.jsonl*"):
        text = (gzip.decompress(p.read_bytes()) if p.suffix == ".gz" else p.read_bytes()).decode()
        out |= {f"{p.relative_to(folder).as_posix().removesuffix('.gz')}:{line}" for line in text.splitlines()}
    return out


def test_the_shipped_schema_is_the_one_the_row_types_make():
    assert published.schema() == published.build_schema()  # regenerate results.schema.json if a row type changed


def test_export_import_round_trip_is_equal_row_for_row_and_exports_byte_identical(store, tmp_path, monkeypatch):
    monkeypatch.setattr(published, "GZIP_ABOVE", 8192)  # some files compressed, some not
    out = tmp_path / "pub"
    with ResultsStore(store, read_only=True) as s:
        written = published.export(s, out)
    names = {p.relative_to(out).as_posix() for p in written}
    assert {n.removesuffix(".gz") for n in names} == {
        "format.json", "configs.jsonl", "versions.jsonl", "provenance.jsonl", "minigrid/offline.jsonl",
        "panda_reach/offline.jsonl", "minigrid/online.jsonl", "minigrid/open_set.jsonl", "minigrid/fits.jsonl"}
    assert any(n.endswith(".gz") for n in names) and any(n.endswith(".jsonl") for n in names)
    rebuilt = tmp_path / "rebuilt.sqlite"
    with ResultsStore(rebuilt) as s:
        assert published.load(out, s) == sum(len(v) for v in all_rows(store).values())
    assert all_rows(rebuilt) == all_rows(store)
    again = tmp_path / "again"
    with ResultsStore(rebuilt, read_only=True) as s:
        published.export(s, again)
    assert files_of(again) == files_of(out)  # gzip included: no name, no time in its header


def test_boards_markdown_and_page_of_the_rebuilt_store_are_those_of_the_original(store, tmp_path):
    out = tmp_path / "pub"
    with ResultsStore(store, read_only=True) as s:
        published.export(s, out)
    rebuilt = tmp_path / "rebuilt.sqlite"
    with ResultsStore(rebuilt) as s:
        published.load(out, s)
    made = []
    for path, site in ((store, tmp_path / "site_a"), (rebuilt, tmp_path / "site_b")):
        got = all_rows(path)
        board = leaderboard.build(got["ResultRow"], None, None, fits=got["FitRow"],
                                  studies={"online": got["OnlineRow"], "open-set": got["OpenSetRow"]})
        text = markdown(board.boards, board.records, fits=board.fits, variants=board.variants, archive=board.archive)
        write_site(board, site)
        made.append((text, files_of(site)))
    assert made[0][0] == made[1][0] and "MiniGrid" in made[0][0]
    assert made[0][1] == made[1][1] and "index.html" in made[0][1]


def test_a_republish_with_one_more_task_adds_only_its_lines(store, tmp_path):
    out = tmp_path / "pub"
    with ResultsStore(store) as s:
        published.export(s, out)
        before = lines_of(out)
        extra = [dataclasses.replace(r, task="GRAIL/MiniGrid-Suboptimal-v0") for r in s.rows()
                 if r.task == "GRAIL/MiniGrid-Optimal-v0"]
        s.add(extra)
        published.export(s, out)
    added = lines_of(out) - before
    assert before <= lines_of(out)
    assert len(added) == len(extra) and all('"GRAIL/MiniGrid-Suboptimal-v0"' in line for line in added)


def test_import_refuses_a_row_that_breaks_the_schema_naming_file_and_line(store, tmp_path):
    out = tmp_path / "pub"
    with ResultsStore(store, read_only=True) as s:
        published.export(s, out)
    file = out / "minigrid" / "online.jsonl"
    lines = file.read_text().splitlines()
    bad = json.loads(lines[1])
    bad["seed"] = "one"
    file.write_text("\n".join([lines[0], json.dumps(bad), *lines[2:]]) + "\n")
    target = tmp_path / "t.sqlite"
    result = runner.invoke(app, ["results", "import", str(out), "--store", str(target)])
    assert result.exit_code == 2 and "online.jsonl:2: seed: 'one' is not of type 'integer'" in result.stderr
    assert not target.exists()


def test_cli_schema_export_and_import(store, tmp_path):
    result = runner.invoke(app, ["results", "schema"])
    assert result.exit_code == 0 and set(json.loads(result.stdout)["$defs"]) >= set(published.KINDS)
    out = tmp_path / "pub"
    assert runner.invoke(app, ["results", "export", "--store", str(store), "--out", str(out)]).exit_code == 0
    target = tmp_path / "t.sqlite"
    result = runner.invoke(app, ["results", "import", str(out), "--store", str(target)])
    assert result.exit_code == 0, result.output
    assert all_rows(target) == all_rows(store)


# --- per-instance outputs ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    """A tiny offline run (bc, one epoch, two seeds, two levels, two scorers, one a posterior) in its own store."""
    from grail_bench.harness.planning import RecognizerSpec
    from grail_bench.harness.api import request
    from grail_bench.harness.sweep import run_sweep

    path = tmp_path_factory.mktemp("run") / "run.sqlite"
    req = request("GRAIL/MiniGrid-Optimal-v0", [RecognizerSpec("bc", {"n_epochs": 1}, ("mse", "loglik"))],
                  seeds=[0, 1], observability=[0.3, 1.0])
    with ResultsStore(path) as s:
        run_sweep([req], s)
    return path


def test_every_offline_metric_is_recomputed_exactly_from_the_per_instance_outputs(tiny_run):
    from grail_bench.harness.outputs import OutputRow, disagreements, recompute

    with ResultsStore(tiny_run, read_only=True) as s:
        rows, kept = s.rows(), {(o.scorer, o.seed, o.observability): o for o in s.select(OutputRow)}
    assert len(rows) == len(kept) == 8 and {r.scorer for r in rows} == {"mse", "loglik"}
    for r in rows:
        outputs = kept[(r.scorer, r.seed, r.observability)]
        y_true, lengths, scores = outputs.arrays()
        assert len(y_true) == len(lengths) == scores.shape[0] == r.n_observations and scores.shape[1] == 2
        assert disagreements(r, outputs) == []
        assert (r.brier is not None) == (r.scorer == "loglik") == bool(outputs.posterior)
    wrong = dataclasses.replace(rows[0], f1=rows[0].f1 + 0.01, n_ties=rows[0].n_ties + 1)
    assert disagreements(wrong, kept[(wrong.scorer, wrong.seed, wrong.observability)]) == ["f1", "n_ties"]
    assert recompute(outputs)["confusion"] == r.confusion


@pytest.fixture(scope="module")
def modes_run(tmp_path_factory) -> Path:
    """A tiny run of the online, open-set and zero-shot modes (bc and gc-bc, a few updates, one or two seeds) on
    a four-goal task, in its own store."""
    from grail_bench.harness.api import request
    from grail_bench.harness.planning import RecognizerSpec
    from grail_bench.harness.sweep import run_sweep

    task = "GRAIL/MiniGrid-Optimal-4Goals-v0"
    bc = RecognizerSpec("bc", {"n_epochs": 1}, ("mse", "loglik"))
    path = tmp_path_factory.mktemp("modes") / "modes.sqlite"
    with ResultsStore(path) as s:
        run_sweep([request(task, [bc], seeds=[0], mode="online"),
                   request(task, [bc], seeds=[0, 1], observability=[0.5, 1.0], mode="open-set"),
                   request(task, [RecognizerSpec("gc-bc", {"n_batches": 30})], seeds=[0], observability=[0.5],
                           mode="zero-shot", protocol="prefix")], s)
    return path


@pytest.mark.parametrize("mode", ["online", "open-set", "zero-shot"])
def test_every_metric_of_every_mode_is_recomputed_exactly_from_its_per_instance_outputs(modes_run, mode):
    from grail_bench.harness.outputs import KINDS, disagreements

    kind = next(k for k in KINDS.values() if k.mode == mode)
    with ResultsStore(modes_run, read_only=True) as s:
        rows = s.select(kind.of)
        kept = {tuple(getattr(o, k) for k in kind.key): o for o in s.select(kind.row)}
    assert rows and len(rows) == len(kept)
    for r in rows:
        outputs = kept[tuple(getattr(r, k) for k in kind.key)]
        arrays = outputs.named()
        assert kind.consistent(arrays)
        assert disagreements(r, outputs) == []
        again = kind.recompute(outputs)
        assert {name: again[name] for name in kind.metrics} == {name: getattr(r, name) for name in kind.metrics}
        if mode == "online":  # every prefix of every trajectory scored, and kept
            assert len(arrays["y_true"]) == r.n_trajectories and len(arrays["scores"]) == sum(arrays["lengths"])
        elif mode == "open-set":  # the known goals' scores, the held-out goal's observations labelled K
            assert arrays["scores"].shape == (r.n_observations, 3) and set(arrays["y_true"]) == {0, 1, 2, 3}
        else:  # every goal given at test time scored; the held-out ones named by index
            assert arrays["scores"].shape == (r.n_observations, 4) and len(arrays["held_out"]) == 1
    first = rows[0]
    changed = {name: (getattr(first, name) + 1 if isinstance(getattr(first, name), (int, float)) else "[]")
               for name in kind.metrics[:2]}
    wrong = dataclasses.replace(first, **changed)
    assert disagreements(wrong, kept[tuple(getattr(first, k) for k in kind.key)]) == list(kind.metrics[:2])


def test_the_outputs_of_every_mode_are_exported_imported_and_validated(modes_run, tmp_path):
    out = tmp_path / "pub"
    with ResultsStore(modes_run, read_only=True) as s:
        published.export(s, out)
    assert {p.name for p in (out / "minigrid").iterdir()} >= {
        "online_outputs.jsonl", "open_set_outputs.jsonl", "zero_shot_outputs.jsonl"}
    rebuilt = tmp_path / "rebuilt.sqlite"
    assert runner.invoke(app, ["results", "import", str(out), "--store", str(rebuilt)]).exit_code == 0
    assert all_rows(rebuilt) == all_rows(modes_run)
    result = runner.invoke(app, ["results", "validate", str(out)])
    assert result.exit_code == 0, result.output
    assert "2 online_outputs, 8 open_set, 8 open_set_outputs, 1 zero_shot, 1 zero_shot_outputs" in result.stdout
    assert "every metric recomputed from its outputs" in result.stdout
    edit_lines(out / "minigrid" / "open_set.jsonl",
               lambda lines: [dict(line, auroc=0.5) if i == 1 else line for i, line in enumerate(lines)])
    edit_lines(out / "minigrid" / "zero_shot_outputs.jsonl",
               lambda lines: [dict(line, held_out=[0, 1]) for line in lines])
    edit_lines(out / "minigrid" / "online_outputs.jsonl", lambda lines: lines[1:])
    result = runner.invoke(app, ["results", "validate", str(out)])
    assert result.exit_code == 2
    assert "stated auroc differ from those its outputs give" in result.stderr
    assert "stated f1_held_out, f1_trained, accuracy_held_out, accuracy_trained differ" in result.stderr
    assert "no per-instance outputs to recompute its metrics from" in result.stderr and "3 problem(s)" in result.stderr
    edit_lines(out / "minigrid" / "online_outputs.jsonl",
               lambda lines: [dict(line, lengths=[n + 1 for n in line["lengths"]]) for line in lines])
    result = runner.invoke(app, ["results", "validate", str(out)])
    assert result.exit_code == 2 and "scores one row per prefix" in result.stderr


# --- submissions --------------------------------------------------------------------------------------------------

SOURCE = {"lab": "Example Lab", "recognizer": "bc", "version": "1.0", "url": "https://example.org/bc"}


@pytest.fixture()
def submission(tiny_run, tmp_path) -> Path:
    """The tiny run published as a submission, with its per-instance outputs and source.json."""
    out = tmp_path / "submission"
    with ResultsStore(tiny_run, read_only=True) as s:
        published.export(s, out)
    (out / "source.json").write_text(json.dumps(SOURCE))
    return out


def edit_lines(file: Path, change) -> None:  # noqa: ANN001
    lines = [json.loads(line) for line in file.read_text().splitlines()]
    file.write_text("".join(json.dumps(line) + "\n" for line in change(lines)))


def test_validate_accepts_a_complete_submission(submission):
    result = runner.invoke(app, ["results", "validate", str(submission)])
    assert result.exit_code == 0, result.output
    assert "is valid: 2 fits, 8 offline, 8 outputs rows" in result.stdout


def test_validate_refuses_a_wrong_metric(submission):
    edit_lines(submission / "minigrid" / "offline.jsonl",
               lambda lines: [dict(line, f1=line["f1"] + 0.01) if i == 3 else line for i, line in enumerate(lines)])
    result = runner.invoke(app, ["results", "validate", str(submission)])
    assert result.exit_code == 2
    assert "stated f1 differ from those its outputs give" in result.stderr and "1 problem(s)" in result.stderr


def test_validate_refuses_a_missing_seed(submission):
    edit_lines(submission / "minigrid" / "offline.jsonl", lambda lines: [line for line in lines if line["seed"] != 0])
    result = runner.invoke(app, ["results", "validate", str(submission)])
    assert result.exit_code == 2 and "seeds are 0..1 but 0 missing" in result.stderr


def test_validate_refuses_an_unknown_task(submission):
    for name in ("offline", "outputs", "fits"):
        edit_lines(submission / "minigrid" / f"{name}.jsonl",
                   lambda lines: [dict(line, task="GRAIL/MiniGrid-Optimal-v9") for line in lines])
    result = runner.invoke(app, ["results", "validate", str(submission)])
    assert result.exit_code == 2 and "unknown task GRAIL/MiniGrid-Optimal-v9" in result.stderr


def test_merge_labels_the_rows_by_their_source_and_the_leaderboard_shows_them_as_submitted(submission, tmp_path):
    target = tmp_path / "mine.sqlite"
    result = runner.invoke(app, ["results", "merge", str(submission), "--store", str(target)])
    assert result.exit_code == 0 and "18 rows merged" in result.stdout
    with ResultsStore(target, read_only=True) as s:
        assert {json.loads(r.source)["lab"] for r in s.rows()} == {"Example Lab"}
    result = runner.invoke(app, ["leaderboard", "--store", str(target), "--no-ceiling",
                                 "--markdown", str(tmp_path / "board.md")])
    assert result.exit_code == 0, result.output
    assert "BC-GRAIL · n_epochs 1 · submitted by Example Lab" in (tmp_path / "board.md").read_text()
    again = tmp_path / "again"
    assert runner.invoke(app, ["results", "export", "--store", str(target), "--out", str(again)]).exit_code == 0
    assert json.loads((again / "sources.jsonl").read_text())["json"] == json.dumps(SOURCE, sort_keys=True)


def test_merge_refuses_an_invalid_submission_and_one_without_a_source(submission, tmp_path):
    target = tmp_path / "mine.sqlite"
    (submission / "source.json").unlink()
    result = runner.invoke(app, ["results", "merge", str(submission), "--store", str(target)])
    assert result.exit_code == 2 and "has no source.json" in result.stderr
    edit_lines(submission / "minigrid" / "offline.jsonl", lambda lines: [dict(lines[0], n_ties=5), *lines[1:]])
    result = runner.invoke(app, ["results", "merge", str(submission), "--store", str(target)])
    assert result.exit_code == 2 and "not merged" in result.stderr and "n_ties" in result.stderr
    assert not target.exists()  # refused before the store was opened


def test_verify_runs_units_again_and_reports_agreement(submission):
    result = runner.invoke(app, ["results", "verify", str(submission), "--sample", "1"])
    assert result.exit_code == 0, result.output
    assert "agreement: 1/1 units, 4/4 rows" in result.stdout
    edit_lines(submission / "minigrid" / "offline.jsonl", lambda lines: [dict(line, f1=0.0) for line in lines])
    result = runner.invoke(app, ["results", "verify", str(submission), "--sample", "1"])
    assert "agreement: 0/1 units" in result.stdout


def test_verify_runs_units_of_every_mode_again_and_compares_every_recomputable_metric(modes_run, tmp_path):
    out = tmp_path / "submission"
    with ResultsStore(modes_run, read_only=True) as s:
        published.export(s, out)
    result = runner.invoke(app, ["results", "verify", str(out), "--sample", "4"])
    assert result.exit_code == 0, result.output
    task = "GRAIL/MiniGrid-Optimal-4Goals-v0"
    for line in (f"{task} bc seed 0 subset (online): 2/2 rows agree", f"{task} bc seed 1 subset (open-set): 4/4",
                 f"{task} gc-bc seed 0 prefix (zero-shot): 1/1"):
        assert line in result.stdout
    assert "agreement: 4/4 units, 11/11 rows" in result.stdout
    edit_lines(out / "minigrid" / "online.jsonl",  # one of the two rows
               lambda lines: [dict(lines[0], never=lines[0]["never"] + 0.25), *lines[1:]])
    edit_lines(out / "minigrid" / "open_set.jsonl",
               lambda lines: [dict(line, threshold=line["threshold"] + 1e-9) if line["seed"] == 1 else line
                              for line in lines])
    result = runner.invoke(app, ["results", "verify", str(out), "--sample", "4"])
    assert result.exit_code == 0, result.output
    assert "(online): 1/2 rows agree" in result.stdout and f"{task} bc seed 1 subset (open-set): 0/4" in result.stdout
    assert "agreement: 2/4 units, 6/11 rows" in result.stdout
    for name in ("online", "open_set", "zero_shot"):
        (out / "minigrid" / f"{name}.jsonl").unlink()
    result = runner.invoke(app, ["results", "verify", str(out)])
    assert result.exit_code == 2 and "has no rows (offline, online, open-set, zero-shot) to run again" in result.stderr


@pytest.mark.parametrize("kind", ["offline", "online", "open_set", "zero_shot", "fits", "shared"])
def test_the_quick_line_check_agrees_with_the_schema_validator(kind):
    from hypothesis import given, settings
    from hypothesis import strategies as st

    quick, full = published._quick(kind), published._validator(kind)
    spec = published.schema()["$defs"][kind]
    assert quick is not None
    scalars = st.one_of(st.none(), st.booleans(), st.integers(-3, 3), st.floats(allow_nan=False), st.text(max_size=3),
                        st.just("0" * 64), st.just(1.0))
    names = st.sampled_from([*spec["properties"], "extra"])

    @settings(max_examples=300, deadline=None, derandomize=True)
    @given(st.dictionaries(names, scalars), st.sampled_from([*spec["required"]]), scalars)
    def agree(line, name, value):
        whole = {n: line.get(n, value) for n in spec["required"]} | line  # mostly complete lines
        for candidate in (line, whole, whole | {name: value}):
            assert quick(candidate) == full.is_valid(candidate), candidate

    agree()


def test_a_compressed_file_that_unpacks_past_the_bound_is_refused(tmp_path, monkeypatch):
    import gzip

    from grail_bench.harness import published

    monkeypatch.setattr(published, "MAX_FILE_BYTES", 1 << 16)
    bomb = tmp_path / "offline.jsonl.gz"
    bomb.write_bytes(gzip.compress(b"{}\n" * (1 << 16)))  # a few hundred bytes that unpack past the bound
    with pytest.raises(published.PublishedError, match="more than 0 MiB of rows in one file"):
        list(published.read_lines(bomb))
