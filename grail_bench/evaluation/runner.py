"""The run loop: demos -> fit -> score every observation -> metrics -> store."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from grail_bench.evaluation import metrics, robust
from grail_bench.evaluation.protocol import (
    cell_rng, get_protocol, observe, parse_observability, protocol_label, seed_list,
)
from grail_bench.executors import Executor
from grail_bench.errors import UserError
from grail_bench.recognizers.base import FitReport, RecognizerError
from grail_bench.recognizers.registry import make_recognizer
from grail_bench.scoring import available_scorers, check_scorer, get_scorer
from grail_bench.store import ResultRow, ResultsStore, config_hash
from grail_bench.task import GRTask, make_task
from grail_bench.trajectory import Demos

RECORD_KEYS = (
    "task", "recognizer", "scorer", "protocol", "observability", "n_seeds", "f1_mean", "f1_std",
    "f1_ci95_low", "f1_ci95_high", "accuracy_mean", "precision_mean", "recall_mean",
    "fit_seconds_per_goal", "score_us_per_observation", "tie_rate", "brier_mean", "nll_mean", "top2_mean",
    "mean_rank_mean", "config_hash", "task_params",
)


@dataclass(frozen=True)
class RecognizerSpec:
    """A recognizer name, its constructor config and the scorers to judge it with.

    An empty ``scorers`` means the recognizer's own default scorer.
    """

    name: str
    config: Mapping[str, Any] = field(default_factory=dict)
    scorers: tuple[str, ...] = ()


def _spec(item: str | RecognizerSpec | tuple[str, Mapping[str, Any]]) -> RecognizerSpec:
    if isinstance(item, RecognizerSpec):
        return item
    if isinstance(item, str):
        return RecognizerSpec(item)
    name, config = item
    return RecognizerSpec(name, dict(config))


@dataclass(frozen=True)
class Planned:
    """A recognizer as the run loop uses it: checked, identified and hashed once.

    Attributes:
        spec: What was asked for.
        scorers: Scorer labels the rows are stored under.
        score_args: Per scorer, what ``score`` gets (``None`` for the recognizer's default).
        posterior: Per scorer, whether its scores give a posterior over goals.
        config: JSON of the fitted configuration (recognizer and task parameters).
        config_hash: Its hash, the store's key.
    """

    spec: RecognizerSpec
    scorers: tuple[str, ...]
    score_args: tuple[str | None, ...]
    posterior: tuple[bool, ...]
    config: str
    config_hash: str


def plan(task: GRTask, spec: RecognizerSpec, action_space: Any) -> Planned:
    """Check a recognizer and its scorers against a task, and compute its identity.

    The hash covers the fitted configuration (recognizer hyperparameters and
    task parameters), not the scorer, which has its own column.

    Raises:
        grail_bench.errors.UserError: For unknown names, bad hyperparameters or
            a scorer the recognizer cannot serve on this task.
    """
    recognizer = make_recognizer(spec.name, **spec.config)
    own = recognizer.default_scorer
    scorers = tuple(spec.scorers) or (own,)
    exposes = recognizer.exposes(action_space)
    for name in scorers:
        if name != own:
            check_scorer(name, exposes, spec.name)
    registered = available_scorers()
    config = {"recognizer": spec.name, "config": dict(recognizer.config),
              "task": {"params": dict(task.params), "env": dict(task.env_params),
                       "n_demos": task.n_demos, "n_train": task.n_train}}
    return Planned(
        spec=spec, scorers=scorers, score_args=tuple(None if s == own else s for s in scorers),
        posterior=tuple(s in registered and get_scorer(s).posterior for s in scorers),
        config=json.dumps(config, sort_keys=True, default=str), config_hash=config_hash(config),
    )


def check_scores(name: str, scores: Any, goals: Sequence[tuple]) -> np.ndarray:
    """A recognizer's ``{goal: score}`` as a ``(K,)`` array in the order of ``goals``.

    Raises:
        RecognizerError: Unless there is one finite score per goal.
    """
    if not isinstance(scores, Mapping) or {tuple(g) for g in scores} != set(goals):
        raise RecognizerError(f"recognizer {name!r} must return one score per candidate goal {list(goals)}")
    out = np.array([float(scores[g]) for g in goals])
    if not np.all(np.isfinite(out)):
        raise RecognizerError(f"recognizer {name!r} returned a non-finite score: {out.tolist()}")
    return out


def fit_recognizer(task: GRTask, planned: Planned, seed: int,
                   train: Mapping[tuple, Sequence[Any]]) -> tuple[Any, FitReport | None, float]:
    """A new recognizer of ``planned``, fitted on ``train`` (the goals it is to recognise).

    Returns:
        ``(recognizer, its fit report, fit seconds per goal)``.
    """
    recognizer = make_recognizer(planned.spec.name, **planned.spec.config)
    start = time.perf_counter()
    report = recognizer.fit(train, task.env_factory(), seed=seed, cache_key=task.env_key)
    fit_seconds = report.train_seconds if report is not None else time.perf_counter() - start
    return recognizer, report, fit_seconds / len(train)


def run_seed(task: GRTask, planned: Planned, seed: int, levels: Sequence[float], protocol: str,
             versions: str, demos: Demos | None = None,
             rounding: str = "ceil") -> tuple[list[ResultRow], FitReport | None]:
    """Fit one recognizer on one seed's training demos, then score every level with every scorer.

    The recognizer never sees the true goal: it gets the training demos per
    goal, an env factory, and observations stripped of infos, scored in a
    seeded random order across goals. Each (seed, level, protocol) cell draws
    its observations from its own random stream (:func:`cell_rng`), so the
    rows do not depend on which other levels run in the same call. With a
    scorer that yields a posterior (``loglik``), its Brier score and NLL are
    recorded too.

    Args:
        planned: The recognizer, as :func:`plan` checked it.
        protocol: Observation protocol name (see :mod:`grail_bench.evaluation.protocol`).
        demos: The seed's demonstrations, if already generated.
        rounding: ``"ceil"`` or ``"floor"`` for the number of observed pairs.

    Returns:
        The rows (one per level and scorer) and the recognizer's fit report.
    """
    chosen = get_protocol(protocol)
    stored_protocol = protocol_label(chosen.name, rounding)
    name = planned.spec.name
    train, test = task.split(demos if demos is not None else task.generate_demos(seed))
    recognizer, report, fit_per_goal = fit_recognizer(task, planned, seed, train)

    labelled = [(i, traj) for i, goal in enumerate(task.goals) for traj in test[goal]]
    rows = []
    for level in levels:
        rng = cell_rng(seed, level, stored_protocol)
        order = rng.permutation(len(labelled))
        observations = [(labelled[j][0], observe(labelled[j][1], level, chosen, rng, rounding)) for j in order]
        for scorer, score_arg, posterior in zip(planned.scorers, planned.score_args, planned.posterior):
            y_true, y_pred, ties, elapsed_ns, brier, nll, ranks, top2 = [], [], 0, 0, [], [], [], []
            for label, observed in observations:
                t0 = time.perf_counter_ns()
                scores = recognizer.score(observed, score_arg)
                elapsed_ns += time.perf_counter_ns() - t0
                values = check_scores(name, scores, task.goals)
                pred, tied = metrics.predict(values)
                y_true.append(label)
                y_pred.append(pred)
                ties += tied
                rank, in_top2 = metrics.ranking(values, label)
                ranks.append(rank)
                top2.append(in_top2)
                if posterior:
                    b, n = metrics.calibration(values, len(observed.acts), label)
                    brier.append(b)
                    nll.append(n)
            m = metrics.classification(y_true, y_pred, len(task.goals))
            rows.append(ResultRow(
                task=task.id, recognizer=name, scorer=scorer, config_hash=planned.config_hash, seed=seed,
                observability=level, protocol=stored_protocol, n_observations=len(y_true), n_ties=ties,
                fit_seconds_per_goal=fit_per_goal, score_us_per_observation=elapsed_ns / 1e3 / len(y_true),
                config=planned.config, versions=versions,
                brier=float(np.mean(brier)) if brier else None, nll=float(np.mean(nll)) if nll else None,
                top2=float(np.mean(top2)), mean_rank=float(np.mean(ranks)), **m,
            ))
    return rows, report


def _task_params(config_json: str) -> dict[str, Any]:
    """The regime and env parameters a row was run with (``{}`` for rows without them)."""
    try:
        task = json.loads(config_json).get("task", {})
    except (ValueError, AttributeError):
        return {}
    return {**task.get("params", {}), **task.get("env", {})}


def _recognizer_config(config_json: str) -> dict[str, Any]:
    """The recognizer configuration a row was run with (``{}`` for rows without it)."""
    try:
        return dict(json.loads(config_json).get("config", {}))
    except (ValueError, AttributeError, TypeError):
        return {}


def _mean_or_none(values: list[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    return float(np.mean(present)) if present else None


def aggregate(rows: Iterable[ResultRow]) -> list[dict[str, Any]]:
    """Across-seed records (the ``--json`` format), one per configuration and level."""
    groups: dict[tuple, list[ResultRow]] = {}
    for r in rows:
        groups.setdefault((r.task, r.recognizer, r.scorer, r.config_hash, r.protocol, r.observability), []).append(r)
    records = []
    for (task, rec, scorer, chash, protocol, level), group in groups.items():
        group.sort(key=lambda r: r.seed)
        f1 = metrics.summarize([r.f1 for r in group])
        n_obs = sum(r.n_observations for r in group)
        records.append({
            "task": task, "recognizer": rec, "scorer": scorer, "protocol": protocol, "observability": level,
            "n_seeds": len(group), "f1_mean": f1["mean"], "f1_std": f1["std"], "f1_ci95_low": f1["ci_low"],
            "f1_ci95_high": f1["ci_high"], "f1_iqm": robust.iqm([r.f1 for r in group]),
            "seeds": [r.seed for r in group], "f1_values": [r.f1 for r in group],
            "accuracy_mean": float(np.mean([r.accuracy for r in group])),
            "precision_mean": float(np.mean([r.precision for r in group])),
            "recall_mean": float(np.mean([r.recall for r in group])),
            "fit_seconds_per_goal": float(np.mean([r.fit_seconds_per_goal for r in group])),
            "score_us_per_observation": float(np.mean([r.score_us_per_observation for r in group])),
            "tie_rate": sum(r.n_ties for r in group) / n_obs if n_obs else 0.0,
            "brier_mean": _mean_or_none([r.brier for r in group]),
            "nll_mean": _mean_or_none([r.nll for r in group]),
            "top2_mean": _mean_or_none([r.top2 for r in group]),
            "mean_rank_mean": _mean_or_none([r.mean_rank for r in group]),
            "config_hash": chash,
            "task_params": _task_params(group[0].config),
            "recognizer_config": _recognizer_config(group[0].config),
        })
    return sorted(records, key=lambda r: (r["task"], r["recognizer"], r["scorer"], r["protocol"], r["observability"]))


def evaluate(
    task_id: str,
    recognizers: Sequence[str | RecognizerSpec | tuple[str, Mapping[str, Any]]],
    *,
    seeds: int | Sequence[int] = 3,
    observability: Iterable[float] | str | None = None,
    protocol: str | None = None,
    rounding: str = "ceil",
    store: ResultsStore | None = None,
    progress: bool = False,
    task_params: Mapping[str, Any] | None = None,
    executor: Executor | None = None,
    mode: str = "offline",
) -> list[dict[str, Any]]:
    """Benchmark recognizers on one task.

    Seeds whose rows are already in ``store`` are skipped, so an interrupted
    run resumes where it stopped.

    Args:
        task_id: A ``GRAIL/`` ID.
        recognizers: Names, ``(name, config)`` pairs or :class:`RecognizerSpec`
            (which also selects scorers).
        seeds: ``n`` for seeds ``0..n-1``, or explicit seeds.
        observability: Fractions observed; defaults to the task's.
        protocol: Observation protocol; defaults to the task's (``subset`` for
            the paper's optimal and suboptimal MiniGrid tasks).
        rounding: ``"ceil"`` (default) or ``"floor"`` (gr_libs' ``int(p * T)``)
            for the number of observed pairs.
        store: Where rows go; an in-memory store if ``None``.
        progress: Show a progress bar.
        task_params: Task overrides, as ``gym.make`` accepts them (e.g.
            ``{"turn_prob": 0.5}`` or ``{"n_demos": 20, "n_train": 14}``).
        executor: Where the (recognizer, seed) units run
            (:mod:`grail_bench.executors`); in this process if ``None``.
        mode: ``offline`` (the protocol at each level), ``online`` (every
            prefix; no ``observability``) or ``open-set`` (one goal held out
            per seed; at least 3 goals).

    Returns:
        Offline: one record per recognizer, scorer and observability level
        (keys: :data:`RECORD_KEYS`). Online: one per recognizer and scorer
        (:func:`~grail_bench.evaluation.online.aggregate_online`). Open set:
        one per recognizer, scorer and level
        (:func:`~grail_bench.evaluation.open_set.aggregate_open_set`).
    """
    from grail_bench.evaluation.online import aggregate_online
    from grail_bench.evaluation.open_set import aggregate_open_set
    from grail_bench.evaluation.sweep import MODES, Request, plan_request, run_sweep

    task = make_task(task_id, **dict(task_params or {}))
    if observability is not None:
        levels = parse_observability(observability)  # refused online, when the request is planned
    else:
        levels = () if mode == "online" else task.observability
    specs = [_spec(r) for r in recognizers]
    if not specs:
        raise UserError("name at least one recognizer")
    request = Request(task.id, tuple(specs), tuple(seed_list(seeds)), tuple(levels),
                      get_protocol(protocol or task.protocol).name,  # maps deprecated names, with a warning
                      rounding, dict(task_params or {}), mode)
    store = store if store is not None else ResultsStore(":memory:")
    run_sweep([request], store, executor, progress=progress, description=f"{task.id} ({mode})")
    planned, _, _ = plan_request(request, store)
    rows = []
    for p in planned:
        rows += [r for r in store.select(MODES[mode], task=task.id, recognizer=p.spec.name, scorer=list(p.scorers),
                                         config_hash=p.config_hash, protocol=request.label, seed=list(request.seeds))
                 if getattr(r, "observability", None) in (levels or (None,))]
    return {"offline": aggregate, "online": aggregate_online, "open-set": aggregate_open_set}[mode](rows)
