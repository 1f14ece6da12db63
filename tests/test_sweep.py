"""Parallel sweeps: identical rows on every executor, lost workers, the shared model cache, `reproduce`."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import sqlite3
import time

import numpy as np
import pytest
from conftest import install_plugin
from test_cli import cli

from grail_bench.core.errors import UserError
from grail_bench.harness.executors import make_executor
from grail_bench.harness.planning import RecognizerSpec
from grail_bench.harness.store import OnlineRow, OpenSetRow, ResultsStore
from grail_bench.harness.sweep import Request, plan_request, plan_sweep, run_sweep
from grail_bench.report.reproduce import load_profile
from grail_bench.task.observation import ObservationSpec

TASK_ID = "GRAIL/MiniGrid-Biased-v0"
TIMING = {"fit_seconds_per_goal", "score_us_per_observation", "versions", "provenance"}
SPECS = (RecognizerSpec("bc", {"n_epochs": 3}, ("mse", "kl")), RecognizerSpec("graql", {"episodes": 200}))


def request(seeds=(0, 1)) -> Request:
    return Request(TASK_ID, SPECS, tuple(seeds), ObservationSpec("prefix", "ceil", (0.2, 0.4)))


def comparable(store: ResultsStore) -> list[tuple]:
    """Every stored row without its timings and provenance: what must not depend on where a unit ran."""
    return [tuple(v for k, v in dataclasses.asdict(r).items() if k not in TIMING) for r in store.rows()]


@pytest.mark.slow
def test_serial_local_and_ray_store_identical_rows(tmp_path, monkeypatch):
    results = {}
    for name, workers in (("serial", None), ("local", 2), ("ray", 2)):
        monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / f"cache-{name}"))  # every executor trains afresh
        store = ResultsStore(tmp_path / f"{name}.sqlite")
        executor = make_executor(name, workers)
        try:
            summary = run_sweep([request()], store, executor)
        finally:
            executor.close()
        assert summary.units == 4 and summary.rows == 2 * 2 * (2 + 1)  # seeds x levels x (bc: 2 scorers, graql: 1)
        results[name] = comparable(store)
    assert results["serial"] == results["local"] == results["ray"]


def test_finished_units_are_not_run_again(tmp_path):
    store = ResultsStore(tmp_path / "s.sqlite")
    run_sweep([request(seeds=(0,))], store)
    _, todo, skipped = plan_request(request(seeds=(0, 1)), store)
    assert skipped == 2 and {(u.planned.spec.name, u.seed) for u in todo} == {("bc", 1), ("graql", 1)}
    summary = run_sweep([request(seeds=(0,))], store)
    assert (summary.units, summary.skipped, summary.rows) == (2, 2, 0)


def test_models_shared_across_goal_sets_are_trained_once(tmp_path, monkeypatch):
    """GRAQL ignores demonstrations: the 4-goal task reuses the 2-goal task's tables for their shared goals."""
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / "cache"))  # counts from an empty cache
    store = ResultsStore(tmp_path / "s.sqlite")
    spec = (RecognizerSpec("graql", {"episodes": 100}),)
    small = Request("GRAIL/MiniGrid-Optimal-v0", spec, (0,), ObservationSpec("subset", "ceil", (0.3,)))
    large = Request("GRAIL/MiniGrid-Optimal-4Goals-v0", spec, (0,), ObservationSpec("subset", "ceil", (0.3,)))
    summary = run_sweep([small, large], store)
    assert (summary.trained, summary.reused, summary.naive) == (4, 2, 6)


def test_a_seed_starts_with_one_unit_of_each_group_that_shares_models(tmp_path):
    """Two workers should start by training different models, not one waiting for the other's: DRACO on three
    regimes of one goal set trains on the first and reuses on the others."""
    specs = (RecognizerSpec("draco", {"ppo_steps": 64}), RecognizerSpec("draco", {"algorithm": "sac", "sac_steps": 64}))
    tasks = ("GRAIL/PandaReach-Aligned-Optimal-v0", "GRAIL/PandaReach-Gaussian-0.1-v0",
             "GRAIL/PandaReach-Aligned-Gaussian-0.1-v0")
    requests = [Request(t, specs, (0, 1), ObservationSpec("subset", "ceil", (0.02,))) for t in tasks]
    units, _ = plan_sweep(requests, ResultsStore(tmp_path / "s.sqlite"))
    order = [(u.seed, u.task.id.removeprefix("GRAIL/PandaReach-"), json.loads(u.planned.config)["config"]["algorithm"])
             for u in units]
    assert order == [(s, t, a) for s in (0, 1) for t, a in [
        ("Aligned-Gaussian-0.1-v0", "ppo"), ("Aligned-Gaussian-0.1-v0", "sac"),  # each goal set and algorithm
        ("Gaussian-0.1-v0", "ppo"), ("Gaussian-0.1-v0", "sac"),                  # trains first,
        ("Aligned-Optimal-v0", "ppo"), ("Aligned-Optimal-v0", "sac")]]           # then its models are reused


