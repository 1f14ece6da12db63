"""Shift reports: F1 against a test-time shift's size (``SHIFTS.md``) and the cross-regime grid (``REGIMES.md``).

A profile's sections that set test parameters (a shift sweep, ``vary = { shift = "slip" }``, or fixed ones,
``params = { test_regime = "biased" }``; docs/concepts/shifts.md) form **families**: those of one ``[shifts]``
list (or of the same test parameters) share one. A family that varies ``test_regime`` (and its
``test_regime_params``) alone joins the cross-regime grid; every other one is a shift of the dynamics, drawn
against its values in the profile's order, the unshifted task first.

Every value is one configuration (as the leaderboard names it, :mod:`grail_bench.report.configs`) on one task
and protocol, **pooled over the observability levels**: F1 is the mean over seeds of each seed's mean over the
levels, with the 95 % bootstrap interval of that mean (:func:`grail_bench.stats.metrics.summarize`), beside
the per-level means; the Bayes ceiling (accuracy) is the mean of the levels' ceilings (None unless every level
has one); NLL is the mean over levels, ECE that of every level's reliability bins pooled (posterior scorers
only). Computed once from the leaderboard (its records and ceilings), as frozen rows the Markdown and the
figures draw.
"""

from __future__ import annotations

import json
import re
from collections import defaultdict
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from grail_bench.harness.ceiling import Ceiling, Cell
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.boards import cell_of_record, domain_of, short_name
from grail_bench.report.configs import ConfigKey, Configuration, config_key
from grail_bench.stats.metrics import expected_calibration_error, summarize
from grail_bench.task import find_task
from grail_bench.task.model import TEST_DEFAULTS, test_defaults
from grail_bench.task.overrides import TaskOverrides

#: The label of a family's unshifted value where no table of the profile names it.
UNSHIFTED = "unshifted"


@dataclass(frozen=True)
class Shift:
    """One value of a family: the test parameters that shift something (empty: the unshifted task).

    Attributes:
        params: The test parameters as the task keeps them (those at their "as in training" value dropped).
        label: As the profile wrote it (``test_slip=0.3``), or :data:`UNSHIFTED`.
        x: The value on a figure's axis: the one parameter's number, where a family varies a single number.
    """

    params: TaskOverrides
    label: str
    x: float | None = None


@dataclass(frozen=True)
class Family:
    """The sections of a profile that share test parameters.

    Attributes:
        name: The ``[shifts]`` list's name (``slip``), else the parameters' names (``test_regime``).
        shifts: Its values in the profile's order, the unshifted task first.
        configs: The configurations its sections ran (:func:`~grail_bench.report.configs.config_key`).
    """

    name: str
    shifts: tuple[Shift, ...]
    configs: frozenset[ConfigKey]

    @property
    def regimes(self) -> bool:
        """Whether it changes the test regime alone (the cross-regime grid), not the dynamics."""
        return all(set(s.params) <= set(TEST_DEFAULTS) for s in self.shifts)

    def index(self, params: TaskOverrides) -> int | None:
        """The position of a record's test parameters among the family's values (None: not one of them)."""
        return next((i for i, s in enumerate(self.shifts) if s.params == params), None)


def family(name: str, tables: Iterable[tuple[Mapping[str, Any], Mapping[str, Any]]],
           configs: Iterable[ConfigKey]) -> Family:
    """A family from its tables in the profile's order: ``(as written, as the task keeps them)`` each.

    The unshifted task comes first (under its table's label where the profile writes one); ``x`` is set where
    every table sets the same single number.
    """
    shifts: dict[TaskOverrides, Shift] = {}
    written = [(dict(raw), TaskOverrides.of(kept)) for raw, kept in tables]
    numbers = all(len(raw) == 1 and isinstance(next(iter(raw.values())), (int, float))
                  and not isinstance(next(iter(raw.values())), bool) for raw, _ in written)
    one_key = numbers and len({next(iter(raw)) for raw, _ in written}) == 1
    for raw, kept in sorted(written, key=lambda w: bool(w[1])):  # stable: the unshifted first, else in order
        if kept not in shifts:
            x = float(next(iter(raw.values()))) if one_key else None
            shifts[kept] = Shift(kept, TaskOverrides.of(raw).label() or UNSHIFTED, x)
    if TaskOverrides() not in shifts:
        shifts = {TaskOverrides(): Shift(TaskOverrides(), UNSHIFTED), **shifts}
    return Family(name, tuple(shifts.values()), frozenset(configs))


