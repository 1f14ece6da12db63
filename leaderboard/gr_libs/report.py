"""RESULTS.md: gr_libs 1.0.3 and grail-bench side by side on one MiniGrid problem.

Runs in grail-bench's own virtualenv. Reads the per-instance records ``gr_libs_side.py`` wrote (JSON) and the
rows ``grail-bench run`` stored (SQLite, read-only), and writes one Markdown table: accuracy per observed
fraction under gr_libs' consecutive (first ``int(p*T)`` pairs) and non-consecutive (an ordered random subset of
``int(p*T)`` pairs) forms, then learning and inference times. Across runs or seeds every cell is the mean with
grail-bench's 95 % bootstrap interval (:func:`grail_bench.stats.metrics.summarize`).

    .venv/bin/python leaderboard/gr_libs/report.py --gr-libs gr_libs.json --store store.sqlite \\
        --task GRAIL/MiniGrid-SimpleCrossing-Optimal-v0 --command "bash leaderboard/gr_libs/run.sh" --out RESULTS.md
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.harness.store import ResultsStore
from grail_bench.stats.metrics import summarize

# gr_libs' two observation forms and the grail-bench protocol that draws the same pairs.
FORMS = {True: ("consecutive (first k)", "prefix+floor"), False: ("non-consecutive (ordered subset)", "subset+floor")}
GR_LIBS = {"Graql": "gr_libs GRAQL", "ExpertBasedGraml": "gr_libs GRAML"}
GRAIL = {"graql": "grail-bench GRAQL", "bc": "grail-bench BC"}


def cell(values: Sequence[float], digits: int = 2) -> str:
    """``mean [low, high]`` over runs or seeds; ``-`` without values."""
    if not values:
        return "-"
    s = summarize(values)
    if len(values) == 1:
        return f"{s.mean:.{digits}f}"
    return f"{s.mean:.{digits}f} [{s.ci95[0]:.{digits}f}, {s.ci95[1]:.{digits}f}]"


def gr_libs_accuracy(runs: Sequence[Mapping[str, Any]]) -> dict[tuple[float, bool], list[float]]:
    """Per (fraction, consecutive): one accuracy per run, over the instances whose actor produced a sequence."""
    out: dict[tuple[float, bool], list[float]] = defaultdict(list)
    for run in runs:
        by_cell: dict[tuple[float, bool], list[bool]] = defaultdict(list)
        for inst in run["instances"]:
            if not inst["actor_failed"]:
                by_cell[(float(inst["percentage"]), inst["consecutive"])].append(inst["correct"])
        for key, correct in by_cell.items():
            out[key].append(float(np.mean(correct)))
    return out


def grail_accuracy(store: Path, task: str) -> tuple[dict[tuple[str, str, float], list[float]], dict[str, Any]]:
    """Per (recognizer, protocol, fraction): one accuracy per seed; and per recognizer its timings."""
    with ResultsStore(store, read_only=True) as db:
        rows = db.rows(task=task)
    if not rows:
        raise UserError(f"{store} holds no row of {task}")
    acc: dict[tuple[str, str, float], list[float]] = defaultdict(list)
    fit: dict[str, list[float]] = defaultdict(list)
    score: dict[str, list[float]] = defaultdict(list)
    for r in sorted(rows, key=lambda r: (r.recognizer, r.protocol, r.observability, r.seed)):
        acc[(r.recognizer, r.protocol, round(r.observability, 6))].append(r.accuracy)
        if r.protocol == "subset+floor":  # the fit is shared by both protocols (cached): count it once
            if r.observability == max(x.observability for x in rows):
                fit[r.recognizer].append(r.fit_seconds_per_goal)
        score[r.recognizer].append(r.score_us_per_observation)
    return acc, {"fit": fit, "score": score}


def gr_libs_timings(gr: Mapping[str, Any], name: str, n_goals: int) -> dict[str, list[float]]:
    """Learning seconds per goal, the true mean inference µs per observed sequence, and the inference time gr_libs
    reports (``total_average_inference_time``), one value per run.

    Learning: the Q-tables' training (``gr["training"]``, one batch per folder, wall seconds per goal) plus the
    recognizer's own phases in the folder's first run (GRAQL: loading them; GRAML: loading them, then its LSTM
    dataset and training, then its sequence library), per goal. With one shared folder only the first run learns.
    """
    runs = [r for r in gr["runs"][name] if "failed" not in r]
    learners = runs if gr.get("fresh_per_run") else runs[:1]
    learn = []
    for batch, run in zip(gr["training"], learners):
        q_tables = float(np.mean([t["wall_seconds"] for t in batch]))
        learn.append(q_tables + (run["domain_learning_seconds"] + run["goals_adaptation_seconds"]) / n_goals)
    infer = [1e6 * float(np.mean([i["inference_seconds"] for i in run["instances"] if not i["actor_failed"]]))
             for run in runs]
    reported = [1e6 * run["grlibs_reported"]["total"]["total_average_inference_time"] for run in runs]
    return {"learn": learn, "infer": infer, "reported": reported}


def check_disagreements(runs: Sequence[Mapping[str, Any]]) -> int:
    """Instances where gr_libs' prefix-matching check and exact equality disagree."""
    return sum(1 for run in runs for i in run["instances"]
               if not i["actor_failed"] and i["correct"] != i["grlibs_correct"])


