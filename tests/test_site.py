"""The web leaderboard: page model, rendering, CLI, and the page in a real browser (Chromium)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from grail_bench.cli import app
from grail_bench.harness.diagnostics import FitRow, to_json
from grail_bench.task import make_task
from grail_bench.harness.store import OnlineRow, OpenSetRow, ResultRow, ResultsStore
from grail_bench.recognizers.contract import FitDiagnostics
from grail_bench.report import leaderboard
from grail_bench.report.html import build_page, render, write_site
from grail_bench.report.summary import common_strata
from grail_bench.report.reference import paper_reference_path as reference_path
from grail_bench.report.reference import read_reference

TASKS = {  # task -> levels
    "GRAIL/MiniGrid-Optimal-v0": (0.1, 0.2, 0.3),
    "GRAIL/MiniGrid-Optimal-4Goals-v0": (0.1, 0.2, 0.3),
    "GRAIL/MiniGrid-Biased-v0": (0.2, 0.3, 0.4),
    "GRAIL/PandaReach-Optimal-v0": (0.02,),
}
METHODS = [("bc", "mse", 0.8), ("graql", "kl", 0.6), ("bc", "kl", 0.79)]
STAMP = json.dumps({"command": ["grail-bench", "run", "-r", "bc</script>"], "git_commit": "abc123", "python": "3.11",
                    "platform": "Linux", "cpu": "test CPU", "cores": 2, "date": "2026-11-22T00:00:00+00:00"})


def config(task_id: str) -> str:
    """The configuration JSON of a run at the task's defaults."""
    task = make_task(task_id)
    return json.dumps({"task": {"params": dict(task.params), "env": dict(task.env_params), "n_demos": task.n_demos,
                                "n_train": task.n_train}})


def rows(seeds: int = 5) -> list[ResultRow]:
    rng = np.random.default_rng(0)
    out = []
    for task, levels in TASKS.items():
        for rec, scorer, level_f1 in METHODS:
            if task.startswith("GRAIL/Panda") and rec == "graql":
                continue
            for lv in levels:
                for seed in range(seeds):
                    f1 = float(np.clip(level_f1 + rng.normal(0, 0.1), 0, 1))
                    k = 4 if "4Goals" in task or "Panda" in task else 2
                    out.append(ResultRow(task, rec, scorer, "h" + rec, seed, lv, make_task(task).protocol_label,
                                         f1, f1, f1, f1, 6, 0, 1.5, 40.0, config(task), '{"torch": "2.13.0"}',
                                         provenance=STAMP if seed < 3 else None,
                                         confusion=json.dumps(np.eye(k, dtype=int).tolist())))
    return out


def online_rows() -> list[OnlineRow]:
    curve = json.dumps({"fractions": [0.5, 1.0], "accuracy": [0.5, 0.9], "f1": [0.4, 0.9]})
    return [OnlineRow("GRAIL/MiniGrid-Optimal-v0", rec, scorer, "h" + rec, seed, "subset", 6, 0.3 + 0.1 * seed,
                      0.0, acc, acc, curve, 1.0, 5.0, "{}", "{}")
            for rec, scorer, acc in (("bc", "mse", 0.8), ("graql", "kl", 0.6)) for seed in range(3)]


def open_set_rows() -> list[OpenSetRow]:
    return [OpenSetRow("GRAIL/MiniGrid-Optimal-4Goals-v0", rec, scorer, "h" + rec, seed, 0.3, "subset", "[7, 1]",
                       auroc, 0.5, 0.5, 0.3, 0.1, -0.2, 12, 1.0, "{}", "{}")
            for rec, scorer, auroc in (("bc", "mse", 0.6), ("graql", "kl", 0.9)) for seed in range(3)]


def fit_rows() -> list[FitRow]:
    """Diagnostics of the bc fits on the 2-goal optimal task (2 seeds)."""
    out = []
    for seed in range(2):
        d = FitDiagnostics(goals=((7, 1), (7, 7)), agreement_train=(0.9, 0.8), agreement_held_out=(0.85, 0.7),
                           imitation=((0.8, 0.3), (0.25, 0.75)), reached=(True, seed == 0), rollout_length=(11, 60),
                           demo_length=(11.0, 11.0), curves={0: {"loss": [1.2, 0.8, 0.5]}, 1: {"loss": [1.3, 0.9]}})
        out.append(FitRow("GRAIL/MiniGrid-Optimal-v0", "bc", "hbc", seed, "offline", to_json(d)))
    return out


