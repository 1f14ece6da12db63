"""Planning a run: recognizers checked, identified and hashed once; fitting them; checking what they return.

Everything a user can get wrong about a recognizer (an unknown name or
hyperparameter, a value of the wrong type, a scorer it cannot serve, a setting
the task's domain cannot serve) is refused here, before any unit runs.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from grail_bench.core.trajectory import Demos, Goal
from grail_bench.recognizers.contract import Capabilities, FitDiagnostics, FitReport, RecognizerError
from grail_bench.recognizers.identity import identity
from grail_bench.recognizers.registry import build, recognizer_info
from grail_bench.recognizers.scoring import available_scorers, check_scorer, get_scorer
from grail_bench.task import GRTask
from grail_bench.task.datasets import source_digest


@dataclass(frozen=True)
class RecognizerSpec:
    """A recognizer name, its constructor config and the scorers to judge it with.

    An empty ``scorers`` means the recognizer's own default scorer.
    """

    name: str
    config: Mapping[str, Any] = field(default_factory=dict)
    scorers: tuple[str, ...] = ()

    @classmethod
    def of(cls, item: str | RecognizerSpec | tuple[str, Mapping[str, Any]]) -> RecognizerSpec:
        """A spec from a name, a ``(name, config)`` pair or a spec."""
        if isinstance(item, RecognizerSpec):
            return item
        if isinstance(item, str):
            return cls(item)
        name, config = item
        return cls(name, dict(config))


@dataclass(frozen=True)
class ScorerPlan:
    """One scorer a planned recognizer is judged with.

    Attributes:
        label: The scorer column its rows are stored under.
        arg: What ``score`` gets: the registered scorer's name, or None for the recognizer's own scoring.
        posterior: Whether its scores give a posterior over goals (Brier score and NLL are then recorded).
    """

    label: str
    arg: str | None
    posterior: bool


@dataclass(frozen=True)
class Planned:
    """A recognizer as the run loop uses it: checked, identified and hashed once.

    Attributes:
        spec: What was asked for, its hyperparameters converted to their declared types.
        scorers: The scorers it is judged with.
        config: JSON of the fitted configuration (recognizer and task parameters).
        config_hash: Its hash, the store's key.
        scores_unfitted: Whether it can score goals it was not fitted on (it has ``set_goals``).
    """

    spec: RecognizerSpec
    scorers: tuple[ScorerPlan, ...]
    config: str
    config_hash: str
    scores_unfitted: bool = False

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def labels(self) -> tuple[str, ...]:
        """The scorer columns its rows are stored under."""
        return tuple(s.label for s in self.scorers)


def config_hash(payload: dict[str, Any]) -> str:
    """Short, stable hash of a JSON-able configuration (no git state involved)."""
    text = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def fitted_config(task: GRTask, name: str, settings: Mapping[str, Any],
                  demos: Mapping[str, str] | None = None) -> dict[str, Any]:
    """What a configuration's hash covers: the recognizer, its settings (as built), the task's parameters, the
    dataset its demonstrations came from, and a plugin recognizer's identity
    (:func:`grail_bench.recognizers.identity.identity`: distribution, version and, unless installed from a
    built wheel, a hash of its source; none for grail-bench's own recognizers, whose configurations are as
    before).

    Args:
        demos: The dataset as a stored configuration records it (:func:`dataset`), for a task given without it
            (reading stored rows); by default the task's own (``task.demos``: its content's digest and name).
    """
    config: dict[str, Any] = {"recognizer": name, "config": dict(settings),
                              "task": {"params": dict(task.params), "env": dict(task.env_params),
                                       "n_demos": task.n_demos, "n_train": task.n_train}}
    if task.demos:  # demonstrations from a dataset: its content keys the results, its name labels them
        config["task"] |= {"demos": source_digest(task.demos), "dataset": dataset_name(task.demos)}
    elif demos:
        config["task"] |= dict(demos)
    digest = getattr(task.spec, "content_digest", None)
    content = digest(task) if digest is not None else None
    if content:  # files the task is made of (a symbolic problem set): their content keys the results
        config["task"]["content"] = content
    if task.test_params:  # shifted test demonstrations (unshifted configurations keep their hashes)
        config["task"]["test"] = dict(task.test_params)
    plugin = identity(name)
    if plugin is not None:
        config["identity"] = plugin
    return config


def dataset_name(source: str) -> str:
    """A dataset's name as boards label its runs: a folder's name, or the Minari ID as given."""
    path = Path(source).expanduser()
    return path.resolve().name if path.is_dir() else source


def dataset(config_json: str) -> dict[str, str]:
    """The dataset a stored configuration's demonstrations came from (``demos``: its digest; ``dataset``: its
    name, absent for rows stored before names were recorded); ``{}`` for the generator's."""
    try:
        task = json.loads(config_json).get("task", {})
    except (ValueError, AttributeError):
        return {}
    return {k: task[k] for k in ("demos", "dataset") if isinstance(task.get(k), str)}


def stored_identity(config_json: str) -> dict[str, Any]:
    """The plugin identity a stored configuration records (``{}``: grail-bench's own, or stored before
    identities were recorded)."""
    try:
        found = json.loads(config_json).get("identity")
    except (ValueError, AttributeError):
        return {}
    return dict(found) if isinstance(found, dict) else {}


def without_identity(config_json: str) -> dict[str, Any]:
    """A stored configuration without the recognizer's identity: what stays the same when only the plugin
    changed (``{}`` for malformed JSON)."""
    try:
        config = json.loads(config_json)
    except ValueError:
        return {}
    if not isinstance(config, dict):
        return {}
    config.pop("identity", None)
    return config


