"""`reproduce`'s shift reports: F1 against a shift's size (SHIFTS.md) and the cross-regime grid (REGIMES.md)."""

from __future__ import annotations

import re
from collections import defaultdict

import numpy as np
import pytest
from matplotlib.image import imread

from grail_bench.harness.planning import task_params
from grail_bench.harness.store import ResultsStore
from grail_bench.harness.sweep import run_sweep
from grail_bench.report import plots
from grail_bench.report.reproduce import load_profile, write_outputs
from grail_bench.report.shifts import (UNSHIFTED, Pooled, Shift, ShiftCurve, ShiftPoint, drawn, family,
                                       figure_stems)
from grail_bench.task import find_task
from grail_bench.task.overrides import TaskOverrides

OPTIMAL, SUBOPTIMAL = "GRAIL/MiniGrid-Optimal-v0", "GRAIL/MiniGrid-Suboptimal-v1"
BC = "BC-GRAIL · n_epochs 3"  # the configuration's label (a reduced budget is a named variant)
DEMONSTRATOR = "Demonstrator (perfect imitation)"  # canonical under its own scorer, mse
# BC at a tiny budget and the demonstrator under two scorers (loglik: NLL and ECE), two seeds, two levels; a slip
# sweep on one task and a regimes sweep of BC on two (a 2 x 2 grid whose diagonal is each task unshifted).
PROFILE = f"""seeds = 2
[config.bc]
n_epochs = 3
[shifts]
slip = [{{ test_slip = 0.0 }}, {{ test_slip = 0.3 }}]
regimes = [{{ test_regime = "optimal" }}, {{ test_regime = "suboptimal" }}]
[[section]]
name = "slip"
tasks = ["{OPTIMAL}"]
recognizers = ["bc", "demonstrator"]
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
    """The profile run into a store, then its outputs written (coarse Monte Carlo ceilings, no web page), with
    the curves each shift figure was given."""
    folder = tmp_path_factory.mktemp("shifts")
    (folder / "shifts.toml").write_text(PROFILE)
    profile = load_profile(str(folder / "shifts.toml"))
    with ResultsStore(folder / "results.sqlite") as store:
        summary = run_sweep(profile.requests(), store)
        rows = store.rows()
    figures: dict[str, list] = {}

    def spy(curves):
        figures[curves[0].family] = list(curves)
        return draw(curves)

    draw = plots.shifts
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(plots, "shifts", spy)
        written = write_outputs(rows, profile, folder / "out", {}, site=False, plans=summary.planned,
                                ceiling_samples=50)
    return folder / "out", rows, written, figures


def stored_f1(rows, task, scorer, recognizer="bc", **test) -> float:
    """F1 recomputed from the stored rows: the mean over seeds of each seed's mean over the levels."""
    per_seed = defaultdict(list)
    for r in rows:
        if (r.task, r.recognizer, r.scorer) == (task, recognizer, scorer) and \
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
    out, rows, written, _ = outputs
    text = (out / "SHIFTS.md").read_text()
    heading = "## slip: MiniGrid-Optimal-v0 (subset, 20%, 30% observed)"
    table = table_rows(text, heading)
    labels = [BC, f"{BC} · loglik", DEMONSTRATOR, f"{DEMONSTRATOR} · loglik"]
    assert [(r[0], r[1]) for r in table] == [(label, f"test_slip={v}") for label in labels for v in ("0.0", "0.3")]
    for row in table:
        scorer = "loglik" if "loglik" in row[0] else "mse"
        shift = {"test_slip": 0.3} if row[1].endswith("0.3") else {}
        recognizer = "demonstrator" if row[0].startswith(DEMONSTRATOR) else "bc"
        assert row[2] == "2" and float(row[3]) == pytest.approx(stored_f1(rows, OPTIMAL, scorer, recognizer, **shift),
                                                                abs=0.005)
        low, high = map(float, row[4].strip("[]").split(", "))
        assert low <= float(row[3]) <= high
        assert row[7] != "–"  # every level has a ceiling, shifted or not
        assert (row[8] != "–") == (scorer == "loglik") and (row[9] != "–") == (scorer == "loglik")
    drops = table_rows(text[text.index(heading):], "| method | F1 unshifted")
    assert [d[0] for d in drops] == labels
    for drop in drops:
        assert float(drop[3]) == pytest.approx(float(drop[2]) - float(drop[1]), abs=0.011)
    # The regimes sweep changes the test regime alone: it is not a shift of the dynamics.
    assert "test_regime" not in text
    assert "Figure: [`shifts-slip.png`](shifts-slip.png)" in text