def board(offline, reference=None, online=(), open_set=(), fits=()):
    """The leaderboard model the page draws (no Bayes ceilings: these rows' scores are made up)."""
    return leaderboard.build(offline, reference, None, studies={"online": online, "open-set": open_set}, fits=fits)


def n_records(rs: list[ResultRow]) -> int:
    return len({(r.task, r.recognizer, r.scorer, r.config_hash, r.protocol, r.observability) for r in rs})


@pytest.fixture(scope="module")
def page() -> dict:
    return build_page(board(rows(), read_reference(reference_path())), reps=500)


def test_page_has_a_cell_per_record_and_a_run_per_invocation(page):
    cells = [c for s in page["sections"] for row in s.rows for c in row["cells"] if c is not None]
    assert len(cells) == len(page["records"]) == n_records(rows())
    assert len(page["runs"]) == 2  # the stamped sweep, and rows stored before provenance existed
    assert page["runs"][0]["git_commit"] == "abc123" and page["runs"][1]["command"] is None
    assert page["domains"] == ["minigrid", "panda_reach"]
    for c in cells:
        assert c.interval.low <= c.mean <= c.interval.high
        assert c.runs and all(0 <= i < len(page["runs"]) for i in c.runs)
    assert {tuple(c.runs) for c in cells} == {(0, 1)}  # seeds 0-2 by the stamped sweep, 3-4 from before


def test_ties_are_every_cell_overlapping_the_best(page):
    for s in page["sections"]:
        for row in s.rows:
            present = [c for c in row["cells"] if c is not None]
            best = max(present, key=lambda c: c.mean)
            assert best.best
            for c in present:
                assert c.best == (c.interval.low <= best.interval.high and best.interval.low <= c.interval.high)
    # bc/mse (0.8) and bc/kl (0.79) are mostly not told apart; graql/kl (0.6) mostly is.
    flags = [(page["records"][c.record], c.best) for s in page["sections"] for row in s.rows for c in row["cells"]
             if c is not None]
    share = {name: np.mean([best for r, best in flags if f"{r['recognizer']}/{r['scorer']}" == name])
             for name in ("bc/mse", "bc/kl", "graql/kl")}
    assert share["bc/mse"] > 0.5 and share["bc/kl"] > 0.5 and share["graql/kl"] < 0.5


def test_domain_summary_iqm_and_probability_of_improvement(page):
    minigrid = next(s for s in page["summaries"] if s.domain == "minigrid")
    assert minigrid.names == ["bc/mse", "graql/kl"]  # own scorers only
    assert minigrid.strata == 9 and minigrid.all_strata == {"bc/mse": 9, "graql/kl": 9}
    assert minigrid.iqm["bc/mse"].point > minigrid.iqm["graql/kl"].point
    p, q = minigrid.poi[("bc/mse", "graql/kl")], minigrid.poi[("graql/kl", "bc/mse")]
    assert p.point == pytest.approx(1 - q.point) and p.point > 0.8
    assert minigrid.best == {"bc/mse"}


def test_summaries_compare_recognizers_on_the_strata_they_share():
    strata = {"a": {1: [0.5], 2: [0.6], 3: [0.7]}, "b": {2: [0.1], 3: [0.2]}, "c": {9: [0.3]}}
    names, shared, left_out = common_strata(strata)
    assert names == ["a", "b"] and shared == {2, 3} and left_out == ["c"]
    # A recognizer run on more strata is aggregated over the shared ones only.
    extra = [ResultRow("GRAIL/MiniGrid-Optimal-6Goals-v0", "bc", "mse", "hbc", seed, 0.1, "subset", 0.0, 0.0, 0.0,
                       0.0, 6, 0, 1.5, 40.0, config("GRAIL/MiniGrid-Optimal-6Goals-v0"), "{}") for seed in range(3)]
    with_extra = build_page(board(rows() + extra), reps=100)
    minigrid = next(s for s in with_extra["summaries"] if s.domain == "minigrid")
    assert minigrid.all_strata == {"bc/mse": 10, "graql/kl": 9} and minigrid.strata == 9
    plain = next(s for s in build_page(board(rows()), reps=100)["summaries"] if s.domain == "minigrid")
    assert minigrid.iqm["bc/mse"].point == plain.iqm["bc/mse"].point  # the extra zeros do not count