def check_channel(specs: Sequence[RecognizerSpec], channel: str) -> None:
    """Refuse, before anything is built, a recognizer that cannot use the observation ``channel`` (its
    ``channels`` capability, read from its class).

    Raises:
        RecognizerError: In one line (``"bc cannot use the states channel: ..."``).
        UnknownRecognizerError: For an unregistered name.
    """
    for spec in specs:
        recognizer_info(spec.name).check_channel(channel)


def plan(task: GRTask, spec: RecognizerSpec, action_space: Any) -> Planned:
    """Check a recognizer and its scorers against a task, and compute its identity.

    The hash covers the fitted configuration (recognizer hyperparameters and
    task parameters), not the scorer, which has its own column.

    Raises:
        grail_bench.core.errors.UserError: For unknown names, bad hyperparameters,
            a scorer the recognizer cannot serve on this task, or a task the
            recognizer refuses as configured (its optional ``check_task``).
    """
    caps = build(spec.name, dict(spec.config))
    caps.check_task(task)
    own = caps.default_scorer
    scorers = tuple(spec.scorers) or (own,)
    exposes = caps.exposes(action_space)
    for name in scorers:
        if name != own:
            check_scorer(name, exposes, spec.name)
            if not caps.takes_scorer:
                raise RecognizerError(f"recognizer {spec.name!r} exposes policy outputs but its score() takes no "
                                      "scorer argument")
    registered = available_scorers()
    config = fitted_config(task, spec.name, caps.config)
    return Planned(
        spec=RecognizerSpec(spec.name, dict(caps.kwargs), scorers),
        scorers=tuple(ScorerPlan(s, None if s == own else s, s in registered and get_scorer(s).posterior)
                      for s in scorers),
        config=json.dumps(config, sort_keys=True, default=str), config_hash=config_hash(config),
        scores_unfitted=caps.has_set_goals,
    )


def check_scores(name: str, scores: Any, goals: Sequence[Goal]) -> np.ndarray:
    """A recognizer's ``{goal: score}`` as a ``(K,)`` array in the order of ``goals``.

    Raises:
        RecognizerError: Unless there is one finite score per goal.
    """
    if not isinstance(scores, Mapping) or {tuple(g) for g in scores} != set(goals):
        raise RecognizerError(f"recognizer {name!r} must return one score per candidate goal {list(goals)}")
    values = [scores[g] for g in goals]
    if not all(np.ndim(v) == 0 and np.asarray(v).dtype.kind in "iuf" for v in values):  # no text, no flags
        raise RecognizerError(f"recognizer {name!r} must return numbers as scores, got "
                              f"{', '.join(sorted({type(v).__name__ for v in values}))}")
    out = np.array(values, dtype=np.float64)
    if not np.all(np.isfinite(out)):
        raise RecognizerError(f"recognizer {name!r} returned a non-finite score: {out.tolist()}")
    return out


@dataclass(frozen=True)
class Fitted:
    """A recognizer fitted on one seed's training demonstrations.

    Attributes:
        recognizer: Its capabilities (what the harness scores through).
        report: What the fit reported (None: it reported nothing).
        seconds_per_goal: Training seconds per goal fitted (the report's, else the timed call's).
        diagnostics: The fit's diagnostics, where the recognizer offers them (read-only evidence: nothing
            selects, retrains or filters on them).
    """

    recognizer: Capabilities
    report: FitReport | None
    seconds_per_goal: float
    diagnostics: FitDiagnostics | None = None


def fit_recognizer(task: GRTask, planned: Planned, seed: int, train: Demos, held_out: Demos) -> Fitted:
    """A new recognizer of ``planned``, fitted on ``train`` (the goals it is to recognise), then diagnosed.

    Args:
        held_out: Other demonstrations of the fitted goals, for the diagnostics only.
    """
    caps = build(planned.spec.name, dict(planned.spec.config))
    start = time.perf_counter()
    report = caps.fit(train, task.env_factory(), seed, task.env_key)
    seconds = report.train_seconds if report is not None else time.perf_counter() - start
    diagnostics = caps.diagnose(train, {g: held_out[g] for g in train if g in held_out}, task.env_factory())
    return Fitted(caps, report, seconds / len(train), diagnostics)


def _task_part(config_json: str) -> dict[str, Any]:
    """The task part of a stored configuration (``{}`` for rows without it)."""
    try:
        task = json.loads(config_json).get("task", {})
    except (ValueError, AttributeError, TypeError):
        return {}
    return task if isinstance(task, dict) else {}


def shift_params(config_json: str) -> dict[str, Any]:
    """The test parameters a row was run with (``{}``: a task without test-time shifts, see
    docs/concepts/shifts.md)."""
    return dict(_task_part(config_json).get("test", {}))


def task_params(config_json: str) -> dict[str, Any]:
    """The regime, env and test parameters a row was run with, and its demonstration counts (``{}`` for rows
    without them)."""
    task = _task_part(config_json)
    counts = {k: task[k] for k in ("n_demos", "n_train") if k in task}
    return {**task.get("params", {}), **task.get("env", {}), **task.get("test", {}), **counts}


def recognizer_config(config_json: str) -> dict[str, Any]:
    """The recognizer configuration a row was run with (``{}`` for rows without it)."""
    try:
        return dict(json.loads(config_json).get("config", {}))
    except (ValueError, AttributeError, TypeError):
        return {}
