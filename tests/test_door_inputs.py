"""Every value a user supplies is bounded and checked where it enters; a broken input file or plugin is one line
naming it, never a traceback, and breaks nothing else.

Command-line cases exit 2 with one line and leave the store and folders as they were; their Python API twins
raise :class:`UserError`.
"""

from __future__ import annotations

import bz2
import importlib
import io
import logging
import os
import re
import subprocess
import sys
import tarfile
import textwrap
import time
from importlib.resources import files
from pathlib import Path

import gymnasium as gym
import pytest
from test_cli_inputs import invoke, refused, results, snapshot
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.core.bounds import Range, bounded_count
from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic import dataset
from grail_bench.domains.symbolic.dataset import load_problem, read_files, write_problem
from grail_bench.domains.symbolic.generator import builtin_problem
from grail_bench.domains.symbolic.problem_set import problem_set_tasks
from grail_bench.recognizers.registry import make_recognizer
from grail_bench.task import cards
from grail_bench.task.cards import CardError, load_cards, skipped_cards

TASK = "GRAIL/MiniGrid-Biased-v0"
SYMBOLIC = "GRAIL/Symbolic-Grid-Optimal-v0"
GOOD_CARD = textwrap.dedent("""\
    domain = "minigrid"
    [[task]]
    id = "GRAIL/Door-{name}-v0"
    regime = "optimal"
    goals = [[7, 1], [7, 7]]
    {extra}
    """)


def unchanged(tmp_path: Path, args: list[str], message: str) -> str:
    """Refuse ``args`` (exit 2, one line containing ``message``) with a store of results in ``tmp_path``, which
    is left exactly as it was."""
    store = results(tmp_path / "r.sqlite")
    before = snapshot(tmp_path)
    line = refused(args, store, message)
    assert snapshot(tmp_path) == before
    return line


# --- 1. sizes bounded where they enter ---------------------------------------------------------------------------


@pytest.mark.parametrize("args, message", [
    (["run", "--param", "n_demos=1000000000000"], "n_demos: 1000000000000 is out of range (allowed 2..10,000)"),
    (["run", "--param", "max_steps=1000000000000"], "env.max_steps: 1000000000000 is out of range (allowed 1..10,000)"),
    (["run", "--param", "size=3000"], "env.size: 3000 is out of range (allowed ..64)"),
    (["run", "--set", "bc.n_epochs=1e12"],
     "recognizer 'bc': n_epochs=1000000000000 is out of range (allowed 1..100,000)"),
    (["run", "-r", "gail", "--set", "gail.total_timesteps=1e15"], "total_timesteps=1000000000000000 is out of range"),
    (["run", "-r", "draco", "--set", "draco.net_arch=[64, 1000000]"], "net_arch=(64, 1000000) is out of range"),
    (["ceiling", "--samples", "2000000000"], "samples=2000000000 is out of range (allowed 2..1,000,000)"),
    (["ceiling", "--samples", "1"], "samples=1 is out of range (allowed 2..1,000,000)"),
    (["leaderboard", "--ceiling-samples", "2000000000"], "samples=2000000000 is out of range"),
    (["export", "--param", "size=100000", "--out", "OUT"], "env.size: 100000 is out of range"),
], ids=["n_demos", "max_steps", "size", "bc-epochs", "gail-steps", "net-arch", "ceiling-samples", "ceiling-one",
        "leaderboard-samples", "export-size"])
def test_a_size_beyond_its_bound_is_refused_before_any_work(tmp_path, args, message):
    args = [a.replace("OUT", str(tmp_path / "out")) for a in args]
    unchanged(tmp_path, args, message)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("make", [
    lambda: grail_bench.make_task(TASK, n_demos=10**12),
    lambda: grail_bench.make_task(TASK, size=3000),
    lambda: grail_bench.make_task("GRAIL/PandaReach-Optimal-v0", expert_steps=10**12),
    lambda: grail_bench.make_task("GRAIL/PointMaze-Biased-v0",
                                  maze=["#" * 99] + ["#" + "." * 97 + "#"] * 97 + ["#" * 99]),
    lambda: gym.make(TASK, max_steps=10**12),
    lambda: make_recognizer("bc", n_epochs=10**12),
    lambda: make_recognizer("graql", episodes=1e12),
    lambda: importlib.import_module("grail_bench.recognizers.bc").BCRecognizer(n_epochs=10**9),
    lambda: grail_bench.bayes_ceiling(grail_bench.make_task(TASK), "subset", 0.3, samples=2 * 10**9),
], ids=["n_demos", "size", "expert_steps", "maze", "gym.make", "bc", "graql", "constructor", "ceiling"])
def test_the_api_refuses_the_same_sizes_at_once(make):
    start = time.perf_counter()
    with pytest.raises(UserError, match="out of range"):
        make()
    assert time.perf_counter() - start < 5


