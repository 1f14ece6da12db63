"""Per-configuration tables beside the boards: runs and timings, the scorer ablation, calibration.

Each is computed once from the offline records and drawn by the terminal, Markdown and web renderers.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any, Sequence

import numpy as np

from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.boards import column_label, config_variants, domain_of
from grail_bench.stats.metrics import expected_calibration_error
from grail_bench.task import find_task


def timing_rows(records: Sequence[OfflineRecord],
                fits: dict[tuple[str, str, str], Any] | None = None) -> list[dict[str, Any]]:
    """Per task and column: seeds, training seconds per goal, the means over levels of the scoring µs per
    observation, tie rate, top-2 accuracy and mean rank (``None`` when a level lacks them), and the share of its
    goal fits whose greedy rollout reached the goal (``None`` without stored diagnostics)."""
    variants = config_variants(records)
    groups: dict[tuple, list[OfflineRecord]] = defaultdict(list)
    for r in records:
        groups[(r.task, r.recognizer, r.scorer, r.config_hash)].append(r)
    out = []
    for same in groups.values():
        first = same[0]
        out.append({"task": first.task, "column": column_label(first, variants), "recognizer": first.recognizer,
                    "seeds": first.n_seeds, "fit_seconds_per_goal": first.fit_seconds_per_goal,
                    "score_us_per_observation": sum(x.score_us_per_observation for x in same) / len(same),
                    "tie_rate": sum(x.tie_rate for x in same) / len(same),
                    "top2": _level_mean([x.top2_mean for x in same]),
                    "mean_rank": _level_mean([x.mean_rank_mean for x in same]),
                    **{key: _level_mean([getattr(x, f"{key}_mean") for x in same])
                       for key in ("set_precision", "set_recall", "set_spread")},
                    "reached": _reached((fits or {}).get((first.task, first.recognizer, first.config_hash)))})
    return out


def _reached(summary: Any) -> str | None:
    """``"reached/rolled out"`` of a fit summary (None without one)."""
    if summary is None or not sum(summary.rolled_out):
        return None
    return f"{sum(summary.reached)}/{sum(summary.rolled_out)}"


def _level_mean(values: list[float | None]) -> float | None:
    return None if any(v is None for v in values) else sum(values) / len(values)


def ablation_rows(records: Sequence[OfflineRecord]) -> list[dict[str, Any]]:
    """Per task and protocol, recognizer and scorer: F1 at each level and mean scoring time.

    Only recognizers run with more than one scorer on a task are included
    (the paper's Figures 4 and 5).
    """
    scorers = defaultdict(set)
    for r in records:
        scorers[(r.task, r.protocol, r.recognizer)].add(r.scorer)
    out: dict[tuple, dict[str, Any]] = {}
    for r in records:
        if len(scorers[(r.task, r.protocol, r.recognizer)]) < 2:
            continue
        task = f"{r.task} ({r.protocol})"  # protocols are compared apart
        row = out.setdefault((task, r.recognizer, r.scorer), {
            "task": task, "recognizer": r.recognizer, "scorer": r.scorer, "f1": {}, "score_us": []})
        row["f1"][r.observability] = (r.f1_mean, r.f1_std)
        row["score_us"].append(r.score_us_per_observation)
        if r.brier_mean is not None:
            row.setdefault("calibration", []).append((r.brier_mean, r.nll_mean))
        if r.reliability is not None:
            row.setdefault("bins", []).append(r.reliability)
    for row in out.values():
        row["score_us"] = sum(row["score_us"]) / len(row["score_us"])
        bins = row.pop("bins", None)
        row["ece"] = expected_calibration_error(np.sum(bins, axis=0).tolist()) if bins else None
        row["f1_overall"] = sum(m for m, _ in row["f1"].values()) / len(row["f1"])
    return [out[k] for k in sorted(out)]


def calibration_rows(records: Sequence[OfflineRecord]) -> list[dict[str, Any]]:
    """Per domain and recognizer/scorer with a posterior (``loglik``): Brier score, NLL and the ECE and
    reliability bins of every observation of every seed, task and level pooled."""
    groups: dict[tuple[str, str], list[OfflineRecord]] = defaultdict(list)
    for r in records:
        if r.reliability is not None:
            task = find_task(r.task)
            groups[(task.domain if task else domain_of(r.task), f"{r.recognizer}/{r.scorer}")].append(r)
    out = []
    for (domain, label), group in sorted(groups.items()):
        bins = np.sum([r.reliability for r in group], axis=0).tolist()
        out.append({"domain": domain, "column": label, "records": len(group),
                    "brier": _level_mean([r.brier_mean for r in group]), "nll": _level_mean([r.nll_mean for r in group]),
                    "ece": expected_calibration_error(bins), "bins": bins})
    return out