@dataclass(frozen=True)
class Pooled:
    """One configuration's records of one task, protocol and test parameters, pooled over the levels.

    Attributes:
        n_seeds: The seeds run at every level (the pooled F1's).
        f1_mean, f1_ci95_low, f1_ci95_high: Mean over seeds of each seed's mean F1 over the levels, its 95 %
            bootstrap interval.
        by_level: Mean F1 over seeds at each level.
        ceiling: Mean Bayes ceiling (accuracy) over the levels, None unless every level has one.
        nll: Mean NLL over the levels (None without a posterior).
        ece: ECE of every level's reliability bins pooled (None without a posterior).
    """

    n_seeds: int
    f1_mean: float
    f1_ci95_low: float
    f1_ci95_high: float
    by_level: dict[float, float]
    ceiling: float | None
    nll: float | None
    ece: float | None


def pooled(records: Sequence[OfflineRecord], ceilings: Mapping[Cell, Ceiling]) -> Pooled | None:
    """The records of one configuration, task, protocol and test parameters (one per level) pooled (see the
    module docstring); None when no seed ran every level."""
    per_seed = [dict(zip(r.seeds, r.f1.values)) for r in records]
    common = sorted(set.intersection(*(set(s) for s in per_seed))) if per_seed else []
    if not common:
        return None
    f1 = summarize([float(np.mean([s[seed] for s in per_seed])) for seed in common])
    levels = [ceilings.get(cell_of_record(r)) for r in records]
    bins = [r.reliability for r in records if r.reliability is not None]
    nll = [r.nll_mean for r in records]
    return Pooled(len(common), f1.mean, *f1.ci95, {r.observability: r.f1.mean for r in records},
                  None if None in levels else float(np.mean([c.accuracy for c in levels])),
                  None if None in nll else float(np.mean(nll)),
                  expected_calibration_error(np.sum(bins, axis=0).tolist()) if len(bins) == len(records) else None)


@dataclass(frozen=True)
class ShiftPoint:
    """One value of a shift curve: the family's value and the pooled result there."""

    shift: Shift
    result: Pooled


@dataclass(frozen=True)
class ShiftCurve:
    """One configuration on one task and protocol against a family's values (those it has rows at).

    Attributes:
        family: The family's name.
        task, protocol: What the curve is of.
        label: The configuration's label (``BC-GRAIL · off_support stay``).
        method: Its method's published name (``BC-GRAIL``).
        levels: The observability levels pooled.
        points: In the family's order.
        last: The family's largest shift (its last value).
        canonical: Whether it is its method's canonical configuration (the figures draw those).
        reference: Whether its recognizer is a reference (the demonstrator), never ranked.
        values: All the family's values, in its order (those of every curve of the family).
    """

    family: str
    task: str
    protocol: str
    label: str
    method: str
    levels: tuple[float, ...]
    points: tuple[ShiftPoint, ...]
    last: Shift
    canonical: bool = False
    reference: bool = False
    values: tuple[Shift, ...] = ()

    @property
    def unshifted(self) -> float | None:
        """F1 of the unshifted task (None without its rows)."""
        first = self.points[0]
        return None if first.shift.params else first.result.f1_mean

    @property
    def at_last(self) -> float | None:
        """F1 at the family's largest shift (None without its rows)."""
        final = self.points[-1]
        return final.result.f1_mean if final.shift == self.last else None

    @property
    def drop(self) -> float | None:
        """F1 at the family's largest shift minus F1 unshifted (None unless it has both)."""
        if len(self.points) < 2 or self.unshifted is None or self.at_last is None:
            return None
        return self.at_last - self.unshifted