def test_bounds_admit_every_published_configuration():
    """The cards' and leaderboard scripts' largest values pass (a bound must never refuse an existing run)."""
    grail_bench.make_task(TASK, size=13, max_steps=200, n_demos=200, n_train=150)
    make_recognizer("bc", n_epochs=400)
    make_recognizer("graql", episodes=50_000)
    make_recognizer("draco", ppo_steps=500_000)
    make_recognizer("draco", algorithm="sac", sac_steps=200_000)
    make_recognizer("gail", total_timesteps=160_000)


def test_range_reads_and_counts():
    assert str(Range(1, 10_000)) == "1..10,000" and str(Range(0.0, None)) == "0.0.."
    assert Range(1, 3).contains([1, 2, 3]) and not Range(1, 3).contains([1, 4]) and Range(1, 3).contains("x")
    assert bounded_count("samples", 1e3, 10**6) == 1000
    for bad in (0, 10**7, 2.5, True, "5", 10**400):
        with pytest.raises(UserError, match=r"samples must be an integer in 1\.\.1,000,000"):
            bounded_count("samples", bad, 10**6)


def test_a_card_bomb_is_refused_quickly(tmp_path):
    card = tmp_path / "bomb.toml"
    card.write_text(GOOD_CARD.format(name="Bomb", extra="env = { size = 100000 }"))
    start = time.perf_counter()
    with pytest.raises(CardError, match=r"bomb.toml: task\[0\].env.size: 100000 is out of range"):
        load_cards([card])
    assert time.perf_counter() - start < 2


def _zeros_bomb(path: Path, size: int, name: str = "domain.pddl") -> Path:
    """A .tar.bz2 of one member of ``size`` zero bytes, a few KB on disk: bzip2 streams of one compressed MiB of
    zeros, concatenated (a reader unpacks them as one stream)."""
    header = tarfile.TarInfo(name)
    header.size = size
    mib = bz2.compress(bytes(1 << 20))
    path.write_bytes(bz2.compress(header.tobuf(format=tarfile.GNU_FORMAT)) + mib * (size >> 20))
    return path


def test_an_archive_bomb_is_refused_before_unpacking(tmp_path):
    bomb = _zeros_bomb(tmp_path / "bomb.tar.bz2", 300 << 20)
    assert bomb.stat().st_size < 64_000
    start = time.perf_counter()
    with pytest.raises(UserError, match=r"bomb.tar.bz2 unpacks to more than 67,108,864 bytes"):
        read_files(bomb)
    assert time.perf_counter() - start < 2


def test_an_archive_of_too_many_members_or_too_large_a_stream_is_refused(tmp_path, monkeypatch):
    many = tmp_path / "many.tar.bz2"
    with tarfile.open(many, "w:bz2") as tar:
        for i in range(dataset.MAX_MEMBERS + 5):
            tar.addfile(tarfile.TarInfo(f"f{i}"), io.BytesIO(b""))
    with pytest.raises(UserError, match="many.tar.bz2 holds more than 1,000 members"):
        read_files(many)
    # the unpacked stream is cut off too, whatever the headers declare (here: a long name of 2 MiB)
    monkeypatch.setattr(dataset, "MAX_BYTES", 1 << 20)
    monkeypatch.setattr(dataset, "MAX_MEMBERS", 10)
    long_name = tmp_path / "long.tar.bz2"
    with tarfile.open(long_name, "w:bz2", format=tarfile.GNU_FORMAT) as tar:
        tar.addfile(tarfile.TarInfo("x" * (2 << 20)), io.BytesIO(b""))
    with pytest.raises(UserError, match="long.tar.bz2 unpacks to more than 1,048,576 bytes"):
        read_files(long_name)


