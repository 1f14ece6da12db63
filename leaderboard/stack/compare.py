"""Compare a rerun's results store with the published one, configuration by configuration.

``python leaderboard/stack/compare.py --published leaderboard/results.sqlite --rerun PATH --out REPORT.md``

Both stores are opened read-only. A cell is one mode (offline, online, open-set, zero-shot), task,
recognizer, configuration hash (the recognizer's settings and the task's parameters, so its variant), scorer,
protocol and observability level; its rows are its seeds. Only the rerun's cells are compared: per row of the
same seed, whether the headline metric (F1; online: the F1 area) is identical; per cell, a Welch t-test of the
rerun's per-seed values against the published ones. Stale rows (the old tie rule, see
:mod:`grail_bench.harness.schema`) are left out on both sides.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import warnings
from collections import defaultdict
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Optional

import numpy as np
from scipy import stats

from grail_bench.core.errors import UserError
from grail_bench.harness.modes import MODES, Mode
from grail_bench.harness.planning import recognizer_config, task_params
from grail_bench.harness.schema import stale
from grail_bench.harness.store import ResultsStore

ALPHA = 0.05
MAX_LISTED = 40  # most lines listed per section of the report
Key = tuple  # (mode, task, recognizer, scorer, config_hash, protocol, observability or None)


@dataclass
class Side:
    """One store's rows per cell (metric per seed, package versions, stale rows left out) and its configurations."""

    cells: dict[Key, dict[int, float]]
    versions: dict[Key, set[str]]
    stale: dict[Key, int]
    configs: dict[str, str]  # config hash -> its settings, as JSON


@dataclass
class Cell:
    """One compared cell: both sides' per-seed values, its verdict and the test's p-value."""

    key: Key
    rerun: dict[int, float]
    published: dict[int, float]
    verdict: str  # identical, consistent, differs, few seeds
    p: Optional[float]

    def mean(self, side: str) -> float:
        """The mean over seeds of one side (``rerun`` or ``published``)."""
        return float(np.mean(list(getattr(self, side).values())))

    def diffs(self) -> list[float]:
        """Absolute differences of the rows of the same seed."""
        return [abs(self.rerun[s] - self.published[s]) for s in sorted(self.rerun.keys() & self.published.keys())]


def metric(mode: Mode) -> str:
    """A mode's headline metric: its rows' F1, else their F1 area (online)."""
    return "f1" if "f1" in {f.name for f in fields(mode.row)} else "f1_auc"


def read(path: Path, where: dict[str, Any]) -> Side:
    """A store's rows (read-only; ``where``: column equality, a list meaning any of), grouped per cell.

    Raises:
        UserError: For a missing file or one that is not a grail-bench store.
    """
    side = Side(defaultdict(dict), defaultdict(set), defaultdict(int), {})
    with ResultsStore(path, read_only=True) as store:
        for mode in MODES.values():
            for row in store.select(mode, **where):
                key = (mode.name, row.task, row.recognizer, row.scorer, row.config_hash, row.protocol,
                       getattr(row, "observability", None))
                if stale(row):
                    side.stale[key] += 1
                    continue
                side.cells[key][row.seed] = float(getattr(row, metric(mode)))
                side.versions[key].add(row.versions)
                side.configs[row.config_hash] = json.dumps(
                    {"recognizer": recognizer_config(row.config), "task": task_params(row.config)}, sort_keys=True)
    return side


def judge(key: Key, rerun: dict[int, float], published: dict[int, float]) -> Cell:
    """A cell's verdict: identical (the same value at every seed, on the same seeds), few seeds (< 2 on a side),
    consistent (Welch p >= ALPHA) or differs (p < ALPHA, or no spread on either side and different means)."""
    if rerun == published:
        return Cell(key, rerun, published, "identical", None)
    a, b = np.array([rerun[s] for s in sorted(rerun)]), np.array([published[s] for s in sorted(published)])
    if len(a) < 2 or len(b) < 2:
        return Cell(key, rerun, published, "few seeds", None)
    if np.ptp(a) == 0 and np.ptp(b) == 0:
        return Cell(key, rerun, published, "identical" if a[0] == b[0] else "differs", None)
    with warnings.catch_warnings():  # near-equal values: scipy warns of precision loss
        warnings.simplefilter("ignore", RuntimeWarning)
        p = float(stats.ttest_ind(a, b, equal_var=False).pvalue)
    return Cell(key, rerun, published, "consistent" if p >= ALPHA else "differs", p)


def changed_packages(rerun: Side, published: Side, keys: list[Key]) -> str:
    """The packages whose versions differ between the two sides' matched rows (``name old -> new``)."""
    def seen(side: Side) -> dict[str, set[str]]:
        out: dict[str, set[str]] = defaultdict(set)
        for text in {t for key in keys for t in side.versions[key]}:
            for name, version in (json.loads(text) if text else {}).items():
                out[name].add(str(version))
        return out

    old, new = seen(published), seen(rerun)
    return "; ".join(f"{n} {'/'.join(sorted(old.get(n, {'-'})))} -> {'/'.join(sorted(new.get(n, {'-'})))}"
                     for n in sorted(old.keys() | new.keys()) if old.get(n) != new.get(n)) or "none"


def fmt(x: Optional[float], spec: str = ".4f") -> str:
    """``x`` formatted, ``-`` for None."""
    return "-" if x is None else format(x, spec)