def _reading(record: OfflineRecord) -> tuple[TaskOverrides, str] | None:
    """How a record's runs read their task: its test parameters (as the task keeps them) and how its other
    parameters differ from the task's defaults (``n_demos=6``; empty: the defaults); None when its task is not
    known here."""
    return _read(record.task, TaskOverrides.of(record.task_params).to_json())


@lru_cache(maxsize=4096)
def _read(task_id: str, params: str) -> tuple[TaskOverrides, str] | None:
    task, base = find_task(task_id, json.loads(params)), find_task(task_id)
    if task is None or base is None:
        return None
    test = test_defaults(task.spec)
    others = {k: v for k, v in task.overrides_against(base).as_dict().items() if k not in test}
    return TaskOverrides.of(task.test_params), TaskOverrides.of(others).label()


def _shown(records: Iterable[OfflineRecord], configs: Mapping[ConfigKey, Configuration]) -> list[OfflineRecord]:
    """The records a shift report shows: neither archived nor on a dataset's demonstrations."""
    return [r for r in records if (c := configs[config_key(r)]).kind != "archived" and c.dataset is None]


def _members(fam: Family | Sequence[Family], records: Sequence[OfflineRecord],
             configs: Mapping[ConfigKey, Configuration]) -> list[tuple[OfflineRecord, TaskOverrides, str]]:
    """The records of a family's (or families') sections, with the unshifted task's records of the same
    configurations read alike (a section with fixed test parameters runs no unshifted task; another section may),
    each with its test parameters and the configuration's label (with the reading of the task's other parameters
    where it is not the defaults: ``BC-GRAIL (n_demos=6)``)."""
    families = [fam] if isinstance(fam, Family) else list(fam)
    keys = frozenset().union(*(f.configs for f in families))
    out: dict[tuple[Any, ...], tuple[OfflineRecord, TaskOverrides, str]] = {}
    named = set()
    for r in records:
        if config_key(r) in keys and (reading := _reading(r)) is not None:
            label = configs[config_key(r)].label + (f" ({reading[1]})" if reading[1] else "")
            out[(config_key(r), r.protocol, r.observability)] = (r, reading[0], label)
            named.add((r.task, label, r.protocol))
    for r in records:
        reading = _reading(r) if config_key(r) not in keys else None
        if reading is not None and not reading[0]:
            label = configs[config_key(r)].label + (f" ({reading[1]})" if reading[1] else "")
            if (r.task, label, r.protocol) in named:
                out.setdefault((config_key(r), r.protocol, r.observability), (r, TaskOverrides(), label))
    return list(out.values())


def shift_curves(records: Sequence[OfflineRecord], configs: Mapping[ConfigKey, Configuration],
                 ceilings: Mapping[Cell, Ceiling], families: Sequence[Family]) -> list[ShiftCurve]:
    """Per family of shifted dynamics, task, protocol and configuration: its F1 (pooled over levels, see the
    module docstring) at each of the family's values it has rows at.

    Args:
        records: The leaderboard's offline records.
        configs: Their configurations (:attr:`grail_bench.report.leaderboard.Leaderboard.configs`).
        ceilings: The Bayes ceilings by cell (:attr:`grail_bench.report.leaderboard.Leaderboard.ceilings`).
        families: The profile's families (those of the cross-regime grid are left to :func:`regime_cells`).
    """
    shown = _shown(records, configs)
    out = []
    for fam in families:
        if fam.regimes:
            continue
        groups: dict[tuple[str, str, str], dict[int, list[OfflineRecord]]] = defaultdict(lambda: defaultdict(list))
        for r, params, label in _members(fam, shown, configs):
            index = fam.index(params)
            if index is not None:
                groups[(r.task, r.protocol, label)][index].append(r)
        for (task, protocol, label), by_shift in sorted(groups.items()):
            points = []
            for index, group in sorted(by_shift.items()):
                result = pooled(sorted(group, key=lambda r: r.observability), ceilings)
                if result is not None:
                    points.append(ShiftPoint(fam.shifts[index], result))
            if points:
                config = configs[config_key(next(iter(by_shift.values()))[0])]
                out.append(ShiftCurve(fam.name, task, protocol, label, config.method,
                                      tuple(sorted({r.observability for g in by_shift.values() for r in g})),
                                      tuple(points), fam.shifts[-1], config.canonical, config.reference,
                                      fam.shifts))
    return out