def test_a_problem_past_the_grounding_limit_is_refused(monkeypatch):
    from grail_bench.domains.symbolic import grounding

    monkeypatch.setattr(grounding, "BINDING_LIMIT", 5)
    with pytest.raises(UserError, match="too large to ground: more than 5 parameter bindings"):
        _ = builtin_problem("grid").model  # a fresh problem: its model is grounded here
    monkeypatch.setattr(grounding, "BINDING_LIMIT", 10**6)
    monkeypatch.setattr(grounding, "OPERATOR_LIMIT", 20)
    with pytest.raises(UserError, match="too large to ground: more than 20 ground operators"):
        _ = builtin_problem("grid").model


def test_a_larger_grid_plans_fast_enough(tmp_path):
    """A 12x12 grid (144 fluents, 528 operators): planning and every plan's likelihood stay quick."""
    from grail_bench.domains.symbolic.generator import GRID_DOMAIN, _cell, _template
    from grail_bench.domains.symbolic.planner import optimal_plan_graph
    from grail_bench.domains.symbolic.problem import GRProblem

    n = 12
    cells = {(x, y) for y in range(n) for x in range(n)}
    init = [("robot-at", _cell(0, 0))] + [("adjacent", _cell(x, y), _cell(x + dx, y + dy)) for x, y in sorted(cells)
                                         for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)) if (x + dx, y + dy) in cells]
    objects = " ".join(_cell(x, y) for x, y in sorted(cells)) + " - cell"
    hyps = tuple((("robot-at", _cell(x, y)),) for x, y in ((n - 1, 0), (n - 1, n - 1)))
    problem = GRProblem("grid12", GRID_DOMAIN, _template("grid-12", "grid-navigation", objects, init), hyps,
                        hyps[0], ())
    start = time.perf_counter()
    model = load_problem(write_problem(problem, tmp_path / "grid12.tar.bz2")).model
    graph = optimal_plan_graph(model, model.goal_mask(hyps[1]))
    assert graph.length == 2 * (n - 1) and graph.n_plans == 705_432  # C(22, 11)
    assert time.perf_counter() - start < 20


# --- 2. a key given twice -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("args, message", [
    (["run", "--param", "size=9", "--param", "turn_prob=0.5", "--param", "size=11"],
     "--param size given more than once (size=9, size=11); give each parameter once"),
    (["run", "--set", "bc.n_epochs=9", "--set", "bc.n_epochs=11"],
     "--set bc.n_epochs given more than once (bc.n_epochs=9, bc.n_epochs=11); give each setting once"),
    (["ceiling", "--param", "route_choice=\"fixed\"", "--param", "route_choice=\"uniform\""],
     "--param route_choice given more than once"),
])
def test_a_key_given_twice_is_refused(tmp_path, args, message):
    unchanged(tmp_path, args, message)


def test_the_parsers_refuse_a_key_given_twice():
    from grail_bench.cli.inputs import params, settings

    with pytest.raises(UserError, match="--param n_demos given more than once"):
        params(["n_demos=20", "n_demos=30"])
    with pytest.raises(UserError, match="--set bc.n_epochs given more than once"):
        settings(["bc.n_epochs=1", "graql.episodes=5", "bc.n_epochs=2"], ["bc", "graql"])
    assert settings(["bc.n_epochs=1", "graql.n_epochs=2"], ["bc", "graql"]) == {"bc": {"n_epochs": 1},
                                                                                "graql": {"n_epochs": 2}}


# --- 3. a broken card or plugin breaks nothing else ----------------------------------------------------------------

BROKEN_CARDS = {
    "bad_toml.toml": ("domain = 'minigrid'\n[[task]\n".encode(), "invalid TOML"),
    "latin1.toml": (GOOD_CARD.format(name="Latin", extra='description = "caf\u00e9"').encode("latin-1"),
                    "not UTF-8 text"),
    "utf16.toml": (GOOD_CARD.format(name="Wide", extra="").encode("utf-16"), "not UTF-8 text"),
    "wrong_types.toml": (GOOD_CARD.format(name="Types", extra='n_demos = "ten"').encode(), "n_demos"),
    "tasks_not_tables.toml": (b'domain = "minigrid"\ntask = [1, 2]\n', "expected a [[task]] table"),
    "unknown_key.toml": (GOOD_CARD.format(name="Keys", extra="colour = 3").encode(), "unknown field"),
    "bomb.toml": (GOOD_CARD.format(name="Bomb", extra="env = { size = 100000 }").encode(), "out of range"),
    "twice.toml": (GOOD_CARD.format(name="Twice", extra="").replace("GRAIL/Door-Twice-v0", TASK).encode(),
                   "defined twice"),
}