def test_paper_values_appear_on_the_default_protocol(page):
    from grail_bench.task import make_task

    papered = [r for r in page["records"] if r["paper_f1"] is not None]
    assert papered and all(r["protocol"] == make_task(r["task"]).protocol_label for r in papered)
    assert {(r["recognizer"], r["scorer"]) for r in papered} == {("bc", "mse"), ("graql", "kl")}  # the paper's scorers
    places = {r["task"]: r["paper_place"] for r in papered}
    assert places["GRAIL/MiniGrid-Optimal-v0"] in ("inside", "above", "below")  # the appendix gives intervals
    assert places["GRAIL/MiniGrid-Biased-v0"] is None  # the text gives a range only


def test_same_rows_same_page():
    first = render(build_page(board(rows()), reps=200))
    assert first == render(build_page(board(rows()), reps=200))


def test_embedded_records_cannot_close_the_script(page):
    html = render(page)
    assert "bc</script>" not in html
    start = html.index('<script type="application/json" id="records">') + len('<script type="application/json" id="records">')
    embedded = json.loads(html[start:html.index("</script>", start)])
    assert len(embedded) == len(page["records"])
    for ref in ('src="http', "src='http", 'href="http', "href='http", "url(http", "@import"):
        assert ref not in html  # nothing loads from the network


def test_online_and_open_set_runs_get_tables_of_their_own(page):
    assert page["studies"] == []  # none stored, none shown
    with_studies = build_page(board(rows(seeds=2), online=online_rows(), open_set=open_set_rows()), reps=100)
    online, open_set = with_studies["studies"]
    assert (online["id"], open_set["id"]) == ("online", "open-set")
    assert [r["recognizer"] for r in online["rows"]] == ["bc", "graql"]  # one row per recognizer over 3 seeds
    assert online["figure"].startswith("<svg") and open_set["figure"] is None
    auroc = [h for h, _ in open_set["header"]].index("AUROC")
    assert [r["cells"][auroc][1] for r in open_set["rows"]] == pytest.approx([0.6, 0.9])
    html = render(with_studies)
    assert 'id="online"' in html and 'id="open-set"' in html and 'href="#online"' in html


def test_cli_writes_the_page(tmp_path):
    store_path = tmp_path / "r.sqlite"
    with ResultsStore(store_path) as store:
        store.add(rows(seeds=2))
    out = tmp_path / "site"
    result = CliRunner().invoke(app, ["leaderboard", "--store", str(store_path), "--no-ceiling", "--html", str(out)])
    assert result.exit_code == 0, result.output
    assert (out / "index.html").stat().st_size > 0
    assert len(json.loads((out / "records.json").read_text())) == n_records(rows(seeds=2))
    missing = CliRunner().invoke(app, ["leaderboard", "--store", str(tmp_path / "none.sqlite"), "--html", str(out)])
    assert missing.exit_code != 0 and "no results store" in missing.output


# --- in a real browser ---------------------------------------------------------------------------------------

CHROMIUM_FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync"]


