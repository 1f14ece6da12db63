"""The run path end to end: what it builds, what it keys results by, and what it refuses before any training."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sqlite3
import sys
import time
import typing
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from grail_bench import UserError
from grail_bench.cli import app
from grail_bench.harness import published, sweep
from grail_bench.harness.api import evaluate, inspect_fit, request
from grail_bench.harness.planning import RecognizerSpec, plan, task_params
from grail_bench.harness.store import ResultsStore
from grail_bench.recognizers.contract import FitReport, settings_key
from grail_bench.recognizers.registry import RECOGNIZERS, make_recognizer, register_recognizer, unregister_recognizer
from grail_bench.task import GRTask, make_task
from grail_bench.task.observation import observe
from grail_bench.task.overrides import TaskOverrides
from grail_bench.task.registration import find_task

TASK = "GRAIL/MiniGrid-Biased-v0"
TINY_BC = ("bc", {"n_epochs": 1})
LEADERBOARD = Path(__file__).resolve().parents[1] / "leaderboard"
BUILTINS = ("bc", "gail", "airl", "draco", "graql", "gc-bc")
#: Where each built-in recognizer's default rows are published (GC-BC runs only in the goal-count study).
PUBLISHED = {"bc": "results", "gail": "results", "airl": "results", "draco": "results", "graql": "results",
             "gc-bc": "goals"}


def _count_calls(monkeypatch: pytest.MonkeyPatch, owner: type, name: str) -> list[None]:
    """Replace ``owner.name`` by a wrapper that counts its calls (``functools.wraps`` keeps its signature)."""
    calls: list[None] = []
    original = getattr(owner, name)

    @functools.wraps(original)
    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(None)
        return original(*args, **kwargs)

    monkeypatch.setattr(owner, name, counted)
    return calls


def _no_training(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make any unit that would run fail loudly, so a refusal is shown to come before the work."""

    def trained(unit: Any) -> Any:
        raise AssertionError(f"a unit ran: {unit.describe()}")

    monkeypatch.setattr(sweep, "run_unit", trained)


def _one_action_observation() -> Any:
    task = make_task(TASK, n_demos=2, n_train=1)
    traj = next(iter(task.generate_demos(0).values()))[0]
    return observe(traj, 0.3)


# --- what a run builds ---------------------------------------------------------------------------------------------


def test_evaluate_builds_the_task_once_and_the_recognizer_once_to_plan_and_once_per_unit(monkeypatch):
    from grail_bench.recognizers.bc import BCRecognizer

    make_task(TASK)  # the shipped cards are read (and built) once per process, before counting
    tasks = _count_calls(monkeypatch, GRTask, "__post_init__")
    recognizers = _count_calls(monkeypatch, BCRecognizer, "__init__")
    seeds = 2
    records = evaluate(TASK, [TINY_BC], seeds=seeds, observability=[0.3])
    assert len(records) == 1 and records[0].n_seeds == seeds
    assert len(tasks) == 1
    assert len(recognizers) == seeds + 1


def test_the_cli_run_path_builds_the_task_once(monkeypatch, tmp_path):
    make_task(TASK)
    cli_app = sys.modules["grail_bench.cli.app"]
    monkeypatch.setattr(cli_app, "_show", lambda *args: None)  # the report's own tasks (Bayes ceilings) are not the run's
    tasks = _count_calls(monkeypatch, GRTask, "__post_init__")
    result = CliRunner().invoke(app, ["run", "-t", TASK, "-r", "bc", "--set", "bc.n_epochs=1", "--seeds", "1",
                                      "-o", "0.3", "--store", str(tmp_path / "s.sqlite"), "--no-progress"])
    assert result.exit_code == 0, result.output
    assert len(tasks) == 1


def test_planning_a_clipped_run_reads_the_action_space_from_one_env(monkeypatch):
    task = make_task("GRAIL/PointMaze-Optimal-v0")
    envs = _count_calls(monkeypatch, GRTask, "make_env")
    plan(task, RecognizerSpec("draco", {"action_box": "clip"}), task.action_space())  # check_task reads it again
    assert len(envs) == 1


def test_task_overrides_round_trip_through_the_store(tmp_path):
    task_id, asked = "GRAIL/MiniGrid-Suboptimal-v1", {"turn_prob": 0.5}
    card = make_task(task_id)
    assert card.params["turn_prob"] != asked["turn_prob"]
    path = tmp_path / "s.sqlite"
    with ResultsStore(path) as store:
        evaluate(task_id, [TINY_BC], seeds=1, observability=[0.3], task_params=asked, store=store)
    with ResultsStore(path, read_only=True) as store:
        rows = store.rows(task=task_id)
    assert rows
    stored = TaskOverrides.of(task_params(rows[0].config))
    rebuilt = make_task(task_id, **stored.as_dict())
    assert rebuilt.overrides_against(card) == TaskOverrides.of(asked)