def card_folder(root: Path) -> Path:
    """A copy of the card folder with every broken card of :data:`BROKEN_CARDS` and one good extra card."""
    root.mkdir(parents=True, exist_ok=True)
    for card in files("grail_bench.tasks").iterdir():
        if card.name.endswith(".toml"):
            (root / card.name).write_bytes(card.read_bytes())
    for name, (data, _) in BROKEN_CARDS.items():
        (root / name).write_bytes(data)
    (root / "zz_good.toml").write_text(GOOD_CARD.format(name="Good", extra=""), encoding="utf-8")
    (root / "__init__.py").write_text("")
    return root


@pytest.fixture
def broken_cards(tmp_path, monkeypatch):
    """The card folder with broken cards, read afresh in this process (and afresh again afterwards)."""
    folder = card_folder(tmp_path / "cards")
    registered = set(gym.registry)
    monkeypatch.setattr(cards, "files", lambda package: folder)
    cards._shipped_cards.cache_clear()
    yield folder
    cards._shipped_cards.cache_clear()
    for env_id in set(gym.registry) - registered:  # the extra card's tasks, registered by the commands
        del gym.registry[env_id]


def test_each_broken_card_is_skipped_with_one_warning_naming_it(broken_cards, caplog):
    with caplog.at_level(logging.WARNING, logger="grail_bench.task.cards"):
        tasks = {t.id for t in load_cards()}
        load_cards()  # parsed once: warned once
    assert TASK in tasks and "GRAIL/Door-Good-v0" in tasks
    assert not any(i.startswith(("GRAIL/Door-Bomb", "GRAIL/Door-Latin", "GRAIL/Door-Keys")) for i in tasks)
    skipped = skipped_cards()
    assert set(skipped) == set(BROKEN_CARDS)
    for name, (_, why) in BROKEN_CARDS.items():
        assert why in skipped[name], (name, skipped[name])
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == len(BROKEN_CARDS) and all("\n" not in line for line in lines)
    assert sorted(re.match(r"grail-bench: skipped the task card (\S+): ", line)[1] for line in lines) == \
        sorted(BROKEN_CARDS)


@pytest.mark.parametrize("command", [["tasks"], ["list", "tasks"]])
def test_grail_bench_tasks_lists_the_skipped_cards(broken_cards, tmp_path, command):
    code, output = invoke(command, tmp_path / "r.sqlite")
    assert code == 0, output
    for name in BROKEN_CARDS:
        assert f"skipped the broken task card {name}:" in output


def test_a_skipped_cards_task_is_unknown_and_the_error_says_why(broken_cards):
    with pytest.raises(UserError, match=r"unknown task 'GRAIL/Door-Bomb-v0'.*the broken task card\(s\) .*bomb.toml"):
        grail_bench.make_task("GRAIL/Door-Bomb-v0")


def fresh(code: str, folder: Path | None = None, path: Path | None = None) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter, with ``folder`` as the card folder and ``path`` on the import path."""
    patch = textwrap.dedent(f"""\
        import importlib.util, sys
        spec = importlib.util.spec_from_file_location(
            "grail_bench.tasks", {str(folder / "__init__.py")!r}, submodule_search_locations=[{str(folder)!r}])
        module = importlib.util.module_from_spec(spec)
        sys.modules["grail_bench.tasks"] = module
        spec.loader.exec_module(module)
        """) if folder is not None else ""
    paths = ([str(path)] if path is not None else []) + [str(Path(grail_bench.__file__).parents[1])]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths + [os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-c", patch + code], capture_output=True, text=True, timeout=120, env=env)


def plugins(root: Path, group: str, entries: dict[str, str], modules: dict[str, str]) -> Path:
    """An installed distribution under ``root`` declaring ``entries`` in ``group``, with ``modules``' code."""
    root.mkdir(parents=True, exist_ok=True)
    for name, code in modules.items():
        (root / f"{name}.py").write_text(code)
    dist = root / f"door_plugin_{root.name}-0.1.dist-info"
    dist.mkdir(exist_ok=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: door-plugin-{root.name}\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items()))
    return root


