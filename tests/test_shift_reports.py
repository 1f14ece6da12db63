"""`reproduce`'s shift reports: F1 against a shift's size (SHIFTS.md) and the cross-regime grid (REGIMES.md)."""

from __future__ import annotations

import re
from collections import defaultdict

import numpy as np
import pytest

from grail_bench.harness.planning import task_params
from grail_bench.harness.store import ResultsStore
from grail_bench.harness.sweep import run_sweep
from grail_bench.report.reproduce import load_profile, write_outputs
from grail_bench.task import find_task

OPTIMAL, SUBOPTIMAL = "GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Suboptimal-v1"
BC = "BC-GRAIL · n_epochs 3"  # the configuration's label (a reduced budget is a named variant)
# BC at a tiny budget under two scorers (loglik: NLL and ECE), two seeds, two levels; a slip sweep on one task
# and a regimes sweep on two (a 2 x 2 grid whose diagonal is each task unshifted).
PROFILE = f"""seeds = 2
[config.bc]
n_epochs = 3
[shifts]
slip = [{{ test_slip = 0.0 }}, {{ test_slip = 0.3 }}]
regimes = [{{ test_regime = "optimal" }}, {{ test_regime = "suboptimal" }}]
[[section]]
name = "slip"
tasks = ["{OPTIMAL}"]
recognizers = ["bc"]
scorers = ["mse", "loglik"]
observability = [0.2, 0.3]
vary = {{ shift = "slip" }}
[[section]]
name = "regimes"
tasks = ["{OPTIMAL}", "{SUBOPTIMAL}"]
recognizers = ["bc"]
scorers = ["mse"]
observability = [0.2, 0.3]
vary = {{ shift = "regimes" }}
"""


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """The profile run into a store, then its outputs written (coarse Monte Carlo ceilings, no web page)."""
    folder = tmp_path_factory.mktemp("shifts")
    (folder / "shifts.toml").write_text(PROFILE)
    profile = load_profile(str(folder / "shifts.toml"))
    with ResultsStore(folder / "results.sqlite") as store:
        summary = run_sweep(profile.requests(), store)
        rows = store.rows()
    written = write_outputs(rows, profile, folder / "out", {}, site=False, plans=summary.planned, ceiling_samples=50)
    return folder / "out", rows, written


def stored_f1(rows, task, scorer, **test) -> float:
    """F1 recomputed from the stored rows: the mean over seeds of each seed's mean over the levels."""
    per_seed = defaultdict(list)
    for r in rows:
        if (r.task, r.recognizer, r.scorer) == (task, "bc", scorer) and \
                dict(find_task(task, task_params(r.config)).test_params) == test:
            per_seed[r.seed].append(r.f1)
    assert len(per_seed) == 2 and all(len(v) == 2 for v in per_seed.values())
    return float(np.mean([np.mean(v) for v in per_seed.values()]))


def table_rows(text: str, heading: str) -> list[list[str]]:
    """The cells of the first Markdown table after ``heading``."""
    lines = text[text.index(heading):].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    out = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        out.append([c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]])
    return out