def report(published_path: str, rerun_path: str, rerun: Side, published: Side) -> tuple[str, str]:
    """The Markdown report and its summary (the part printed to stdout)."""
    ordered = sorted(rerun.cells, key=lambda k: k[:6] + (-1.0 if k[6] is None else k[6],))
    matched = [k for k in ordered if k in published.cells]
    cells = [judge(k, rerun.cells[k], published.cells[k]) for k in matched]
    count = lambda cs, *v: sum(c.verdict in v for c in cs)  # noqa: E731
    lines = [
        "# Rerun against published results", "",
        f"Published `{published_path}`, rerun `{rerun_path}`. Cells matched on mode, task, recognizer, "
        "configuration hash (recognizer settings and task parameters), scorer, protocol and observability; "
        f"rows also on seed. Metric: F1 (online: F1 area). Welch t-test, alpha {ALPHA}. Stale rows left out: "
        f"rerun {sum(rerun.stale.values())}, published {sum(published.stale.get(k, 0) for k in ordered)}.", "",
        f"- cells in the rerun: {len(ordered)}; matched: {len(cells)}; without published rows: "
        f"{len(ordered) - len(cells)}",
        f"- identical: {count(cells, 'identical')}; consistent (identical included): "
        f"{count(cells, 'identical', 'consistent')} of {len(cells) - count(cells, 'few seeds')} testable; "
        f"differing: {count(cells, 'differs')}; fewer than 2 seeds on a side: {count(cells, 'few seeds')}",
        f"- packages changed: {changed_packages(rerun, published, matched)}", "",
        "| recognizer | rows identical / matched | max abs dF1 | cells consistent / testable | differing |",
        "|---|---|---|---|---|",
    ]
    for name in sorted({c.key[2] for c in cells}):
        mine = [c for c in cells if c.key[2] == name]
        diffs = [d for c in mine for d in c.diffs()]
        lines.append(f"| {name} | {sum(d == 0 for d in diffs)} / {len(diffs)} | {fmt(max(diffs, default=None))} | "
                     f"{count(mine, 'identical', 'consistent')} / {len(mine) - count(mine, 'few seeds')} | "
                     f"{count(mine, 'differs')} |")
    summary = "\n".join(lines) + "\n"
    # Differing cells, then untestable ones (< 2 seeds) with a row that differs from its seed's published one.
    listed = [c for c in cells if c.verdict == "differs"] + [
        c for c in cells if c.verdict == "few seeds" and any(c.diffs())]
    lines = ["", "## Differing cells", ""] + ([
        "| mode | task | recognizer/scorer | config | protocol | obs | seeds rerun/published | mean rerun "
        "| mean published | p |", "|---|---|---|---|---|---|---|---|---|---|"] if listed else ["None."])
    for c in listed[:MAX_LISTED]:
        mode, task, rec, scorer, chash, protocol, obs = c.key
        p = "n < 2" if c.verdict == "few seeds" else "no spread" if c.p is None else fmt(c.p, ".2g")
        lines.append(f"| {mode} | {task.removeprefix('GRAIL/')} | {rec}/{scorer} | {chash} | {protocol} | "
                     f"{fmt(obs, 'g')} | {len(c.rerun)}/{len(c.published)} | {fmt(c.mean('rerun'))} | "
                     f"{fmt(c.mean('published'))} | {p} |")
    if len(listed) > MAX_LISTED:
        lines.append(f"\n... and {len(listed) - MAX_LISTED} more")
    unmatched: dict[tuple, int] = defaultdict(int)  # per configuration: its cells without published rows
    for k in (k for k in ordered if k not in published.cells):
        unmatched[k[:3] + (k[4],)] += 1
    if unmatched:
        lines += ["", "## Rerun cells without published rows (per configuration)", ""]
        lines += [f"- {mode} {task.removeprefix('GRAIL/')} {rec} {chash}: {n} cells; {rerun.configs[chash]}"
                  for (mode, task, rec, chash), n in sorted(unmatched.items())[:MAX_LISTED]]
        if len(unmatched) > MAX_LISTED:
            lines.append(f"- ... and {len(unmatched) - MAX_LISTED} more")
    return summary + "\n".join(lines) + "\n", summary


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a temporary file beside ``path``, then rename it into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o644)
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv: Optional[list[str]] = None) -> int:
    """Compare the stores, write the report and print its summary; 2 with a one-line error for a bad store."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--published", type=Path, required=True, help="the published store (read-only)")
    parser.add_argument("--rerun", type=Path, required=True, help="the rerun's store (read-only)")
    parser.add_argument("--out", type=Path, required=True, help="the Markdown report to write")
    args = parser.parse_args(argv)
    try:
        rerun = read(args.rerun, {})
        if not rerun.cells:
            raise UserError(f"{args.rerun} holds no result rows")
        where = {"task": sorted({k[1] for k in rerun.cells}), "recognizer": sorted({k[2] for k in rerun.cells})}
        published = read(args.published, where)
        text, summary = report(str(args.published), str(args.rerun), rerun, published)
        write_atomic(args.out, text)
    except (UserError, OSError) as exc:
        print(f"compare.py: error: {exc}", file=sys.stderr)
        return 2
    print(summary, end="")
    print(f"report written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