@pytest.fixture
def duplicate_domain(tmp_path):
    return plugins(tmp_path / "site", "grail_bench.domains", {"minigrid": "door_domain:DOMAIN"},
                   {"door_domain": "raise RuntimeError('never imported')\n"})


def test_import_gymnasium_stays_silent_with_a_broken_card_and_a_duplicate_domain(tmp_path, duplicate_domain):
    out = fresh("import gymnasium as gym\nassert 'grail_bench' not in sys.modules\n"
                "assert not any(i.startswith('GRAIL/') for i in gym.registry)\n",
                card_folder(tmp_path / "cards"), duplicate_domain)
    assert (out.returncode, out.stdout, out.stderr) == (0, "", "")


def test_other_tasks_are_made_with_a_broken_card_and_a_duplicate_domain(tmp_path, duplicate_domain):
    out = fresh("import gymnasium as gym\nenv = gym.make('grail_bench:GRAIL/MiniGrid-Biased-v0')\n"
                "import grail_bench\nassert 'GRAIL/Door-Good-v0' in grail_bench.task_ids()\n"
                "assert not any(i.startswith('GRAIL/Door-Bomb') for i in grail_bench.task_ids())\n"
                "env = gym.make('GRAIL/Door-Good-v0')\nprint('ok')\n",
                card_folder(tmp_path / "cards"), duplicate_domain)
    assert out.returncode == 0 and out.stdout == "ok\n", out.stderr
    lines = out.stderr.splitlines()
    assert len(lines) == len(BROKEN_CARDS) + 1, out.stderr
    assert sum("skipped the task card" in line for line in lines) == len(BROKEN_CARDS)
    assert sum("ignored the domain plugin minigrid = door_domain:DOMAIN" in line and "which is kept" in line
               for line in lines) == 1


def test_a_domain_plugin_reusing_a_builtin_name_keeps_the_builtin(duplicate_domain, monkeypatch, caplog):
    from grail_bench.task.domain import DOMAINS, get_domain

    monkeypatch.syspath_prepend(str(duplicate_domain))
    importlib.invalidate_caches()
    with caplog.at_level(logging.WARNING, logger="grail_bench.core.registry"):
        assert DOMAINS.targets()["minigrid"] != "door_domain:DOMAIN"
        assert type(get_domain("minigrid")).__module__ == "grail_bench.domains.minigrid"
        grail_bench.make_task(TASK, n_demos=12)
    assert all("ignored the domain plugin minigrid" in r.getMessage() for r in caplog.records)


@pytest.fixture
def broken_recognizers(tmp_path, monkeypatch):
    root = plugins(tmp_path / "recs", "grail_bench.recognizers",
                   {"boom": "door_boom:Recognizer", "ghost": "door_no_such_module:Recognizer",
                    "hollow": "door_hollow:Missing"},
                   {"door_boom": "raise RuntimeError('the plugin failed at import')\n", "door_hollow": "X = 1\n"})
    monkeypatch.syspath_prepend(str(root))
    importlib.invalidate_caches()
    return root


@pytest.mark.parametrize("name, why", [
    ("boom", "RuntimeError: the plugin failed at import"),
    ("ghost", "ModuleNotFoundError: No module named 'door_no_such_module'"),
    ("hollow", "AttributeError"),
])
def test_a_broken_recognizer_plugin_is_one_line_only_when_asked_for(broken_recognizers, tmp_path, name, why):
    with pytest.raises(UserError, match=f"the recognizer '{name}' \\(door_.*\\) cannot be loaded: {why}"):
        make_recognizer(name)
    assert make_recognizer("bc", n_epochs=1).config.n_epochs == 1
    line = unchanged(tmp_path, ["run", "-r", name], f"the recognizer '{name}'")
    assert "cannot be loaded" in line


def test_the_other_recognizers_list_and_run_beside_a_broken_plugin(broken_recognizers, tmp_path):
    code, output = invoke(["list", "recognizers"], tmp_path / "r.sqlite")
    assert code == 0 and "boom" in output and "graql" in output, output


# --- 4. files in another encoding, garbage archives ---------------------------------------------------------------


