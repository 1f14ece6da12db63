"""`grail-bench study`: each study on a small store or task, the listing, and one-line errors."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from grail_bench.cli import app
from grail_bench.harness.diagnostics import FitRow, to_json
from grail_bench.harness.planning import RecognizerSpec, plan
from grail_bench.harness.store import ResultRow, ResultsStore
from grail_bench.recognizers.contract import FitDiagnostics
from grail_bench.report.reproduce import load_profile
from grail_bench.report.studies import STUDIES, off_route
from grail_bench.task import make_task

OPTIMAL = "GRAIL/MiniGrid-Optimal-v0"


def study(*args: str):
    return CliRunner().invoke(app, ["study", *args], env={"COLUMNS": "200"})


def result_row(task, planned, seed: int, level: float, f1: float, config_hash: str | None = None) -> ResultRow:
    return ResultRow(task.id, "bc", planned.labels[0], config_hash or planned.config_hash, seed, level,
                     task.protocol_label, f1, f1, f1, f1, 6, 0, 0.1, 1.0, planned.config, "{}")


def fit_row(task, planned, seed: int, reached: tuple[bool, bool]) -> FitRow:
    diagnostics = FitDiagnostics(goals=tuple(task.goals), agreement_train=(1.0, 1.0), agreement_held_out=(1.0, 1.0),
                                 imitation=((0.8, 0.3), (0.2, 0.9)), reached=reached, rollout_length=(5, 5),
                                 demo_length=(5.0, 5.0))
    return FitRow(task.id, "bc", planned.config_hash, seed, "offline", to_json(diagnostics))


@pytest.fixture
def small_store(tmp_path):
    """BC's default configuration on MiniGrid-Optimal at 3 seeds: near the paper at 10 %, far below it at 30 %
    (paper 0.93 ± 0.20); one seed's policies reach both goals, one reaches one, one none."""
    task = make_task(OPTIMAL)
    planned = plan(task, RecognizerSpec("bc"), task.make_env(task.goals[0]).action_space)
    path = tmp_path / "store.sqlite"
    with ResultsStore(path) as store:
        store.add([result_row(task, planned, seed, 0.1, f1) for seed, f1 in enumerate((0.7, 0.75, 0.8))]
                  + [result_row(task, planned, seed, 0.3, f1) for seed, f1 in enumerate((0.6, 0.5, 0.4))]
                  + [result_row(task, planned, seed, 0.3, 0.0, "another-config") for seed in range(3)]
                  + [fit_row(task, planned, seed, reached)
                     for seed, reached in enumerate(((True, True), (True, False), (False, False)))])
    return path


def test_causes_lists_the_cells_below_the_paper_with_their_evidence(small_store):
    result = study("causes", "--store", str(small_store), "-t", OPTIMAL, "--samples", "200")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("| cell | ours | paper | pairs-only ceiling |")
    assert lines[1] == "|---|---|---|---|---|---|---|"
    # Mean 0.50 (the other configuration's rows ignored); the exact pairs-only ceiling at 30 %: 1.00; goals
    # reached 3 of 6; seed 0 reaches every goal (0.60), seeds 1 and 2 do not (0.45); own / other 0.85 / 0.25.
    assert lines[2:] == ["| Optimal 30% bc | 0.50 | 0.93 ± 0.20 | 1.00 | 0.50 | 0.60 (1) / 0.45 (2) | 0.85 / 0.25 |"]


def test_readings_reads_each_route_and_rounding(tmp_path):
    result = study("readings", "-t", OPTIMAL, "--samples", "200")
    assert result.exit_code == 0, result.output
    rows = {line.split(" | ")[0].lstrip("| "): line for line in result.stdout.splitlines()[2:]}
    assert list(rows) == [f"{route}, {rounding}" for route in ("uniform", "fixed", "turn-first", "mixed")
                          for rounding in ("ceil", "floor")]
    # Two goals, uniform routes: the exact pairs-only ceilings; no paper cell above them.
    assert rows["uniform, ceil"] == "| uniform, ceil | 0.97 / 0.99 / 1.00 | 0 of 12 |"
    assert rows["uniform, floor"] == "| uniform, floor | 0.89 / 0.97 / 0.99 | 0 of 12 |"


def test_off_route_scores_each_hand_built_policy():
    result = study("off-route", "-t", OPTIMAL, "--seeds", "1")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0] == "| task | policy | F1 at each level (1 seeds) |"
    assert [line.split(" | ")[1] for line in lines[2:]] == list(off_route.VARIANTS)
    for line in lines[2:]:
        levels = line.split(" | ")[2].rstrip(" |").split(" / ")
        assert [level.split(": ")[0] for level in levels] == ["10%", "20%", "30%"]
        assert all(0 <= float(level.split(": ")[1]) <= 1 for level in levels)
    assert result.stdout == off_route.run([OPTIMAL], seeds=1)  # the registration is the study's alone