def test_two_workers_start_on_different_demonstrations(tmp_path):
    """With two workers, units take turns between two tasks' demonstrations (PandaReach caches them: a worker
    asking for the ones another is generating waits), keeping the model groups' order: each goal set and
    algorithm still trains first."""
    specs = (RecognizerSpec("draco", {"ppo_steps": 64}), RecognizerSpec("draco", {"algorithm": "sac", "sac_steps": 64}))
    tasks = ("GRAIL/PandaReach-Aligned-Optimal-v0", "GRAIL/PandaReach-Gaussian-0.1-v0",
             "GRAIL/PandaReach-Aligned-Gaussian-0.1-v0", "GRAIL/PandaReach-Gaussian-0.3-v0")
    requests = [Request(t, specs, (0,), ObservationSpec("subset", "ceil", (0.02,))) for t in tasks]
    store = ResultsStore(tmp_path / "s.sqlite")
    units, _ = plan_sweep(requests, store, workers=2)
    order = [(u.task.id.removeprefix("GRAIL/PandaReach-"), json.loads(u.planned.config)["config"]["algorithm"])
             for u in units]
    assert order == [("Aligned-Gaussian-0.1-v0", "ppo"), ("Gaussian-0.1-v0", "ppo"),  # firsts of each group,
                     ("Aligned-Gaussian-0.1-v0", "sac"), ("Gaussian-0.1-v0", "sac"),  # two tasks in turn
                     ("Aligned-Optimal-v0", "ppo"), ("Gaussian-0.3-v0", "ppo"),
                     ("Aligned-Optimal-v0", "sac"), ("Gaussian-0.3-v0", "sac")]
    one_worker = plan_sweep(requests, store)[0]
    assert sorted((u.describe(), u.planned.config) for u in units) == \
        sorted((u.describe(), u.planned.config) for u in one_worker), "the same units, in another order"


def test_a_lost_worker_loses_only_its_units_and_the_rerun_completes(tmp_path):
    site = install_plugin(tmp_path / "site")
    marker = tmp_path / "crashed"
    args = ["run", "-r", "toy", "--set", f"toy.crash_marker={marker}", "--seeds", "4", "-o", "0.2,0.4",
            "--workers", "2", "--no-progress"]
    first = cli(args, tmp_path, PYTHONPATH=str(site))
    assert first.returncode == 1 and marker.exists()
    assert first.stderr.strip().splitlines()[-1].startswith("error: a worker process died")
    with sqlite3.connect(tmp_path / "store.sqlite") as db:  # the worker may die before any row creates the tables
        made = db.execute("SELECT COUNT(*) FROM sqlite_master WHERE name = 'results'").fetchone()[0]
        kept = db.execute("SELECT COUNT(*) FROM results WHERE seed = 1").fetchone()[0] if made else 0
    assert kept == 0, "the unit that died stored nothing"
    second = cli(args, tmp_path, PYTHONPATH=str(site))
    assert second.returncode == 0, second.stderr
    with sqlite3.connect(tmp_path / "store.sqlite") as db:
        rows = db.execute("SELECT seed, observability FROM results ORDER BY seed, observability").fetchall()
    assert rows == [(s, lv) for s in range(4) for lv in (0.2, 0.4)], "every cell once: none lost, none doubled"


def _train_slowly(root: str, log: str) -> list[float]:
    """Ask the cache for one model; training takes a while and leaves a line in ``log``."""
    import pathlib

    import torch

    from grail_bench.core.cache import cached_state_dict

    def train():
        with open(log, "a") as fh:
            fh.write("trained\n")
        time.sleep(1.5)
        return {"w": torch.arange(4.0)}

    state, _ = cached_state_dict("race", {"goal": [1, 2]}, train, root=pathlib.Path(root))
    return state["w"].tolist()


