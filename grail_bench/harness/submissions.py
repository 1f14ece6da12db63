"""Submissions: results published elsewhere, checked (:func:`validate`), brought into a store labelled by their
source (:func:`merge`) and spot-checked by running units again here (:func:`verify`).

A submission is a folder in the published format (:mod:`grail_bench.harness.published`) with a
``source.json`` beside its ``format.json``: ``{"lab": ..., "recognizer": ..., "version": ..., "url": ...}``
(:data:`SOURCE_FIELDS`, all text), saying who ran it, with what recognizer package and version, and where it is
published. Its rows, of every mode, come with their per-instance outputs (``<domain>/outputs.jsonl`` for the
offline rows, ``online_outputs.jsonl``, ...), from which every stated metric is recomputed.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES, Mode
from grail_bench.harness.outputs import KINDS as OUTPUT_KINDS
from grail_bench.harness.outputs import differing, disagreements, output_kind
from grail_bench.harness.outputs import ROW_TYPES as OUTPUT_ROWS
from grail_bench.harness.planning import recognizer_config, task_params
from grail_bench.harness.published import KINDS, Published, PublishedError, read
from grail_bench.harness.store import ResultsStore

SOURCE_FILE = "source.json"
SOURCE_FIELDS = ("lab", "recognizer", "version", "url")
#: Problems listed at most per check (the count says how many more).
MAX_LISTED = 20


class SubmissionError(UserError):
    """A submission cannot be merged or verified."""


def read_source(root: Path) -> dict[str, str]:
    """A submission's ``source.json``.

    Raises:
        SubmissionError: If it is missing or is not an object of the four text fields.
    """
    file = root / SOURCE_FILE
    if not file.is_file():
        raise SubmissionError(f"{root} has no {SOURCE_FILE} (an object with {', '.join(SOURCE_FIELDS)})")
    try:
        source = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise SubmissionError(f"cannot read {file}: {exc}") from None
    if not isinstance(source, dict) or set(source) != set(SOURCE_FIELDS) or not all(
            isinstance(v, str) and v.strip() for v in source.values()):
        raise SubmissionError(f"{file} must be an object with exactly {', '.join(SOURCE_FIELDS)}, each non-empty text")
    if not source["url"].startswith(("https://", "http://")):
        raise SubmissionError(f"{file}: url must be a web address (https://...)")
    return {k: source[k] for k in SOURCE_FIELDS}


@lru_cache(maxsize=None)
def _task_exists(task_id: str, params: str) -> bool:
    from grail_bench.task import find_task

    return find_task(task_id, json.loads(params)) is not None


def check(published: Published, need_outputs: bool = True) -> list[str]:
    """The problems of published rows (empty: valid).

    Checks that every task exists here with the parameters its rows were run with (the ID carries its version,
    ``-v0``), that every configuration's seeds are ``0..N-1`` and that every seed has every level any of them
    has, and (``need_outputs``) that every row, of every mode, has per-instance outputs and states exactly the
    metrics they give (and that every output row has its row).
    """
    problems: list[str] = []
    used = {(r.task, json.dumps(task_params(r.config) if hasattr(r, "config") else {}, sort_keys=True))
            for r in published.all_rows()}
    unknown = sorted((task, params) for task, params in used if not _task_exists(task, params))
    for task in sorted({task for task, _ in unknown}):
        if not _task_exists(task, "{}"):
            problems.append(f"unknown task {task} (no such task ID, or not this version of it)")
        else:
            problems += [f"task {task} does not take the parameters {params}" for t, params in unknown if t == task]
    for kind, rows in published.rows.items():
        if kind in ("fits", "outputs"):
            continue
        cells: dict[tuple, dict[int, set]] = defaultdict(lambda: defaultdict(set))
        for r in rows:
            cells[(r.task, r.recognizer, r.scorer, r.config_hash, r.protocol)][r.seed].add(
                getattr(r, "observability", None))
        for (task, recognizer, scorer, _, protocol), seeds in sorted(cells.items()):
            what = f"{kind} {task} {recognizer}/{scorer} {protocol}"
            missing = sorted(set(range(max(seeds) + 1)) - set(seeds))
            if missing:
                problems.append(f"{what}: seeds are 0..{max(seeds)} but {_listed(missing)} missing")
            levels = set().union(*seeds.values())
            for seed, have in sorted(seeds.items()):
                if have != levels:
                    problems.append(f"{what}: seed {seed} lacks level(s) {_listed(sorted(levels - have))}")
    if need_outputs:
        problems += _output_problems(published)
    return problems


def _output_problems(published: Published) -> list[str]:
    """Rows without per-instance outputs, rows whose stated metrics differ from those their outputs give, and
    outputs of no row."""
    problems: list[str] = []
    for output in OUTPUT_KINDS.values():
        kind = next(name for name, row_type in KINDS.items() if row_type is output.of)
        kept = {tuple(getattr(o, k) for k in output.key): o for o in published.rows.get(output.name, [])}
        for r in published.rows.get(kind, []):
            key = tuple(getattr(r, k) for k in output.key)
            level = f" level {r.observability:g}" if hasattr(r, "observability") else ""
            what = f"{kind} {r.task} {r.recognizer}/{r.scorer} seed {r.seed}{level}"
            outputs = kept.pop(key, None)
            if outputs is None:
                problems.append(f"{what}: no per-instance outputs to recompute its metrics from")
                continue
            try:
                wrong = disagreements(r, outputs)
            except (ValueError, IndexError) as exc:  # arrays that fit together but give no metric
                problems.append(f"{what}: its outputs give no metrics ({exc})")
                continue
            if wrong:
                problems.append(f"{what}: stated {', '.join(wrong)} differ from those its outputs give")
        problems += [f"{output.name} {o.task} {o.recognizer}/{o.scorer} seed {o.seed}: outputs of no {kind} row"
                     for _, o in sorted(kept.items())]
    return problems


def _listed(values: list[Any]) -> str:
    return ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values)


def validate(path: Path, need_outputs: bool = True) -> tuple[Published, list[str]]:
    """Read a submission (a published folder, or one row file in one) against the schema, then :func:`check` it.

    Returns:
        What it holds and its problems (empty: valid).

    Raises:
        PublishedError: For a file that breaks the format (the first such line).
    """
    published = read(path)
    if not published.all_rows():
        raise PublishedError(f"{path} holds no rows")
    return published, check(published, need_outputs)


def merge_rows(path: Path) -> list[Any]:
    """A valid submission's rows, each labelled by the submission's source (what :func:`merge` stores); read and
    checked before any store is opened, so a refused submission leaves the store as it was.

    Raises:
        SubmissionError: If it is not valid (naming its first problem) or has no ``source.json``.
    """
    published, problems = validate(path)
    if problems:
        more = f" (and {len(problems) - 1} more; see `grail-bench results validate`)" if len(problems) > 1 else ""
        raise SubmissionError(f"not merged: {problems[0]}{more}")
    source = json.dumps(read_source(published.root), sort_keys=True)
    return [r if isinstance(r, (FitRow, *OUTPUT_ROWS)) else replace(r, source=source) for r in published.all_rows()]


def merge(path: Path, store: ResultsStore) -> int:
    """Bring a valid submission's rows into a store, each labelled by the submission's source (:func:`merge_rows`).

    Rows whose key the store holds already are kept out (the first write wins, as for runs).

    Returns:
        How many rows were new.
    """
    return store.add(merge_rows(path))


@dataclass(frozen=True)
class Verified:
    """One unit run again: how many of its rows agree exactly with the submission's.

    Attributes:
        unit: ``task recognizer seed protocol``, followed by its mode in brackets when not offline.
        rows: Rows compared.
        agreeing: Rows whose every recomputable metric (their mode's output kind's,
            :data:`grail_bench.harness.outputs.KINDS`) is the submission's.
        max_f1_gap: Largest absolute F1 difference (online: of the area under the F1 curve).
    """

    unit: str
    rows: int
    agreeing: int
    max_f1_gap: float


#: A unit run again: task, recognizer, configuration hash, seed, protocol and mode name.
Unit = tuple[str, str, str, int, str, str]


def verify(path: Path, sample: int, seed: int = 0) -> list[Verified]:
    """Run ``sample`` units of a submission, of any of its modes, again here (its recognizer installed from its
    entry point) and compare their rows with the submitted ones.

    Units (task, recognizer, configuration, seed, protocol and mode) are drawn at random (``seed``) from those of
    the submission, over the rows of every mode; each is planned from the stored configuration and task parameters
    in its mode, must hash to the stored configuration, and is compared on every metric its mode recomputes from
    per-instance outputs.

    Raises:
        SubmissionError: For a submission without rows of any mode, a recognizer not installed here, or a
            configuration this grail-bench plans differently.
    """
    if sample < 1:
        raise SubmissionError("--sample must be at least 1")
    modes = {mode.row: mode for mode in MODES.values()}
    units: dict[Unit, list[Any]] = defaultdict(list)
    for r in read(path).all_rows():
        if type(r) in modes:
            units[(r.task, r.recognizer, r.config_hash, r.seed, r.protocol, modes[type(r)].name)].append(r)
    if not units:
        raise SubmissionError(f"{path} has no rows ({', '.join(MODES)}) to run again")
    keys = sorted(units)
    chosen = [keys[i] for i in sorted(np.random.default_rng(seed).choice(len(keys), min(sample, len(keys)),
                                                                         replace=False))]
    return [_run_again(key, MODES[key[-1]], units[key]) for key in chosen]


def _run_again(unit: Unit, mode: Mode, stated: list[Any]) -> Verified:
    """Run one unit of a submission again in an in-memory store and compare its rows with ``stated``."""
    from grail_bench.harness.api import request
    from grail_bench.harness.planning import RecognizerSpec
    from grail_bench.harness.sweep import run_sweep
    from grail_bench.recognizers.registry import UnknownRecognizerError, recognizer_info
    from grail_bench.task.observation import parse_label

    task, recognizer, config_hash, unit_seed, protocol, _ = unit
    try:
        recognizer_info(recognizer)
    except UnknownRecognizerError:
        raise SubmissionError(f"recognizer {recognizer!r} is not installed here: install the submission's "
                              "package (its entry point in grail_bench.recognizers) to verify it") from None
    parts = parse_label(protocol)
    levels = sorted({r.observability for r in stated}) if mode.takes_levels else None
    req = request(task, [RecognizerSpec(recognizer, recognizer_config(stated[0].config),
                                        tuple(sorted({r.scorer for r in stated})))],
                  seeds=[unit_seed], observability=levels, mode=mode.name, protocol=parts.protocol,
                  rounding=parts.rounding, noise=parts.noise, channel=parts.channel,
                  task_params=task_params(stated[0].config))
    with ResultsStore(":memory:") as memory:
        summary = run_sweep([req], memory)
        planned = summary.planned[0][1][0]
        if planned.config_hash != config_hash:
            raise SubmissionError(f"{task} {recognizer}: this grail-bench plans configuration "
                                  f"{planned.config_hash}, the submission states {config_hash}")
        again = {_key(mode, r): r for r in memory.select(mode)}
    f1 = output_kind(stated[0]).f1
    agreeing, gap = 0, 0.0
    for r in stated:
        mine = again.get(_key(mode, r))
        if mine is None:
            continue
        agreeing += not differing(r, mine)
        gap = max(gap, abs(getattr(mine, f1) - getattr(r, f1)))
    which = "" if mode.name == "offline" else f" ({mode.name})"
    return Verified(f"{task} {recognizer} seed {unit_seed} {protocol}{which}", len(stated), agreeing, gap)


def _key(mode: Mode, row: Any) -> tuple:
    return tuple(getattr(row, k) for k in mode.key)