def test_list_names_every_study():
    for args in (["--list"], []):
        result = study(*args)
        assert result.exit_code == 0
        assert all(name in result.stdout for name in STUDIES)


@pytest.mark.parametrize("args, message", [
    (["nope"], "unknown study 'nope'; choose one of causes, off-route, readings"),
    (["causes", "--store", "/nonexistent/results.sqlite"], "no results store at /nonexistent/results.sqlite"),
    (["causes", "-t", "GRAIL/MiniGrid-Biased-v0", "--store", "STORE"], "study causes covers"),
    (["readings", "--store", "STORE"], "study readings takes no --store"),
    (["readings", "--seeds", "3"], "study readings takes no --seeds"),
    (["off-route"], "study off-route needs --task"),
    (["off-route", "-t", "GRAIL/PandaReach-Optimal-v0"], "builds MiniGrid policies"),
])
def test_bad_input_is_one_line_and_exit_2(args, message, small_store):
    result = study(*[str(small_store) if a == "STORE" else a for a in args])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], result.stderr


def test_a_corrupt_store_is_one_line_and_untouched(tmp_path):
    store = tmp_path / "store.sqlite"
    store.write_bytes(b"garbage" * 500)
    result = study("causes", "--store", str(store))
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error:") and "results store" in lines[0]
    assert store.read_bytes() == b"garbage" * 500


PROFILE = """seeds = 1
[[section]]
name = "floor"
tasks = ["GRAIL/MiniGrid-Optimal-v0"]
recognizers = ["bc"]
"""


@pytest.mark.parametrize("extra, observation", [
    ("", ("subset", "ceil", 0.0, "pairs", "subset")),
    ('protocol = "prefix"\nrounding = "floor"\n', ("prefix", "floor", 0.0, "pairs", "prefix+floor")),
    ('rounding = "floor"\n', ("subset", "floor", 0.0, "pairs", "subset+floor")),
    ('noise = 0.2\n', ("subset", "ceil", 0.2, "pairs", "subset+noise0.2")),
    ('channel = "actions"\n', ("subset", "ceil", 0.0, "actions", "subset+actions")),
])
def test_profile_sections_carry_a_protocol_rounding_and_observation_model(tmp_path, extra, observation):
    path = tmp_path / "p.toml"
    path.write_text(PROFILE + extra)
    (request,) = load_profile(str(path)).requests()
    spec = request.observation
    assert (spec.protocol, spec.rounding, spec.noise, spec.channel, spec.label) == observation


@pytest.mark.parametrize("extra, message", [
    ('rounding = "half"\n', "section 'floor': unknown rounding 'half'"),
    ('protocol = "middle"\n', "section 'floor': unknown observation protocol 'middle'"),
    ("protocol = 3\n", "protocol must be a name"),
    ("noise = 2\n", "section 'floor': noise 2 must be a share of the observed steps in [0, 1]"),
    ('channel = "pixels"\n', "section 'floor': "),
])
def test_a_bad_section_protocol_or_rounding_is_one_line(tmp_path, extra, message):
    path = tmp_path / "p.toml"
    path.write_text(PROFILE + extra)
    result = CliRunner().invoke(app, ["reproduce", "--profile", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and message in result.stderr and len(result.stderr.strip().splitlines()) == 1


NAMED = """seeds = 1
[tasks]
rooms = ["GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Biased-v0"]
[[section]]
name = "subset"
protocol = "subset"
tasks = "rooms"
recognizers = ["bc"]
[[section]]
name = "prefix"
tasks = "rooms"
recognizers = ["bc"]
protocol = "prefix"
"""


def test_sections_share_a_named_task_list(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text(NAMED)
    requests = load_profile(str(path)).requests()
    assert [(r.task_id, r.observation.protocol) for r in requests] == [
        ("GRAIL/MiniGrid-Optimal-v0", "subset"), ("GRAIL/MiniGrid-Biased-v0", "subset"),
        ("GRAIL/MiniGrid-Optimal-v0", "prefix"), ("GRAIL/MiniGrid-Biased-v0", "prefix")]


@pytest.mark.parametrize("text, message", [
    (NAMED.replace('"rooms"\nrecognizers = ["bc"]\nprotocol', '"halls"\nrecognizers = ["bc"]\nprotocol'),
     "section 'prefix' names the task list 'halls', which its [tasks] table lacks (it has rooms)"),
    (NAMED.replace('rooms = [', 'rooms = 3 #'), "[tasks] must map a name to a list of task IDs"),
])
def test_a_missing_or_malformed_task_list_is_one_line(tmp_path, text, message):
    path = tmp_path / "p.toml"
    path.write_text(text)
    result = CliRunner().invoke(app, ["reproduce", "--profile", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "results.sqlite").exists()