def build(gr: Mapping[str, Any], store: Path, task: str, command: str, seconds: float | None) -> str:
    """The Markdown of RESULTS.md."""
    acc, timing = grail_accuracy(store, task)
    levels = sorted({k[2] for k in acc})
    recognizers = [r for r in GRAIL if any(k[0] == r for k in acc)]
    n_seeds = max(len(v) for v in acc.values())
    gr_runs = {name: [r for r in runs if "failed" not in r] for name, runs in gr["runs"].items()}
    failed_runs = {name: [f"{r['failed']} in its `{r.get('phase')}` phase" for r in runs if "failed" in r]
                   for name, runs in gr["runs"].items()}
    gr_runs = {name: runs for name, runs in gr_runs.items() if runs}
    n_goals = len(next(iter(gr_runs.values()))[0]["goals"])
    gr_acc = {name: gr_libs_accuracy(runs) for name, runs in gr_runs.items()}
    header = ["fraction", "observed as"] + [GR_LIBS[n] for n in gr_runs] + [GRAIL[r] for r in recognizers]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for p in levels:
        for consecutive in (True, False):
            name, protocol = FORMS[consecutive]
            row = [f"{p:g}", name]
            row += [cell(gr_acc[n].get((p, consecutive), [])) for n in gr_runs]
            row += [cell(acc.get((r, protocol, p), [])) for r in recognizers]
            lines.append("| " + " | ".join(row) + " |")
    gt = {name: gr_libs_timings(gr, name, n_goals) for name in gr_runs}
    pad = [""] * len(recognizers)
    lines.append("| learning | s per goal | " + " | ".join(
        [cell(gt[n]["learn"], 1) for n in gr_runs] + [cell(timing["fit"][r], 1) for r in recognizers]) + " |")
    lines.append("| inference | µs per observed sequence | " + " | ".join(
        [cell(gt[n]["infer"], 0) for n in gr_runs] + [cell(timing["score"][r], 0) for r in recognizers]) + " |")
    lines.append("| inference as gr_libs reports it | µs (`total_average_inference_time`) | " + " | ".join(
        [cell(gt[n]["reported"], 0) for n in gr_runs] + pad) + " |")

    failures = {n: sum(1 for run in runs for i in run["instances"] if i["actor_failed"]) for n, runs in gr_runs.items()}
    totals = {n: sum(len(run["instances"]) for run in runs) for n, runs in gr_runs.items()}
    lengths = [i["T"] for runs in gr_runs.values() for run in runs for i in run["instances"] if not i["actor_failed"]]
    reached = [i["reached"] for runs in gr_runs.values() for run in runs for i in run["instances"]
               if not i["actor_failed"]]
    same = [run["actor_is_recognizer_model"] for run in gr_runs.get("Graql", [])]
    n_runs = max(len(r) for r in gr_runs.values())
    scored = {n: len({tuple(i["goal"]) for run in runs for i in run["instances"] if not i["actor_failed"]})
              for n, runs in gr_runs.items()}
    q_wall = [t["wall_seconds"] for batch in gr["training"] for t in batch]
    q_cpu = [t["cpu_seconds"] for batch in gr["training"] for t in batch]
    out = [
        "# gr_libs 1.0.3 and grail-bench on gr_libs' MiniGrid-SimpleCrossingS13N4",
        "",
        f"Command: `{command}`" + (f" ({seconds / 60:.0f} min on this machine's 2 cores, shared with other jobs)."
                                   if seconds else "."),
        "",
        f"Problem: gr_libs' `MiniGrid-SimpleCrossingS13N4` task `{gr['task']}` ({n_goals} candidate goals; its "
        "inference instances cover 6 of them, all but (6, 1), each at 5 fractions x 2 forms) and grail-bench's "
        f"`{task}` (the same room, start and goals). Accuracy per observed fraction, "
        f"mean [95 % bootstrap interval] over {n_runs} gr_libs runs and {n_seeds} grail-bench seeds; "
        "k = int(p*T) observed pairs on both sides. gr_libs' cells are as gr_libs scores them: one observed "
        "sequence per true goal and cell in each run (" + "; ".join(
            f"{GR_LIBS[n]}: {scored[n]} goals of 6 scored, the others' actor failed" if scored[n] < 6
            else f"{GR_LIBS[n]}: 6 goals" for n in gr_runs) + "); grail-bench's score its 3 test "
        "demonstrations per goal (21 per cell and seed).",
        "",
        *lines,
        "",
        "What differs between the columns (README.md explains each):",
        "",
        f"- gr_libs' Q-learning budget: {gr['episodes']} episodes per goal (gr_libs' task asks for 100 000, "
        "out of reach of the time budget here); GRAML's LSTM dataset: "
        f"{gr['lstm_samples'] or 40000} pairs of sequences (gr_libs: 40 000). grail-bench runs its defaults "
        "(GRAQL 15 000 episodes, BC 100 epochs, 7 training demonstrations per goal).",
        "- Who is observed. gr_libs: the recognizer's own Q-table, sampled with `stochastic_amplified_selection`"
        f" (its actor loads the model the recognizer trained: identical Q-tables in {sum(map(bool, same))} of "
        f"{len(same)} GRAQL runs), at most 32 steps; mean sequence length {np.mean(lengths):.1f} pairs, "
        f"{100 * np.mean(reached):.0f} % of sequences end on the goal. grail-bench: scripted shortest paths "
        "(drawn uniformly among the shortest ones), which no recognizer was trained from (GRAQL learns from "
        "reward, BC from 7 other demonstrations).",
        "- gr_libs' actor crashed on " + ", ".join(f"{failures[n]} of {totals[n]} {GR_LIBS[n]} instances"
                                                   for n in gr_runs)
        + " (all-zero Q-values on its path give NaN probabilities; gr_libs' executor would stop the run): "
          "they are left out of its cells. Failing goals: " + (", ".join(
              str(tuple(g)) for g in sorted({tuple(i["goal"]) for runs in gr_runs.values() for run in runs
                                             for i in run["instances"] if i["actor_failed"]})) or "none") + ".",
        *[f"- {GR_LIBS[n]} failed in all {len(reasons)} runs: {reasons[0]} (`base` is its domain learning, "
          "whose LSTM dataset draws 2 x the dataset size sequences from the same actors, unguarded); no column."
          for n, reasons in failed_runs.items() if reasons and n not in gr_runs],
        f"- gr_libs' correctness check (prefix match) and exact equality disagree on "
        f"{sum(check_disagreements(r) for r in gr_runs.values())} instances: no goal of this problem is a "
        "string prefix of another.",
        "- Times. gr_libs' learning: the Q-tables' training, by gr_libs' own `TabularQLearner`, two goals at a "
        f"time ({np.mean(q_wall):.0f} s wall, {np.mean(q_cpu):.0f} s CPU per goal on average, from "
        f"{min(q_cpu):.0f} to {max(q_cpu):.0f} s CPU), plus the recognizer's own phases in the first run (GRAQL: "
        "loading them; GRAML: its LSTM dataset and training, and its library), per goal. Inference: each call "
        "of `inference_phase` on one observed sequence, timed; gr_libs' own figure below it divides by 4 whatever "
        "the count. grail-bench: fit seconds per goal and scoring µs per observation as it stores them. Both "
        "suites ran at the same time, on 2 cores shared with other jobs: compare orders of magnitude only.",
        "",
        "Versions: " + ", ".join(f"{k} {v}" for k, v in gr["versions"].items()) + ".",
        "",
    ]
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gr-libs", type=Path, required=True, help="JSON written by gr_libs_side.py")
    parser.add_argument("--store", type=Path, required=True, help="the grail-bench store of the run")
    parser.add_argument("--task", required=True)
    parser.add_argument("--command", required=True, help="the command that produced the results")
    parser.add_argument("--seconds", type=float, default=None, help="its wall-clock time")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    gr = json.loads(args.gr_libs.read_text())
    args.out.write_text(build(gr, args.store, args.task, args.command, args.seconds))


if __name__ == "__main__":
    main()