# --- typed settings -----------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _published_configs(store: str, recognizer: str) -> list[tuple[str, str, str]]:
    """The distinct (task, config hash, config) of a recognizer's published offline rows: from the published
    results (leaderboard/published) for the main store, from the SQLite file of a study's store otherwise."""
    if store == "results":
        rows = [r for path in sorted((LEADERBOARD / "published").glob("*/offline.jsonl*"))
                for r in published.read(path, check=False).rows.get("offline", []) if r.recognizer == recognizer]
        return sorted({(r.task, r.config_hash, r.config) for r in rows})
    con = sqlite3.connect(f"file:{LEADERBOARD / (store + '.sqlite')}?mode=ro", uri=True)
    try:
        return con.execute("SELECT DISTINCT task, config_hash, config FROM results WHERE recognizer = ? "
                           "ORDER BY task, config_hash", (recognizer,)).fetchall()
    finally:
        con.close()


@pytest.mark.parametrize("name", BUILTINS)
def test_default_settings_keep_the_published_keys(name):
    """The default Config's key is the ``config`` of published default rows whose hash today's planning reproduces."""
    default = settings_key(RECOGNIZERS.get(name).Config())
    reproduced = None
    for task_id, stored_hash, config in _published_configs(PUBLISHED[name], name):
        if json.loads(config)["config"] != default:
            continue
        task = find_task(task_id, task_params(config))
        if task is None:
            continue
        if plan(task, RecognizerSpec(name), task.action_space()).config_hash == stored_hash:
            reproduced = json.loads(config)["config"]
            break
    assert reproduced is not None, f"no published default row of {name} is reproduced by plan()"
    assert settings_key(make_recognizer(name).config) == default == reproduced


@pytest.mark.parametrize("name, field, value, choices", [
    ("gail", "update", "jax", "'numpy', 'torch'"),
    ("airl", "update", "cuda", "'numpy', 'torch'"),
    ("draco", "algorithm", "dqn", "'ppo', 'sac'"),
])
def test_a_literal_setting_refuses_an_unknown_value_naming_the_choices(name, field, value, choices):
    with pytest.raises(UserError) as err:
        make_recognizer(name, **{field: value})
    message = str(err.value)
    assert "\n" not in message and choices in message and repr(value) in message and field in message


def _another(config: Any, field: dataclasses.Field) -> Any:
    """A valid value of ``field`` other than its default."""
    hint = typing.get_type_hints(type(config))[field.name]
    current = getattr(config, field.name)
    if typing.get_origin(hint) is typing.Literal:
        return next(a for a in typing.get_args(hint) if a != current)
    if isinstance(current, bool):
        return not current
    if isinstance(current, int):
        return current + 1
    if isinstance(current, float):
        return current / 2
    if isinstance(current, tuple):
        return [*current, 8]
    if current is None:  # an optional budget or discount
        return 0.5 if float in typing.get_args(hint) else 7
    raise AssertionError(f"no other value for {field.name}")


@pytest.mark.parametrize("name", BUILTINS)
def test_configurations_that_differ_in_one_setting_hash_apart(name):
    # SAC (DRACO's algorithm) and action_box="clip" need continuous actions; GRAQL needs discrete ones.
    task = make_task(TASK if name == "graql" else "GRAIL/PointMaze-Optimal-v0")
    action_space = task.action_space()
    default = RECOGNIZERS.get(name).Config()
    hashes = {"default": plan(task, RecognizerSpec(name), action_space).config_hash}
    for field in dataclasses.fields(default):
        value = _another(default, field)
        if name == "draco" and field.name == "sac_steps":
            settings = {"algorithm": "sac", "sac_steps": value}  # a budget applies to its own algorithm only
        else:
            settings = {field.name: value}
        hashes[field.name] = plan(task, RecognizerSpec(name, settings), action_space).config_hash
    assert len(set(hashes.values())) == len(hashes), hashes


# --- fit may return anything ---------------------------------------------------------------------------------------