def test_shifts_md_has_one_row_per_method_and_shift_with_its_f1_and_drop(outputs):
    out, rows, written = outputs
    text = (out / "SHIFTS.md").read_text()
    heading = "## slip: MiniGrid-Optimal-v0 (subset, 20%, 30% observed)"
    table = table_rows(text, heading)
    assert [(r[0], r[1]) for r in table] == [(f"{BC}", "test_slip=0.0"), (f"{BC}", "test_slip=0.3"),
                                             (f"{BC} · loglik", "test_slip=0.0"), (f"{BC} · loglik", "test_slip=0.3")]
    for row in table:
        scorer = "loglik" if "loglik" in row[0] else "mse"
        shift = {"test_slip": 0.3} if row[1].endswith("0.3") else {}
        assert row[2] == "2" and float(row[3]) == pytest.approx(stored_f1(rows, OPTIMAL, scorer, **shift), abs=0.005)
        low, high = map(float, row[4].strip("[]").split(", "))
        assert low <= float(row[3]) <= high
        assert row[7] != "–"  # every level has a ceiling, shifted or not
        assert (row[8] != "–") == (scorer == "loglik") and (row[9] != "–") == (scorer == "loglik")
    drops = table_rows(text[text.index(heading):], "| method | F1 unshifted")
    assert [d[0] for d in drops] == [BC, f"{BC} · loglik"]
    for drop in drops:
        assert float(drop[3]) == pytest.approx(float(drop[2]) - float(drop[1]), abs=0.011)
    # The regimes sweep changes the test regime alone: it is not a shift of the dynamics.
    assert "test_regime" not in text
    assert {out / "SHIFTS.md", out / "shifts.png", out / "shifts.svg"} <= set(written)
    assert (out / "shifts.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_regimes_md_is_the_train_by_test_grid_with_the_unshifted_task_on_its_diagonal(outputs):
    out, rows, written = outputs
    text = (out / "REGIMES.md").read_text()
    grid = {r[0]: r[1:] for r in table_rows(text, f"### {BC}: F1")}
    assert list(grid) == ["optimal (MiniGrid-Optimal)", "suboptimal (MiniGrid-Suboptimal)"]
    header = text[text.index(f"### {BC}: F1"):].splitlines()[2]
    assert header == "| train \\ test | optimal | suboptimal |"
    (opt_opt, opt_sub), (sub_opt, sub_sub) = grid.values()
    assert opt_opt == f"**{stored_f1(rows, OPTIMAL, 'mse'):.2f}**"  # the diagonal: each task unshifted
    assert sub_sub == f"**{stored_f1(rows, SUBOPTIMAL, 'mse'):.2f}**"
    assert opt_sub == f"{stored_f1(rows, OPTIMAL, 'mse', test_regime='suboptimal'):.2f}"
    assert sub_opt == f"{stored_f1(rows, SUBOPTIMAL, 'mse', test_regime='optimal'):.2f}"
    ceilings = table_rows(text, "### Bayes ceiling")
    assert all(cell != "–" for row in ceilings for cell in row[1:])
    assert "· loglik" not in text  # the regimes sweep ran mse alone (the slip sweep's loglik rows are not its)
    assert {out / "REGIMES.md", out / "regimes.png", out / "regimes.svg"} <= set(written)
    assert (out / "regimes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_profile_without_test_parameters_writes_no_shift_report(outputs, tmp_path):
    out, rows, _ = outputs
    path = tmp_path / "plain.toml"
    path.write_text(PROFILE.split("[shifts]")[0] + f"""[[section]]
name = "plain"
tasks = ["{OPTIMAL}"]
recognizers = ["bc"]
scorers = ["mse"]
observability = [0.2, 0.3]
""")
    written = write_outputs(rows, load_profile(str(path)), tmp_path / "o", {}, site=False, ceiling_samples=50)
    assert (tmp_path / "o" / "TABLES.md") in written
    assert not any(p.name.startswith(("SHIFTS", "shifts", "REGIMES", "regimes")) for p in written)


def test_a_family_puts_the_unshifted_task_first_and_keeps_the_profiles_order():
    """A weaker actuator shifts more as its scale falls: the profile's order, not the values', is the shift's;
    a section with fixed test parameters gets the unshifted task first; the regimes alone make the grid."""
    from grail_bench.report.shifts import UNSHIFTED, family

    scale = family("action-scale", [({"test_action_scale": v}, {} if v == 1.0 else {"test_action_scale": v})
                                    for v in (1.0, 0.5, 0.25)], [])
    assert [(s.label, s.x) for s in scale.shifts] == [("test_action_scale=1.0", 1.0), ("test_action_scale=0.5", 0.5),
                                                      ("test_action_scale=0.25", 0.25)]
    assert not scale.regimes
    biased = family("test_regime", [({"test_regime": "biased"}, {"test_regime": "biased"})], [])
    assert [s.label for s in biased.shifts] == [UNSHIFTED, 'test_regime="biased"'] and biased.regimes
    assert biased.shifts[0].x is None