def _problem_folder(tmp_path: Path, name: str, encoding: str, file: str = "domain.pddl") -> Path:
    folder = write_problem(builtin_problem("grid"), tmp_path / name)
    text = (folder / file).read_text().replace("Grid navigation", "Grid navigation \u00e0 la carte")
    (folder / file).write_bytes(text.encode(encoding))
    return folder


@pytest.mark.parametrize("make, message", [
    (lambda p: _problem_folder(p, "latin1", "latin-1"), "latin1: domain.pddl is not UTF-8 text"),
    (lambda p: _problem_folder(p, "wide", "utf-16", "template.pddl"), "wide: template.pddl is not UTF-8 text"),
    (lambda p: (p / "garbage.tar.bz2").write_bytes(bytes(range(256)) * 20) and p / "garbage.tar.bz2",
     "garbage.tar.bz2 is not a readable tar archive"),
    (lambda p: (p / "cut.tar.bz2").write_bytes(
        write_problem(builtin_problem("grid"), p / "whole.tar.bz2").read_bytes()[:300]) and p / "cut.tar.bz2",
     "cut.tar.bz2 is not a readable tar archive"),
    (lambda p: _zip(p / "problem.zip"), "problem.zip is not a readable tar archive"),
], ids=["latin-1", "utf-16", "garbage", "truncated", "zip"])
def test_a_broken_problem_file_is_one_line_naming_it(tmp_path, make, message):
    problem = make(tmp_path)
    with pytest.raises(UserError, match=message):
        problem_set_tasks(problem)
    unchanged(tmp_path, ["run", "-t", str(problem), "-r", "landmarks"], message)


def _zip(path: Path) -> Path:
    import zipfile

    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("domain.pddl", "(define (domain d))")
    return path


def test_pddl_that_is_text_but_not_pddl_is_one_line(tmp_path):
    folder = write_problem(builtin_problem("grid"), tmp_path / "noise")
    (folder / "domain.pddl").write_text("(define (domain (((( noise ))) :: )")
    with pytest.raises(UserError, match="domain.pddl does not parse"):
        _ = load_problem(folder).model


# --- 5. adversarial methods and a variable horizon -----------------------------------------------------------------


@pytest.mark.parametrize("recognizer, task, overrides", [
    ("gail", TASK, {"fixed_horizon": False}),
    ("airl", TASK, {"fixed_horizon": False}),
    ("gail", SYMBOLIC, {}),
])
def test_adversarial_methods_refuse_episodes_that_end_early_where_the_run_is_planned(recognizer, task, overrides):
    with pytest.raises(UserError, match="GAIL and AIRL train on episodes of one fixed length"):
        make_recognizer(recognizer).check_task(grail_bench.make_task(task, **overrides))
    make_recognizer(recognizer).check_task(grail_bench.make_task(TASK))  # the published tasks: fixed horizons


def test_run_refuses_gail_on_a_variable_horizon_in_one_line(tmp_path):
    unchanged(tmp_path, ["run", "-r", "bc", "-r", "gail", "--param", "fixed_horizon=false"],
              "recognizer 'gail': GRAIL/MiniGrid-Biased-v0: episodes end at the goal or in lava")


# --- 6. a task's own export read back ------------------------------------------------------------------------------


@pytest.mark.parametrize("task_id", [TASK, "GRAIL/MiniGrid-Suboptimal-v1"])
def test_a_tasks_own_export_is_its_demonstrations(tmp_path, task_id):
    from grail_bench.task.export import export

    (path,) = export(grail_bench.make_task(task_id), [0], tmp_path / "datasets")
    task = grail_bench.make_task(task_id, demos=str(path))
    assert task.demos and task.n_demos == grail_bench.make_task(task_id).n_demos


def test_run_reads_the_biased_tasks_own_export(tmp_path):
    out = tmp_path / "datasets"
    code, output = invoke(["export", "-t", TASK, "--out", str(out)], tmp_path / "r.sqlite")
    assert code == 0, output
    (dataset_path,) = (out / "grail-bench").glob("MiniGrid-Biased-seed0-v0")
    result = CliRunner().invoke(app, ["run", "-t", TASK, "--demos", str(dataset_path), "-r", "bc", "--set",
                                      "bc.n_epochs=1", "--seeds", "1", "--no-progress", "--store",
                                      str(tmp_path / "r.sqlite")], env={"COLUMNS": "200"})
    assert result.exit_code == 0 and "results stored" in result.output, result.output