class _AnyReturn:
    """A third-party recognizer whose ``fit`` returns what it is told to; it always names the first goal."""

    def __init__(self, returning: str = "none") -> None:
        self.returning = returning
        self.goals: list = []

    def fit(self, demos, env_factory=None, *, seed=0):  # noqa: ANN001, ANN201 - a plugin's plain signature
        self.goals = list(demos)
        return {"none": None, "self": self, "dict": {"train_seconds": 1000.0},
                "report": FitReport(train_seconds=1000.0, trained=len(self.goals))}[self.returning]

    def score(self, observed):  # noqa: ANN001, ANN201
        return {g: float(i == 0) for i, g in enumerate(self.goals)}


@pytest.mark.parametrize("returning", ["none", "self", "dict", "report"])
def test_fit_may_return_anything_and_only_a_fit_report_is_read(returning):
    register_recognizer("any-return", _AnyReturn)
    try:
        records = evaluate(TASK, [("any-return", {"returning": returning})], seeds=1, observability=[0.3])
    finally:
        unregister_recognizer("any-return")
    assert len(records) == 1 and records[0].recognizer == "any-return"
    seconds = records[0].fit_seconds_per_goal
    if returning == "report":
        assert seconds == pytest.approx(1000.0 / len(make_task(TASK).goals))
    else:  # the harness timed the call
        assert seconds < 10


# --- inputs refused at the door ------------------------------------------------------------------------------------


def test_evaluate_takes_one_recognizer_name_as_a_string(monkeypatch, tmp_path):
    assert request(TASK, "bc").specs == request(TASK, ["bc"]).specs == (RecognizerSpec("bc"),)
    with ResultsStore(tmp_path / "s.sqlite") as store:
        as_list = evaluate(TASK, ["bc"], seeds=1, observability=[0.3], store=store)
        stored = _count_calls(monkeypatch, ResultsStore, "add")
        as_name = evaluate(TASK, "bc", seeds=1, observability=[0.3], store=store)
    assert [r.to_dict() for r in as_name] == [r.to_dict() for r in as_list]
    assert not stored  # the same configuration: its unit was found in the store, nothing ran


@pytest.mark.parametrize("task_id, recognizers, kwargs, message", [
    (123, [TINY_BC], {}, "a task is named by its GRAIL/ ID, got 123"),
    (None, [TINY_BC], {}, "a task is named by its GRAIL/ ID"),
    ("GRAIL/Nope-v0", [TINY_BC], {}, "unknown task 'GRAIL/Nope-v0'"),
    (TASK, [TINY_BC], {"task_params": [("turn_prob", 0.5)]}, "task parameters must be a mapping"),
    (TASK, [TINY_BC], {"task_params": "turn_prob=0.5"}, "task parameters must be a mapping"),
    (TASK, ["nope"], {}, "unknown recognizer 'nope'"),
    (TASK, [TINY_BC, ("nope", {})], {}, "unknown recognizer 'nope'"),
    (TASK, [TINY_BC], {"observability": 0.3}, "observability is a list of fractions"),
    (TASK, [TINY_BC], {"store": "results.sqlite"}, "store is a ResultsStore"),
    (TASK, [TINY_BC], {"executor": "local"}, "executor is an Executor"),
])
def test_evaluate_refuses_bad_inputs_before_any_training(monkeypatch, task_id, recognizers, kwargs, message):
    _no_training(monkeypatch)
    with pytest.raises(UserError, match=message) as err:
        evaluate(task_id, recognizers, **{"seeds": 1, "observability": [0.3], **kwargs})
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("args, kwargs, message", [
    ((TASK, "nope"), {}, "unknown recognizer 'nope'"),
    ((TASK, ["bc"]), {}, "a recognizer is named by a string"),
    ((TASK, "bc", -1), {}, "seeds must be integers in 0.."),
    ((TASK, "bc", 0), {"config": "n_epochs=1"}, "a recognizer's config is a mapping"),
    ((TASK, "bc", 0), {"config": {"n_epochs": 0}}, "recognizer 'bc': n_epochs=0 is out of range"),
    ((TASK, "bc", 0), {"task_params": "x"}, "task parameters must be a mapping"),
    ((7, "bc", 0), {}, "a task is named by its GRAIL/ ID"),
])
def test_inspect_fit_refuses_bad_inputs_before_any_training(monkeypatch, args, kwargs, message):
    from grail_bench.recognizers.policy import PolicyRecognizer

    def trained(*_: Any, **__: Any) -> Any:
        raise AssertionError("a fit started")

    monkeypatch.setattr(PolicyRecognizer, "fit", trained)
    with pytest.raises(UserError, match=message):
        inspect_fit(*args, **kwargs)


