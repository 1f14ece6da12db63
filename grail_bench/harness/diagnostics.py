"""Fit diagnostics in the store: one :class:`FitRow` per fitted recognizer, and what the reports read of them.

A unit's fit is diagnosed once, right after training (see
:mod:`grail_bench.recognizers.diagnostics`); the sweep stores the diagnostics
beside the unit's rows, keyed like them. They are read-only evidence: nothing
selects, retrains or filters on them.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from typing import Any, Iterable

from grail_bench.recognizers.contract import FitDiagnostics


@dataclass(frozen=True)
class FitRow:
    """The diagnostics of one fit: one recognizer (configuration) on one task, seed and mode.

    ``diagnostics`` is the JSON of a :class:`~grail_bench.recognizers.contract.FitDiagnostics`.
    """

    task: str
    recognizer: str
    config_hash: str
    seed: int
    mode: str
    diagnostics: str
    provenance: str | None = None

    def parsed(self) -> FitDiagnostics:
        """The diagnostics as the recognizer gave them."""
        return from_json(self.diagnostics)


KEY = ("task", "recognizer", "config_hash", "seed", "mode")
TABLE = "fits"


def to_json(diagnostics: FitDiagnostics) -> str:
    """JSON of diagnostics (NaN, for a goal without demonstrations, becomes null)."""
    data = asdict(diagnostics)
    data["curves"] = {str(k): v for k, v in data["curves"].items()}
    return json.dumps(_finite(data), sort_keys=True)


def _finite(value: Any) -> Any:
    if isinstance(value, float) and value != value:
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def from_json(text: str) -> FitDiagnostics:
    """Diagnostics from their stored JSON."""
    data = json.loads(text)
    return FitDiagnostics(
        goals=tuple(tuple(g) for g in data["goals"]), agreement_train=tuple(data["agreement_train"]),
        agreement_held_out=tuple(data["agreement_held_out"]), imitation=tuple(tuple(r) for r in data["imitation"]),
        reached=tuple(data["reached"]), rollout_length=tuple(data["rollout_length"]),
        demo_length=tuple(data["demo_length"]), curves={int(k): v for k, v in data["curves"].items()})


@dataclass(frozen=True)
class FitSummary:
    """The diagnostics of one configuration's fits on one task, across seeds (what the page and reports show).

    Attributes:
        goals: The goals fitted.
        seeds: The seeds whose fits are summarised.
        reached: Per goal, how many seeds' greedy rollouts reached it.
        rolled_out: Per goal, how many seeds were rolled out.
        agreement_train: Per goal, the mean agreement with its training demonstrations.
        agreement_held_out: Per goal, the mean agreement with its held-out demonstrations (None without any).
        imitation: The mean imitation matrix over seeds (``[i][j]``: goal i's actions under goal j's policy).
        rollout_length: Per goal, the mean greedy rollout length (to the goal, or the whole episode).
        demo_length: Per goal, the mean demonstration length to the goal.
        curves: Per goal index, the lowest seed's training curves.
    """

    goals: list[list[float]]
    seeds: list[int]
    reached: list[int]
    rolled_out: list[int]
    agreement_train: list[float | None]
    agreement_held_out: list[float | None]
    imitation: list[list[float | None]]
    rollout_length: list[float | None]
    demo_length: list[float]
    curves: dict[str, dict[str, list[float]]]

    @property
    def reached_share(self) -> float | None:
        """Share of all rolled-out goal fits that reached their goal."""
        total = sum(self.rolled_out)
        return sum(self.reached) / total if total else None

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "reached_share": self.reached_share}


def _mean(values: Iterable[Any]) -> float | None:
    present = [v for v in values if v is not None and v == v]
    return float(sum(present) / len(present)) if present else None


def summarize(rows: Iterable[FitRow], mode: str = "offline") -> dict[tuple[str, str, str], FitSummary]:
    """Per (task, recognizer, config hash), the :class:`FitSummary` of one mode's fits (offline by default)."""
    groups: dict[tuple[str, str, str], list[FitRow]] = {}
    for row in rows:
        if row.mode == mode:
            groups.setdefault((row.task, row.recognizer, row.config_hash), []).append(row)
    out = {}
    for key, group in groups.items():
        group.sort(key=lambda r: r.seed)
        parsed = [r.parsed() for r in group]
        k = len(parsed[0].goals)
        parsed = [d for d in parsed if len(d.goals) == k]
        out[key] = FitSummary(
            goals=[list(g) for g in parsed[0].goals], seeds=[r.seed for r in group],
            reached=[sum(bool(d.reached[i]) for d in parsed) for i in range(k)],
            rolled_out=[sum(d.reached[i] is not None for d in parsed) for i in range(k)],
            agreement_train=[_mean(d.agreement_train[i] for d in parsed) for i in range(k)],
            agreement_held_out=[_mean(d.agreement_held_out[i] for d in parsed) for i in range(k)],
            imitation=[[_mean(d.imitation[i][j] for d in parsed) for j in range(k)] for i in range(k)],
            rollout_length=[_mean(d.rollout_length[i] for d in parsed) for i in range(k)],
            demo_length=[_mean(d.demo_length[i] for d in parsed) or 0.0 for i in range(k)],
            curves={str(i): dict(c) for i, c in parsed[0].curves.items()},
        )
    return out