def test_each_family_has_its_figure_of_the_canonical_configurations_alone(outputs):
    """The slip figure draws the demonstrator (canonical, under its own scorer); BC's reduced budget and the
    loglik scorer are named variants: in SHIFTS.md, not drawn."""
    out, _, written, figures = outputs
    assert {out / "shifts-slip.png", out / "shifts-slip.svg"} <= set(written)
    assert not (out / "shifts.png").exists()
    assert (out / "shifts-slip.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert list(figures) == ["slip"]
    assert [(c.label, len(c.points)) for c in figures["slip"]] == [(DEMONSTRATOR, 2)]
    assert f"| {BC} | test_slip=0.3 |" in (out / "SHIFTS.md").read_text()
    height, width, _ = imread(out / "shifts-slip.png").shape
    assert width <= 4 * 3.5 * 110 and height <= 1200  # one panel: small enough to read on a results page


def _curve(family: str, label: str, canonical: bool, reference: bool = False) -> ShiftCurve:
    result = Pooled(2, 0.5, 0.4, 0.6, {0.3: 0.5}, None, None, None)
    shifts = (Shift(TaskOverrides(), UNSHIFTED), Shift(TaskOverrides.of({"test_slip": 0.3}), "test_slip=0.3", 0.3))
    return ShiftCurve(family, OPTIMAL, "subset", label, label.split(" · ")[0], (0.3,),
                      tuple(ShiftPoint(s, result) for s in shifts), shifts[-1], canonical, reference, shifts)


def test_figures_draw_canonical_configurations_and_all_of_a_family_without_one():
    curves = [_curve("slip", "BC-GRAIL", True), _curve("slip", "BC-GRAIL · off_support stay", False),
              _curve("slip", "BC-GRAIL · occupancy", False), _curve("slip", DEMONSTRATOR, True, reference=True),
              _curve("obstacle", "BC-GRAIL · n_epochs 3", False),
              _curve("obstacle", "GAIL-GRAIL · augment stay", False)]
    assert [(c.family, c.label) for c in drawn(curves)] == [
        ("slip", "BC-GRAIL"), ("slip", DEMONSTRATOR),
        ("obstacle", "BC-GRAIL · n_epochs 3"), ("obstacle", "GAIL-GRAIL · augment stay")]
    assert figure_stems(["slip", "action-scale", "test_slip+test_regime", "../x", ".. x"]) == {
        "slip": "shifts-slip", "action-scale": "shifts-action-scale",
        "test_slip+test_regime": "shifts-test_slip-test_regime", "../x": "shifts-x", ".. x": "shifts-x-2"}


def test_long_categorical_shift_labels_are_drawn_as_levels():
    walls = family("obstacle", [({}, {}), *(({"test_obstacles": w}, {"test_obstacles": w})
                                            for w in ([[7, 4], [6, 1]], [[7, 4], [2, 3], [6, 1]]))], [])
    assert plots.shift_ticks(walls.shifts) == [UNSHIFTED, "level 1", "level 2"]
    regimes = family("test_regime", [({"test_regime": "biased"}, {"test_regime": "biased"})], [])
    assert plots.shift_ticks(regimes.shifts) == [UNSHIFTED, 'test_regime="biased"']


def test_regimes_md_is_the_train_by_test_grid_with_the_unshifted_task_on_its_diagonal(outputs):
    out, rows, written, _ = outputs
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
    out, rows, _, _ = outputs
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
    scale = family("action-scale", [({"test_action_scale": v}, {} if v == 1.0 else {"test_action_scale": v})
                                    for v in (1.0, 0.5, 0.25)], [])
    assert [(s.label, s.x) for s in scale.shifts] == [("test_action_scale=1.0", 1.0), ("test_action_scale=0.5", 0.5),
                                                      ("test_action_scale=0.25", 0.25)]
    assert not scale.regimes
    biased = family("test_regime", [({"test_regime": "biased"}, {"test_regime": "biased"})], [])
    assert [s.label for s in biased.shifts] == [UNSHIFTED, 'test_regime="biased"'] and biased.regimes
    assert biased.shifts[0].x is None