def test_two_processes_asking_for_one_model_train_it_once(tmp_path):
    log = tmp_path / "log"
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        got = pool.starmap(_train_slowly, [(str(tmp_path), str(log))] * 2)
    assert got == [[0.0, 1.0, 2.0, 3.0]] * 2
    assert log.read_text().count("trained") == 1, "the second process waited and reused the first one's model"
    folder = tmp_path / "race"
    assert sorted(p.suffix for p in folder.iterdir() if p.suffix != ".lock") == [".json", ".pt"]
    meta = json.loads(next(folder.glob("*.json")).read_text())
    assert meta["key"] == {"goal": [1, 2]}


@pytest.mark.parametrize("args, message", [
    (["--executor", "threads"], "unknown executor 'threads'"),
    (["--workers", "0"], "--workers must be at least 1"),
    (["--workers", "100000"], "--workers 100000 is more processes than this machine's"),
    (["--executor", "ray", "--workers", "100000"], "--workers 100000 is more processes than this machine's"),
    (["--executor", "ray", "--address", "127.0.0.1:1"], "cannot reach a Ray cluster at 127.0.0.1:1"),
    (["--executor", "serial", "--workers", "2"], "the serial executor runs one unit at a time"),
    (["--address", "127.0.0.1:1", "--executor", "local"], "--address names a Ray cluster"),
])
def test_bad_executor_options_are_one_line_errors(tmp_path, args, message):
    out = cli(["run", "-r", "bc", "--seeds", "1", "--no-progress", *args], tmp_path)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [f"error: {out.stderr.strip().removeprefix('error: ')}"]
    assert message in out.stderr
    assert not (tmp_path / "store.sqlite").exists(), "a refused run leaves no store behind"


def test_make_executor_defaults():
    assert make_executor().name == "serial"
    with pytest.raises(UserError, match="unknown executor"):
        make_executor("dask")


BUDGETS = """
seeds = 2
[config.bc]
n_epochs = 3
[config.graql]
episodes = 200
"""
# BC at its default budget (canonical, so its boards sit beside the paper's values), GRAQL reduced (a variant).
PROFILE = """description = "a reduced grid for tests"
seeds = 2
[config.graql]
episodes = 200

[[section]]
name = "minigrid"
tasks = ["GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Biased-v0"]
recognizers = ["bc", "graql"]
scorers = ["mse", "kl"]
[[section]]
name = "panda"
tasks = ["GRAIL/PandaReach-Optimal-v0", "GRAIL/PandaReach-Gaussian-0.1-v0"]
recognizers = ["bc"]
scorers = ["mse", "wasserstein"]
params = { expert = "scripted", n_demos = 8, n_train = 6 }
"""