@pytest.mark.parametrize("name", BUILTINS)
def test_scoring_before_fitting_is_a_one_line_user_error(name):
    with pytest.raises(UserError) as err:
        make_recognizer(name).score(_one_action_observation())
    assert str(err.value) == f"{name}: call fit() before score()"
    assert isinstance(err.value, RuntimeError)  # what it was before: callers catching that keep working


def test_new_goals_before_fitting_are_a_one_line_user_error():
    with pytest.raises(UserError, match=r"^gc-bc: call fit\(\) before set_goals\(\)$"):
        make_recognizer("gc-bc").set_goals([(1, 1), (7, 7)])


#: Settings that used to fail inside the work (a foreign exception from torch or SB3, or NaN scores after training),
#: refused where the run is planned: (task, recognizer, settings, --set items, what the message says).
REFUSED = [
    (TASK, "bc", {"n_epochs": 1, "learning_rate": math.nan}, ["bc.learning_rate=NaN"],
     "recognizer 'bc': learning_rate expects a finite number, got nan"),
    (TASK, "bc", {"n_epochs": 1, "learning_rate": math.inf}, ["bc.learning_rate=Infinity"],
     "recognizer 'bc': learning_rate expects a finite number, got inf"),
    (TASK, "bc", {"n_epochs": 1, "ent_weight": math.inf}, ["bc.ent_weight=Infinity"],
     "recognizer 'bc': ent_weight expects a finite number, got inf"),
    (TASK, "gc-bc", {"n_batches": 5, "learning_rate": math.nan}, ["gc-bc.learning_rate=NaN"],
     "recognizer 'gc-bc': learning_rate expects a finite number, got nan"),
    (TASK, "gc-bc", {"n_batches": 5, "ent_weight": math.nan}, ["gc-bc.ent_weight=NaN"],
     "recognizer 'gc-bc': ent_weight expects a finite number, got nan"),
    (TASK, "gail", {"total_timesteps": 512, "learning_rate": math.nan}, ["gail.learning_rate=NaN"],
     "recognizer 'gail': learning_rate expects a finite number, got nan"),
    (TASK, "gail", {"total_timesteps": 512, "learning_rate": math.inf}, ["gail.learning_rate=Infinity"],
     "recognizer 'gail': learning_rate expects a finite number, got inf"),
    (TASK, "gail", {"total_timesteps": 512, "batch_size": 1}, ["gail.batch_size=1"],
     "recognizer 'gail': batch_size must be at least 2"),
    (TASK, "airl", {"total_timesteps": 512, "n_envs": 1, "n_steps": 1}, ["airl.n_envs=1", "airl.n_steps=1"],
     "recognizer 'airl': n_steps * n_envs must be at least 2"),
    (TASK, "graql", {"episodes": 10, "temperature": math.nan}, ["graql.temperature=NaN"],
     "recognizer 'graql': temperature expects a finite number, got nan"),
    (TASK, "draco", {"algorithm": "sac", "sac_steps": 64}, ["draco.algorithm=sac", "draco.sac_steps=64"],
     "draco: SAC needs continuous actions"),
    ("GRAIL/PointMaze-Optimal-v0", "graql", {"episodes": 10}, ["graql.episodes=10"],
     "graql needs discrete observations and actions"),
]


@pytest.mark.parametrize("task_id, name, settings, items, message", REFUSED,
                         ids=[f"{r[1]}-{'-'.join(r[3])}" for r in REFUSED])
def test_settings_that_failed_in_the_work_are_refused_at_the_door(monkeypatch, task_id, name, settings, items, message):
    _no_training(monkeypatch)
    with pytest.raises(UserError) as err:
        evaluate(task_id, [TINY_BC, (name, settings)], seeds=1, observability=[0.3])  # BC first: nothing trains
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("task_id, name, settings, items, message", REFUSED,
                         ids=[f"{r[1]}-{'-'.join(r[3])}" for r in REFUSED])
def test_the_cli_refuses_them_in_one_line_leaving_the_store_unchanged(monkeypatch, tmp_path, task_id, name, settings,
                                                                       items, message):
    _no_training(monkeypatch)
    store = tmp_path / "s.sqlite"
    with ResultsStore(store) as created:
        created.create()
    before = store.read_bytes()
    args = ["run", "-t", task_id, "-r", "bc", "-r", name, "--set", "bc.n_epochs=1", "--seeds", "1", "-o", "0.3",
            "--store", str(store), "--no-progress"]
    for item in items:
        args += ["--set", item]
    start = time.perf_counter()
    result = CliRunner().invoke(app, args, env={"COLUMNS": "200"})
    assert time.perf_counter() - start < 5
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], result.stderr
    assert store.read_bytes() == before
