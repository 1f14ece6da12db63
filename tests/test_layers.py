"""The structure the code promises: one-way layers, the minimal plugin contract, modes as one table."""

from __future__ import annotations

import ast
import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import install_plugin

import grail_bench
from grail_bench.harness import modes
from grail_bench.harness.modes.base import Column, Mode, Record, Run
from grail_bench.harness.store import ResultsStore
from grail_bench.recognizers import capabilities
from grail_bench.task.observation import observe

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def lint_imports(package_root: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(package_root)}
    return subprocess.run([str(BIN / "lint-imports"), "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
                          capture_output=True, text=True, cwd=package_root, env=env, timeout=300)


def test_the_layers_contracts_hold():
    """The package's layers point down, and the task layer has no import circle inside it."""
    out = lint_imports(ROOT)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "layers only point down KEPT" in out.stdout and "the task layer is acyclic KEPT" in out.stdout
    assert "0 broken" in out.stdout


def test_every_package_ships_in_the_wheel():
    """pyproject.toml lists its packages one by one: a package folder missing from the list would work in an
    editable install and be absent from a built wheel."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "grail_bench").rglob("__init__.py")}
    assert found - listed == set()


def test_an_upward_import_breaks_the_contract(tmp_path):
    shutil.copytree(ROOT / "grail_bench", tmp_path / "grail_bench", ignore=shutil.ignore_patterns("__pycache__"))
    errors = tmp_path / "grail_bench" / "core" / "errors.py"
    errors.write_text(errors.read_text() + "\nfrom grail_bench.report import boards  # noqa: E402, F401\n")
    out = lint_imports(tmp_path)
    assert out.returncode != 0
    assert "BROKEN" in out.stdout and "grail_bench.core.errors -> grail_bench.report.boards" in out.stdout


def test_no_private_name_is_imported_across_modules():
    offenders = []
    for path in (ROOT / "grail_bench").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("grail_bench"):
                offenders += [f"{path.relative_to(ROOT)}: {a.name}" for a in node.names
                              if a.name.startswith("_") and a.name != "__version__"]
    assert offenders == []


def test_a_minimal_plugin_runs_end_to_end_through_an_entry_point(tmp_path):
    site = install_plugin(tmp_path / "site", name="minimal", target="minimal_recognizer:NearestStart")
    env = {**os.environ, "PYTHONPATH": str(site), "GRAIL_BENCH_STORE": str(tmp_path / "r.sqlite"), "COLUMNS": "200"}

    def cli(*args):
        out = subprocess.run([str(BIN / "grail-bench"), *args], capture_output=True, text=True, env=env, timeout=600)
        assert out.returncode == 0, out.stderr
        return out.stdout

    task = "GRAIL/MiniGrid-Optimal-4Goals-v0"
    cli("run", "-t", task, "-r", "minimal", "--seeds", "2", "--no-progress", "--json", str(tmp_path / "r.json"))
    records = json.loads((tmp_path / "r.json").read_text())
    assert {r["recognizer"] for r in records} == {"minimal"} and all(0 <= r["f1_mean"] <= 1 for r in records)
    assert all(r["scorer"] == "default" for r in records)  # its own scoring
    cli("run", "-t", task, "-r", "minimal", "--seeds", "2", "--no-progress", "--online")
    cli("run", "-t", task, "-r", "minimal", "--seeds", "3", "--no-progress", "--open-set", "-o", "0.5")
    assert "minimal" in cli("leaderboard", "--markdown", str(tmp_path / "LB.md"))
    assert "minimal" in (tmp_path / "LB.md").read_text()
    assert "minimal" in cli("leaderboard", "--online")
    assert "minimal" in cli("leaderboard", "--open-set")
    cli("leaderboard", "--html", str(tmp_path / "site-out"), "--no-ceiling")
    assert "minimal" in (tmp_path / "site-out" / "index.html").read_text()
    with ResultsStore(tmp_path / "r.sqlite") as store:  # its config defaults to the constructor's keywords: none
        (row, *_) = store.rows()
        assert json.loads(row.config)["config"] == {}


def test_capabilities_default_what_a_recognizer_does_not_declare():
    class Minimal:
        def fit(self, demos, env_factory=None, *, seed=0):
            self.goals = list(demos)

        def score(self, observed):
            return {g: 0.0 for g in self.goals}

    caps = capabilities(Minimal(), "minimal", {"k": 1})
    assert caps.info.paper_name == "minimal" and caps.default_scorer == "default"
    assert caps.config == {"k": 1} and caps.exposes(None) == frozenset()
    assert not caps.takes_scorer and not caps.takes_cache_key and not caps.has_prefix_scores
    caps.fit({(1, 1): [], (2, 2): []}, None, seed=0, cache_key="ignored")  # fit is called without it
    assert caps.score_prefixes(None) is None and caps.diagnose({}, {}, None) is None
    with pytest.raises(grail_bench.UserError, match="scores with its own scoring only"):
        caps.score(None, "mse")


# --- modes as one table -------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class CountRow(Run):
    observability: float
    protocol: str
    n_test: int
    config: str
    versions: str
    provenance: str | None = None


@dataclasses.dataclass(frozen=True, kw_only=True)
class CountRecord(Record):
    n_test_mean: float


def _count_run(job):
    _, test = job.task.split(job.demos)
    n = sum(len(t) for t in test.values())
    return [CountRow(job.task.id, job.planned.name, s, job.planned.config_hash, job.seed, lv, job.observation.label,
                     n, job.planned.config, job.versions)
            for lv in job.observation.levels for s in job.planned.labels], None


def _count_aggregate(rows):
    rows = list(rows)
    return [CountRecord(task=rows[0].task, recognizer=rows[0].recognizer, scorer=rows[0].scorer,
                        protocol=rows[0].protocol, config_hash=rows[0].config_hash, n_seeds=len(rows),
                        seeds=[r.seed for r in rows], fit_seconds_per_goal=0.0,
                        n_test_mean=float(np.mean([r.n_test for r in rows])))] if rows else []


COUNT = Mode(name="count", row=CountRow, table="count_demos",
             key=("task", "recognizer", "scorer", "config_hash", "seed", "observability", "protocol"),
             run=_count_run, aggregate=_count_aggregate,
             columns=(Column("test demos", lambda r: f"{r.n_test_mean:.0f}", lambda r: r.n_test_mean),),
             title="test demonstrations", intro="How many test demonstrations each seed has.")


def test_a_new_mode_is_one_entry_in_the_registry(tmp_path, monkeypatch):
    from grail_bench.harness.api import evaluate
    from grail_bench.report.tables import mode_markdown

    assert list(modes.MODES) == ["offline", "online", "open-set", "zero-shot"]
    with pytest.raises(grail_bench.UserError, match="unknown mode 'count'"):
        modes.get_mode("count")
    modes.MODES.register("count", COUNT)
    try:
        with ResultsStore(tmp_path / "r.sqlite") as store:
            (record,) = evaluate("GRAIL/MiniGrid-Biased-v0", [("bc", {"n_epochs": 1})], seeds=2, mode="count",
                                 observability=[0.5], store=store)
            assert record.n_test_mean == 6 and record.n_seeds == 2
            assert len(store.select(COUNT)) == 2  # its own table, keyed by its key
    finally:
        modes.MODES.unregister("count")
    assert "| 6 |" in mode_markdown([record], COUNT)


def test_every_mode_has_a_table_in_the_store(tmp_path):
    import sqlite3

    from grail_bench.harness.diagnostics import FitRow

    with ResultsStore(tmp_path / "r.sqlite") as store:
        assert not (tmp_path / "r.sqlite").exists()  # created by the first rows written, not by opening
        store.add([FitRow("GRAIL/MiniGrid-Biased-v0", "bc", "h", 0, "offline", "{}")])
    tables = {r[0] for r in sqlite3.connect(tmp_path / "r.sqlite").execute("SELECT name FROM sqlite_master")}
    assert {m.table for m in modes.MODES.values()} <= tables


# --- inputs checked before the work starts ------------------------------------------------------------------


def _cli(tmp_path, *args, **env):
    full = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_STORE": str(tmp_path / "store.sqlite"), **env}
    return subprocess.run([str(BIN / "grail-bench"), *args], capture_output=True, text=True, env=full, timeout=600)


def _stored(tmp_path) -> int:
    import sqlite3

    path = tmp_path / "store.sqlite"
    return sqlite3.connect(path).execute("SELECT COUNT(*) FROM results").fetchone()[0] if path.exists() else 0


@pytest.fixture(scope="module")
def one_seed_stored(tmp_path_factory) -> Path:
    """A store holding one seed of BC, shared read-only by the cases below (each works on a copy)."""
    root = tmp_path_factory.mktemp("one-seed")
    first = _cli(root, "run", "-r", "bc", "--seeds", "1", "--set", "bc.n_epochs=1", "--no-progress")
    assert first.returncode == 0, first.stderr
    return root / "store.sqlite"


@pytest.mark.parametrize("args, message", [
    (["--set", "bc.n_epochs=abc"], "n_epochs expects an integer, got 'abc'"),
    (["--set", "bc.learning_rate=[1]"], "learning_rate expects a finite number, got [1]"),
    (["--json", "/proc/nope/r.json"], "cannot write the file /proc/nope/r.json"),
    (["--json", "."], "it is a folder"),
])
def test_bad_values_are_one_line_before_any_unit_runs(tmp_path, one_seed_stored, args, message):
    shutil.copy(one_seed_stored, tmp_path / "store.sqlite")
    before = _stored(tmp_path)
    assert before > 0
    out = _cli(tmp_path, "run", "-r", "bc", "--seeds", "2", "--no-progress", *args)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], out.stderr
    assert _stored(tmp_path) == before


def test_ctrl_c_says_how_many_units_were_kept(tmp_path):
    site = install_plugin(tmp_path / "site")
    # The toy recognizer's crash marker kills the process on seed 1; a KeyboardInterrupt is what Ctrl-C raises.
    code = ("import sys, grail_bench.harness.sweep as sweep\n"
            "real = sweep.run_unit\n"
            "def run_unit(unit):\n"
            "    if unit.seed == 2:\n"
            "        raise KeyboardInterrupt\n"
            "    return real(unit)\n"
            "sweep.run_unit = run_unit\n"
            "from grail_bench.cli import main\n"
            "sys.argv = ['grail-bench', 'run', '-r', 'toy', '--seeds', '4', '--no-progress']\n"
            "main()\n")
    env = {**os.environ, "PYTHONPATH": str(site), "GRAIL_BENCH_STORE": str(tmp_path / "store.sqlite")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 130, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "interrupted: 2 unit(s) of this run were kept in the store" in lines[0]
    assert "run the same command again to resume" in lines[0]
    assert _stored(tmp_path) == 2 * 3  # seeds 0 and 1, three levels each


@pytest.mark.parametrize("change, message", [
    (lambda o, a: (o.astype(float) + 0.5, a), "must be integers in MultiDiscrete"),
    (lambda o, a: (o + 20, a), "observed states lie outside the env's space MultiDiscrete"),
    (lambda o, a: (o, a + 7), "observed actions lie outside the env's space Discrete(4)"),
    (lambda o, a: (np.where(np.arange(o.size).reshape(o.shape) == 0, np.nan, o), a), "must be integers"),
    (lambda o, a: (o[:, :2], a), "observed states have shape (2,), the env's are (3,)"),
])
def test_observations_outside_the_spaces_are_user_errors(change, message):
    from grail_bench.recognizers import make_recognizer

    task = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
    train, test = task.split(task.generate_demos(0))
    for name in ("bc", "graql"):
        rec = make_recognizer(name, **({"n_epochs": 1} if name == "bc" else {"episodes": 10}))
        rec.fit(train, task.env_factory(), seed=0)
        good = observe(test[(7, 1)][0], 0.5)
        obs, acts = change(np.asarray(good.obs), np.asarray(good.acts))
        bad = type(good)(obs=obs, acts=acts, infos=None, terminal=False)
        with pytest.raises(grail_bench.UserError, match=message.replace("(", r"\(").replace(")", r"\)")):
            rec.score(bad)


def test_continuous_observations_outside_the_box_are_user_errors():
    from grail_bench.recognizers import make_recognizer

    task = grail_bench.make_task("GRAIL/PandaReach-Optimal-v0", expert="scripted", n_demos=3, n_train=2)
    train, test = task.split(task.generate_demos(0))
    rec = make_recognizer("bc", n_epochs=1)
    rec.fit(train, task.env_factory(), seed=0)
    good = observe(test[task.goals[0]][0], 0.2, "subset", np.random.default_rng(0))
    one_nan = good.obs.copy()
    one_nan[0, 0] = np.nan
    for obs, acts, message in ((one_nan, good.acts, "observed states lie outside"),
                               (np.full_like(good.obs, np.nan), good.acts,
                                "^this observation carries actions only; scoring it needs pairs$"),
                               (good.obs, good.acts + 5.0, "observed actions lie outside the env's space Box")):
        with pytest.raises(grail_bench.UserError, match=message):
            rec.score(type(good)(obs=obs, acts=acts, infos=None, terminal=False))