def drawn(curves: Sequence[ShiftCurve]) -> list[ShiftCurve]:
    """The curves a family's figure draws: its canonical configurations (each method under its own scorer, the
    demonstrator's among them), as the leaderboard's boards show; all of a family's curves where none is canonical.
    The named variants stay in ``SHIFTS.md``."""
    canonical = {c.family for c in curves if c.canonical}
    return [c for c in curves if c.canonical or c.family not in canonical]


def figure_stems(families: Iterable[str]) -> dict[str, str]:
    """Each family's figure file stem, ``shifts-<family>`` (``shifts-action-scale``), its name reduced to letters,
    digits, ``-`` and ``_`` (a profile names its families) and made unique."""
    stems: dict[str, str] = {}
    for name in dict.fromkeys(families):
        base = "shifts-" + (re.sub(r"[^A-Za-z0-9_-]+", "-", name).strip("-")[:60] or "family")
        stem, k = base, 2
        while stem in stems.values():
            stem, k = f"{base}-{k}", k + 1
        stems[name] = stem
    return stems


@dataclass(frozen=True)
class RegimeCell:
    """One configuration trained on one regime's task and tested on one regime, pooled over levels.

    Attributes:
        domain, goals: The group of tasks its matrix is of (a domain's tasks of one goal count).
        label: The configuration's label, with the protocol where it is not the task's own.
        method: Its method's published name.
        canonical: Whether it is the method's canonical configuration.
        task: The training task (whose regime is the row).
        train, test: The training regime (the task's) and the test regime (``test_regime``; the task's own on the
            diagonal, where the cell is the unshifted task).
        test_params: The test regime's parameters where the profile sets them (``routes=["NE", "ES"]``).
        protocol: The protocol as stored.
        result: The pooled result.
        reference: Whether its recognizer is a reference (the demonstrator), never ranked.
    """

    domain: str
    goals: int
    label: str
    method: str
    canonical: bool
    task: str
    train: str
    test: str
    test_params: str
    protocol: str
    result: Pooled
    reference: bool = False


def regime_cells(records: Sequence[OfflineRecord], configs: Mapping[ConfigKey, Configuration],
                 ceilings: Mapping[Cell, Ceiling], families: Sequence[Family]) -> list[RegimeCell]:
    """The cross-regime grid of the families that change the test regime alone: per configuration, training task
    and test regime, its F1 pooled over levels (see the module docstring), sorted by group, label, row, column."""
    grid = [f for f in families if f.regimes]
    if not grid:
        return []
    groups: dict[tuple[str, str, str, str], list[OfflineRecord]] = defaultdict(list)
    for r, params, label in _members(grid, _shown(records, configs), configs):
        groups[(r.task, r.protocol, label, params.to_json())].append(r)
    out = []
    for (task_id, protocol, label, params_json), group in groups.items():
        task, params = find_task(task_id), TaskOverrides.from_json(params_json)
        result = pooled(sorted(group, key=lambda r: r.observability), ceilings)
        if task is None or result is None:
            continue
        config = configs[config_key(group[0])]
        shown = label + (f" ({protocol})" if protocol != task.protocol_label else "")
        regime_params = TaskOverrides.of(params.get("test_regime_params", {})).label()
        out.append(RegimeCell(task.domain or domain_of(task_id), len(task.goals), shown, config.method,
                              config.canonical, task_id, task.regime, params.get("test_regime", task.regime),
                              regime_params, protocol, result, config.reference))
    return sorted(out, key=lambda c: (c.domain, c.goals, c.label, c.train, c.test))


def regime_order(cells: Iterable[RegimeCell]) -> list[str]:
    """The regimes of a group of cells, training and test alike, sorted (a matrix's columns)."""
    return sorted({r for c in cells for r in (c.train, c.test)})


def row_label(cell: RegimeCell) -> str:
    """A matrix row: the training regime and its task (``optimal (MiniGrid-Optimal)``)."""
    return f"{cell.train} ({short_name(cell.task)})"