def chromium_path() -> str | None:
    return os.environ.get("GRAIL_BENCH_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def browser():
    path = chromium_path()
    if path is None:
        if os.environ.get("CI"):
            pytest.fail("CI must run the browser tests, and no chromium was found (.ci/run installs Debian's)")
        pytest.skip("no Chromium binary (apt-get install chromium, or set GRAIL_BENCH_CHROMIUM)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=path, args=CHROMIUM_FLAGS)
        yield browser
        browser.close()


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    write_site(board(rows(), read_reference(reference_path()), online_rows(), open_set_rows(), fit_rows()), out)
    return out / "index.html"


def open_page(browser, site: Path, **context):
    ctx = browser.new_context(viewport={"width": 1300, "height": 900}, **context)
    page = ctx.new_page()
    errors, requests = [], []
    page.on("console", lambda msg: errors.append(msg.text) if msg.type == "error" else None)
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on("request", lambda req: requests.append(req.url))
    page.goto(site.as_uri())
    page.wait_for_load_state("load")
    return page, errors, requests


def test_page_loads_offline_without_errors(browser, site, tmp_path):
    page, errors, requests = open_page(browser, site)
    assert errors == []
    assert requests and all(url.startswith(("file://", "data:")) for url in requests)
    assert page.title() == "grail-bench leaderboard"
    assert page.locator("td.cell").count() == n_records(rows())
    assert page.evaluate("JSON.parse(document.getElementById('records').textContent).length") == n_records(rows())
    assert page.locator("form#filters").is_visible()
    shot = tmp_path / "leaderboard.png"
    page.screenshot(path=str(shot), full_page=True)
    assert shot.stat().st_size > 10_000
    page.context.close()


def column_values(page, table, col: int) -> list[float | None]:
    texts = table.locator("tbody tr").evaluate_all(
        f"rows => rows.map(r => r.cells[{col}].getAttribute('data-value'))")
    return [float(t) if t else None for t in texts]


def test_sorting_a_column_reorders_rows(browser, site):
    page, errors, _ = open_page(browser, site)
    table = page.locator("section.board table").first
    first = 5  # the first recognizer column, after task, goals, observed, ceiling and pairs-only
    assert table.locator("thead th").all_inner_texts()[first - 2:first] == ["ceiling", "pairs-only"]
    header = table.locator("thead th").nth(first)
    before = column_values(page, table, first)
    pairs = ("rows => rows.map(r => [r.cells[0].textContent.trim(), r.cells[2].textContent.trim(), "
             f"r.cells[{first}].getAttribute('data-record')])")
    rows_before = table.locator("tbody tr").evaluate_all(pairs)
    header.click()
    after = column_values(page, table, first)
    present = [v for v in after if v is not None]
    assert present == sorted(present, reverse=True) and after[len(present):] == [None] * (len(after) - len(present))
    assert sorted(present) == sorted(v for v in before if v is not None)
    assert header.get_attribute("aria-sort") == "descending"
    header.click()
    present = [v for v in column_values(page, table, first) if v is not None]
    assert present == sorted(present)
    rows_after = table.locator("tbody tr").evaluate_all(pairs)
    assert rows_after != rows_before and sorted(map(tuple, rows_after)) == sorted(map(tuple, rows_before))  # rows move whole
    assert errors == []
    page.context.close()


def test_filters_hide_exactly_what_they_should(browser, site):
    page, errors, _ = open_page(browser, site)
    panda_rows = len({(r.task, r.protocol, r.observability) for r in rows() if "Panda" in r.task})
    page.select_option("select[name=domain]", "panda_reach")
    visible = page.locator("section.board:visible")
    assert visible.count() == 1 and visible.first.get_attribute("data-domain") == "panda_reach"
    assert page.locator("section.board:visible tbody tr").count() == panda_rows
    page.select_option("select[name=domain]", "")
    page.select_option("select[name=regime]", "biased")
    assert page.locator("section.board:visible").count() == 1
    assert page.locator("section.board:visible tbody tr").count() == len(TASKS["GRAIL/MiniGrid-Biased-v0"])
    page.select_option("select[name=regime]", "")
    page.select_option("select[name=recognizer]", "graql")
    assert page.locator("td.cell:visible").count() == n_records([r for r in rows() if r.recognizer == "graql"])
    assert page.locator("td.cell[data-recognizer=bc]:visible").count() == 0
    assert page.locator("section.study tbody tr:visible").count() == 2  # graql's online and open-set rows
    assert page.locator("section.study tr[data-recognizer=bc]:visible").count() == 0
    page.select_option("select[name=recognizer]", "")
    assert page.locator("td.cell:visible").count() == n_records(rows())
    assert page.locator("section.study tbody tr:visible").count() == 4
    assert errors == []
    page.context.close()


def test_online_table_sorts_by_value(browser, site):
    page, errors, _ = open_page(browser, site)
    table = page.locator("section#online table")
    col = table.locator("thead th").all_inner_texts().index("step accuracy")
    table.locator("thead th").nth(col).click()
    assert column_values(page, table, col) == pytest.approx([0.8, 0.6])
    table.locator("thead th").nth(col).click()
    assert column_values(page, table, col) == pytest.approx([0.6, 0.8])
    assert page.locator("section#online figure svg").count() == 1
    assert errors == []
    page.context.close()


def test_cell_links_to_its_run(browser, site):
    page, _, _ = open_page(browser, site)
    page.locator("td.cell a").first.click()
    target = page.evaluate("location.hash")
    assert target.startswith("#run-") and page.locator(f"{target}").is_visible()
    assert "grail-bench run" in page.locator("#run-0").inner_text()
    page.context.close()


def test_a_cell_shows_its_confusion_imitation_and_curves_on_demand(browser, site):
    page, errors, _ = open_page(browser, site)
    assert not page.locator("#details").is_visible()
    index = page.evaluate("JSON.parse(document.getElementById('records').textContent).find(r => r.task === "
                          "'GRAIL/MiniGrid-Optimal-v0' && r.column === 'bc/mse' && r.observability === 0.1).id")
    page.locator(f"td.cell[data-record='{index}'] button.diag").click()
    panel = page.locator("#details")
    assert panel.is_visible() and "bc" in page.locator("#details-title").inner_text()
    heatmaps = panel.locator("svg.heatmap")
    assert heatmaps.count() == 2  # confusion and imitation
    assert heatmaps.nth(1).locator("rect").count() == 4 and "0.80" in heatmaps.nth(1).text_content()
    assert panel.locator("table tbody tr").count() == 2 and "2/2" in panel.locator("table").inner_text()
    assert "1/2" in panel.locator("table").inner_text()  # goal (7,7) reached on one seed of two
    assert panel.locator("svg.curve polyline").count() == 2  # one loss curve per goal
    graql = page.locator("section.board td.cell[data-recognizer=graql] button.diag").first  # no diagnostics stored
    graql.click()
    assert "No fit diagnostics" in panel.inner_text() and panel.locator("svg.heatmap").count() == 1
    assert errors == []
    page.context.close()


def test_page_reads_without_scripts(browser, site):
    page, errors, _ = open_page(browser, site, java_script_enabled=False)
    assert page.locator("td.cell").count() == n_records(rows())
    assert page.locator("td.cell").first.is_visible()
    assert not page.locator("form#filters").is_visible()  # nothing to filter with, so not shown
    assert page.locator("button.diag:visible").count() == 0  # details need the script: no dead buttons
    assert page.locator("figure svg").count() >= 1
    page.context.close()


def test_profiles_and_calibration_show_offline(browser, tmp_path):
    from grail_bench.harness.modes.offline import OfflineRecord
    from grail_bench.stats.metrics import reliability_bins

    task = make_task("GRAIL/MiniGrid-Optimal-v0")
    params = {**task.params, **task.env_params, "n_demos": task.n_demos, "n_train": task.n_train}

    def record(rec, scorer, level, values, **extra):
        return OfflineRecord(task=task.id, recognizer=rec, scorer=scorer, protocol="subset", config_hash="h" + rec,
                             n_seeds=2, seeds=[0, 1], fit_seconds_per_goal=1.0, task_params=params,
                             observability=level, f1_mean=float(np.mean(values)), f1_std=0.1, f1_ci95_low=0.0,
                             f1_ci95_high=1.0, f1_iqm=float(np.mean(values)), f1_values=values, accuracy_mean=0.5,
                             precision_mean=0.5, recall_mean=0.5, score_us_per_observation=1.0, tie_rate=0.0, **extra)

    records = [record("bc", "mse", lv, (0.9, 1.0)) for lv in (0.1, 0.2, 0.3)]
    records += [record("graql", "kl", lv, (0.5, 0.7)) for lv in (0.1, 0.2, 0.3)]
    records.append(record("bc", "loglik", 0.1, (0.8, 0.9), reliability=reliability_bins([0.9, 0.6], [True, False])))
    write_site(leaderboard.build([], None, 50, records=records), tmp_path)
    page, errors, requests = open_page(browser, tmp_path / "index.html")
    assert page.locator("#profiles svg").count() == 1 and page.locator("#calibration svg").count() == 1
    assert "bc/loglik" in page.locator("#calibration table").inner_text()
    assert "optimality gap" in page.locator("#summary").inner_text()
    assert errors == [] and all(url.startswith(("file://", "data:")) for url in requests)
    page.context.close()