@pytest.mark.slow
def test_reproduce_writes_every_table_figure_and_the_manifest(tmp_path):
    profile = tmp_path / "tiny.toml"
    profile.write_text(PROFILE)
    out = tmp_path / "out"
    result = cli(["reproduce", "--profile", str(profile), "--out", str(out), "--workers", "2", "--no-progress"],
                 tmp_path)
    assert result.returncode == 0, result.stderr
    tables = (out / "TABLES.md").read_text()
    for title in ("## minigrid / optimal (subset)", "## minigrid / biased (prefix)",
                  "## panda_reach / optimal (subset)"):
        assert title in tables
    assert "BC-GRAIL *(paper)*" in tables and "Against the paper's 95 % intervals" in tables
    assert "GRAQL · episodes 200" in tables
    for stem in ("f1_vs_observability", "panda_regimes", "scoring_time", "training_time", "model_size"):
        assert (out / f"{stem}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert (out / f"{stem}.svg").read_text().lstrip().startswith("<?xml")
    pages = "".join(p.read_text() for p in sorted((out / "site").glob("*.html")))  # the index, a page per domain
    assert pages.count('class="cell') == len(json.loads((out / "site" / "records.json").read_text())) > 0
    assert "reproduce --profile" in pages  # each cell's run, with its command line
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["executor"] == "local" and manifest["workers"] == 2 and manifest["cores"] >= 1
    assert manifest["packages"]["torch"].startswith("2.13.0") and manifest["command"][1:3] == ["reproduce", "--profile"]
    assert manifest["sweep"]["units"] == (2 * 2 + 2 * 1) * 2 and manifest["sweep"]["models trained"] > 0
    # Everything is stored: a second call runs nothing and writes the same tables.
    again = cli(["reproduce", "--profile", str(profile), "--out", str(out), "--no-progress"], tmp_path)
    assert again.returncode == 0 and json.loads((out / "manifest.json").read_text())["sweep"]["rows"] == 0
    assert (out / "TABLES.md").read_text() == tables
    assert "".join(p.read_text() for p in sorted((out / "site").glob("*.html"))) == pages


STUDIES = BUDGETS + """
[[section]]
name = "online"
mode = "online"
tasks = ["GRAIL/MiniGrid-Biased-v0"]
recognizers = ["bc", "graql"]
[[section]]
name = "open-set"
mode = "open-set"
tasks = ["GRAIL/MiniGrid-Optimal-4Goals-v0"]
recognizers = ["bc"]
"""


def test_reproduce_runs_the_online_and_open_set_sections(tmp_path):
    profile = tmp_path / "studies.toml"
    profile.write_text(STUDIES)
    out = tmp_path / "out"
    result = cli(["reproduce", "--profile", str(profile), "--out", str(out), "--no-progress"], tmp_path)
    assert result.returncode == 0, result.stderr
    with ResultsStore(out / "results.sqlite") as store:
        assert len(store.select(OnlineRow)) == 2 * 2 and len(store.select(OpenSetRow)) == 2 * 3  # 3 levels
        assert store.rows() == []
    online, open_set = (out / "ONLINE.md").read_text(), (out / "OPEN_SET.md").read_text()
    assert "| MiniGrid-Biased-v0 | prefix | bc/mse | 2 |" in online and "graql/kl" in online
    assert "| MiniGrid-Optimal-4Goals-v0 | subset | 30% | bc/mse | 2 |" in open_set
    assert (out / "online.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (out / "TABLES.md").exists()  # no section of the paper's protocol
    page = (out / "site" / "index.html").read_text()
    assert 'id="online"' in page and 'id="open-set"' in page
    only = cli(["reproduce", "--profile", str(profile), "--only", "online", "--out", str(tmp_path / "o2"),
                "--store", str(out / "results.sqlite"), "--no-progress"], tmp_path)
    assert only.returncode == 0 and not (tmp_path / "o2" / "OPEN_SET.md").exists()
    # --no-run writes the same tables from the store, running nothing
    again = cli(["reproduce", "--profile", str(profile), "--out", str(tmp_path / "o3"), "--store",
                 str(out / "results.sqlite"), "--no-run", "--no-progress"], tmp_path)
    assert again.returncode == 0 and "0 not run" in again.stdout
    assert (tmp_path / "o3" / "ONLINE.md").read_text() == online


def test_reproduce_no_run_counts_the_missing_units_and_runs_none(tmp_path):
    profile = tmp_path / "studies.toml"
    profile.write_text(STUDIES)
    out = tmp_path / "out"
    result = cli(["reproduce", "--profile", str(profile), "--out", str(out), "--no-run", "--no-progress"], tmp_path)
    assert result.returncode == 0, result.stderr
    sweep = json.loads((out / "manifest.json").read_text())["sweep"]
    assert f"{sweep['units']} not run (--no-run)" in result.stdout and sweep["units"] > 0
    with ResultsStore(out / "results.sqlite") as store:
        assert store.select(OnlineRow) == [] and store.select(OpenSetRow) == [] and store.rows() == []


@pytest.mark.parametrize("args, message", [
    (["--profile", "huge"], "unknown profile 'huge'"),
    (["--profile", "quick", "--only", "atari"], "profile 'quick' has no section 'atari'"),
    (["--profile", "paper", "--only", "panda-sac", "-r", "gail"],
     "no section of profile 'paper' chosen runs recognizer 'gail'; they run draco"),
    (["--profile", "quick", "--seeds", "0"], "need at least one seed, got 0"),
])
def test_reproduce_bad_input_is_one_line(tmp_path, args, message):
    out = cli(["reproduce", "--out", str(tmp_path / "o"), *args], tmp_path)
    assert out.returncode == 2 and message in out.stderr and len(out.stderr.strip().splitlines()) == 1


# The paper profile's budget studies: tasks x values x 5 seeds (BC epochs, GRAQL episodes, GAIL and AIRL steps,
# BC demonstrations and DRACO's PPO steps on MiniGrid; DRACO's PPO and SAC steps and BC demonstrations on one
# PandaReach task).
BUDGET_UNITS = (2 * 6 + 2 * 5 + 2 * 4 + 2 * 4 + 2 * 5 + 2 * 3 + 4 + 4 + 4) * 5


# Beyond the paper: 5 goal counts x 3 cheap and 2 adversarial methods x 5 seeds; zero-shot on 3 tasks x 10 seeds.
GOALS_UNITS = 5 * 3 * 5 + 5 * 2 * 5 + 3 * 10

# gr_libs' problems, both its protocols: 5 crossings, 8 maze and 3 parking tasks x (4, 2 and 2 methods, GC-DRACO
# and DRACO), x 10 seeds; its levels L1-L4, both protocols: 20 crossings x 3 methods, 32 maze tasks x 3 and 12 parking
# (subset only) x 2, x 10 seeds, 10 PandaReach tasks x (BC, GRAML, DRACO and DRACO clipped) x 10 seeds and
# 5 x (GC-DRACO and GC-GRAML) x 10, both; DRACO clipped on the 8 maze tasks x 10 seeds, both; symbolic: 8 tasks x
# 5 methods x 10 seeds missing and noisy, x 2 planners actions only, and the demonstrator on the 5 optimal and
# biased tasks; GC-DRACO's parking budget, 3 values x 3 seeds.
BREADTH_UNITS = (2 * (5 * 6 + 8 * 4 + 3 * 4) * 10 + 2 * (20 * 3 + 32 * 3) * 10 + 12 * 2 * 10 + 2 * 10 * 4 * 10
                 + 2 * 5 * 2 * 10 + 2 * 8 * 10 + 2 * 8 * 5 * 10 + 8 * 2 * 10 + 5 * 10 + 3 * 3)


# The open questions: 17 MiniGrid recognizer configurations (the paper's 4 methods, 3 under the occupancy scorer,
# 3 with off_support stay and 3 with uniform, BC with stay pairs, bip and grnet, the demonstrator) on the paper's
# 7 tasks at 4 slip levels and 2 moved-wall levels (their unshifted level is the slip sweep's first, run once), on
# 10 tasks (with the 3 Boltzmann ones) under 3 test regimes less the 6 where a task meets its own regime unshifted
# (again the slip sweep's first level), and on the 3 2-goal tasks under the biased regime; 15 PointMaze
# configurations on 2 maps at 4 actuator scales; 10 seeds each.
OPEN_QUESTIONS_UNITS = (17 * (7 * 4 + 7 * 2 + (10 * 3 - 6) + 3) + 15 * 2 * 4) * 10


@pytest.mark.parametrize("name, units", [("quick", 7 * 4 * 2 + 10 * 4 * 2 + 4 * 2 + 4 * 2 + 2),
                                         ("paper", 7 * 4 * 10 + 10 * 4 * 10 + 10 * 10 + 7 * 10 + 7 * 4 * 10 + 4 * 4 * 10
                                          + BUDGET_UNITS + GOALS_UNITS),
                                         ("breadth", BREADTH_UNITS),
                                         ("open-questions", OPEN_QUESTIONS_UNITS)])
def test_the_shipped_profiles_plan(tmp_path, name, units):
    with ResultsStore(tmp_path / "r.sqlite") as store:
        planned = [plan_request(r, store) for r in load_profile(name).requests()]
    assert sum(len(todo) for _, todo, _ in planned) == units


SHIFTS = """seeds = 2
[shifts]
slip = [{ test_slip = 0.0 }, { test_slip = 0.2 }]
[[section]]
name = "slip"
tasks = ["GRAIL/MiniGrid-Optimal-v0"]
recognizers = ["bc"]
vary = { shift = "slip" }
[[section]]
name = "regimes"
tasks = ["GRAIL/MiniGrid-Optimal-v0"]
recognizers = ["bc"]
vary = { shift = [{ test_regime = "optimal" }, { test_regime = "suboptimal" }] }
"""


def test_a_shift_sweep_runs_each_table_of_test_parameters_once_in_the_tables(tmp_path):
    """Each table of test parameters is a request of its own, shifted but for the unshifted first one; the
    unshifted task of both sweeps is one request; shift sweeps join the tables, not the budget studies."""
    path = tmp_path / "shifts.toml"
    path.write_text(SHIFTS)
    profile = load_profile(str(path))
    requests = profile.requests()
    assert [dict(r.task.test_params) for r in requests] == [{}, {"test_slip": 0.2}, {"test_regime": "suboptimal"}]
    assert profile.grid_requests() == requests and profile.studies() == []
    with ResultsStore(":memory:") as store:
        hashes = [plan_request(r, store)[0][0].config_hash for r in requests]
    assert len(set(hashes)) == 3  # the shifted tasks' rows are keyed apart from the task's own
    path.write_text(SHIFTS.replace('shift = "slip"', 'shift = "drift"'))
    with pytest.raises(UserError, match=r"names the shift list 'drift', which the profile's \[shifts\] table"):
        load_profile(str(path))
    path.write_text(SHIFTS.replace('shift = "slip"', "shift = [{ test_slip = 0.1 }]"))
    with pytest.raises(UserError, match="at least two tables of test parameters"):
        load_profile(str(path))


def test_reproduce_narrows_to_recognizers():
    """The paper's PandaReach sections for BC and DRACO alone: 10 tasks x 10 seeds of BC and of DRACO with each
    algorithm; and GAIL and AIRL at 3 seeds."""
    paper = load_profile("paper")
    narrowed = paper.requests(["panda", "panda-sac"], ["bc", "draco"])
    assert {s.name for r in narrowed for s in r.specs} == {"bc", "draco"}
    with ResultsStore(":memory:") as store:
        assert sum(len(plan_request(r, store)[1]) for r in narrowed) == 10 * 10 * 3
        assert sum(len(plan_request(r, store)[1]) for r in paper.requests(["panda", "panda-sac"])) == 10 * 10 * 5
        # --seeds: the first 3 seeds of GAIL and AIRL, in one sweep.
        adversarial = paper.requests(["panda"], ["gail", "airl"], seeds=3)
        assert {r.seeds for r in adversarial} == {(0, 1, 2)}
        assert sum(len(plan_request(r, store)[1]) for r in adversarial) == 10 * 3 * 2


SCALING = BUDGETS + """
[config.gc-bc]
n_batches = 100
[[section]]
name = "scaling"
tasks = ["GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Optimal-4Goals-v0"]
recognizers = ["bc", "gc-bc"]
observability = [0.3]
vary = { tasks = "n_goals" }
"""


def test_a_scaling_study_reports_f1_and_fit_cost_against_the_goal_count(tmp_path):
    profile = tmp_path / "scaling.toml"
    profile.write_text(SCALING)
    out = tmp_path / "out"
    result = cli(["reproduce", "--profile", str(profile), "--out", str(out), "--no-site", "--no-progress"], tmp_path)
    assert result.returncode == 0, result.stderr
    curves = {c["recognizer"]: c for c in json.loads((out / "budgets.json").read_text())}
    assert set(curves) == {"bc", "gc-bc"}
    for curve in curves.values():
        assert curve["param"] == "n_goals" and [p["value"] for p in curve["points"]] == [2, 4]
        assert all(p["n_seeds"] == 2 for p in curve["points"])
        sizes, costs = zip(*((p["value"], p["value"] * p["fit_seconds_per_goal"]) for p in curve["points"]))
        assert curve["exponent"] == pytest.approx(np.log(costs[1] / costs[0]) / np.log(sizes[1] / sizes[0]))
        assert "plateau" not in curve
    text = (out / "BUDGETS.md").read_text()
    assert "## bc: n_goals on MiniGrid-Optimal .. MiniGrid-Optimal-4Goals" in text and "Fit cost exponent: b =" in text
    assert (out / "budgets.png").exists() and not (out / "TABLES.md").exists()


def test_a_scaling_study_needs_two_tasks(tmp_path):
    profile = tmp_path / "bad.toml"
    profile.write_text(SCALING.replace('"GRAIL/MiniGrid-Optimal-v0", ', ""))
    out = cli(["reproduce", "--profile", str(profile), "--out", str(tmp_path / "o")], tmp_path)
    assert out.returncode == 2 and "varies its tasks; list two or more" in out.stderr


def test_a_profile_section_with_an_unknown_mode_is_one_line(tmp_path):
    profile = tmp_path / "bad.toml"
    profile.write_text(STUDIES.replace('mode = "online"', 'mode = "live"'))
    out = cli(["reproduce", "--profile", str(profile), "--out", str(tmp_path / "o")], tmp_path)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert "section 'online' has mode 'live'; choose one of offline, online, open-set" in out.stderr
