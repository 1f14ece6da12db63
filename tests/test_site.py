"""The web leaderboard: page model, rendering, CLI, and the page in a real browser (Chromium)."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import offline_record, stored_config
from typer.testing import CliRunner

from grail_bench.cli import app
from grail_bench.harness.diagnostics import FitRow, to_json
from grail_bench.harness.store import OnlineRow, OpenSetRow, ResultRow, ResultsStore
from grail_bench.recognizers.contract import FitDiagnostics
from grail_bench.report import leaderboard
from grail_bench.report.html import MAX_PAGE_BYTES, build_page, json_for_script, render, write_site
from grail_bench.report.summary import common_strata, comparison_groups
from grail_bench.task import make_task
from grail_bench.report.reference import paper_reference_path as reference_path
from grail_bench.report.reference import read_reference

TASKS = {  # task -> levels
    "GRAIL/MiniGrid-Optimal-v0": (0.1, 0.2, 0.3),
    "GRAIL/MiniGrid-Optimal-4Goals-v0": (0.1, 0.2, 0.3),
    "GRAIL/MiniGrid-Biased-v0": (0.2, 0.3, 0.4),
    "GRAIL/PandaReach-Optimal-v0": (0.02,),
}
METHODS = [("bc", "mse", 0.8), ("graql", "kl", 0.6), ("bc", "kl", 0.79)]  # BC-GRAIL, GRAQL, variant BC-GRAIL · kl
STAMP = json.dumps({"command": ["grail-bench", "run", "-r", "bc</script>"], "git_commit": "abc123", "python": "3.11",
                    "platform": "Linux", "cpu": "test CPU", "cores": 2, "date": "2026-11-22T00:00:00+00:00"})


def config(task_id: str) -> str:
    """The configuration JSON of a bc run at the task's defaults."""
    return stored_config(task_id, "bc")[0]


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
                    config_json, hashed = stored_config(task, rec)
                    out.append(ResultRow(task, rec, scorer, hashed, seed, lv, make_task(task).protocol_label,
                                         f1, f1, f1, f1, 6, 0, 1.5, 40.0, config_json, '{"torch": "2.13.0"}',
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


def fit_rows(loss: list[float] | None = None) -> list[FitRow]:
    """Diagnostics of the bc fits on the 2-goal optimal task (2 seeds); ``loss``: goal 0's training curve."""
    out = []
    for seed in range(2):
        d = FitDiagnostics(goals=((7, 1), (7, 7)), agreement_train=(0.9, 0.8), agreement_held_out=(0.85, 0.7),
                           imitation=((0.8, 0.3), (0.25, 0.75)), reached=(True, seed == 0), rollout_length=(11, 60),
                           demo_length=(11.0, 11.0), curves={0: {"loss": loss or [1.2, 0.8, 0.5]}, 1: {"loss": [1.3, 0.9]}})
        out.append(FitRow("GRAIL/MiniGrid-Optimal-v0", "bc", stored_config("GRAIL/MiniGrid-Optimal-v0", "bc")[1],
                          seed, "offline", to_json(d)))
    return out


def board(offline, reference=None, online=(), open_set=(), fits=()):
    """The leaderboard model the page draws (no Bayes ceilings: these rows' scores are made up)."""
    return leaderboard.build(offline, reference, None, studies={"online": online, "open-set": open_set}, fits=fits)


def bc_rows(rows_: list[ResultRow], settings: dict | None = None, drop: str | None = None,
            f1: float | None = None) -> list[ResultRow]:
    """Copies of bc's own-scorer rows stored under another configuration of bc (see
    :func:`conftest.stored_config`)."""
    out = []
    for r in rows_:
        if (r.recognizer, r.scorer) == ("bc", "mse"):
            config_json, hashed = stored_config(r.task, "bc", settings, drop)
            out.append(dataclasses.replace(r, config=config_json, config_hash=hashed, f1=r.f1 if f1 is None else f1))
    return out


def superseded(rows_: list[ResultRow]) -> list[ResultRow]:
    """bc's rows as an earlier version stored them: its configuration lacked ``ent_weight`` (a setting added since)."""
    return bc_rows(rows_, drop="ent_weight", f1=0.1)


def stay_variant(rows_: list[ResultRow]) -> list[ResultRow]:
    """bc's rows run with ``off_support="stay"``: a named variant."""
    return bc_rows(rows_, {"off_support": "stay"})


ODD_NAMES = ("<!--<script>", "</script>")


def odd_names(rows_: list[ResultRow]) -> list[ResultRow]:
    """Rows of two plugins not registered here (records of unknown plugins), named like markup."""
    return [dataclasses.replace(r, recognizer=name, scorer="default") for name in ODD_NAMES
            for r in rows_ if r.recognizer == "graql" and r.task == "GRAIL/MiniGrid-Optimal-v0"]


def n_records(rs: list[ResultRow]) -> int:
    return len({(r.task, r.recognizer, r.scorer, r.config_hash, r.protocol, r.observability) for r in rs})


def page_of(offline, reference=None, reps=100, **studies) -> dict:
    """The page model of rows (no headline claims: :mod:`grail_bench.report.claims` is tested on its own)."""
    return build_page(board(offline, reference, **studies), reps=reps, claims=[])


def main_cells(page: dict) -> list:
    return [c for s in page["sections"] for row in s.rows for c in row["cells"] if c is not None]


@pytest.fixture(scope="module")
def page() -> dict:
    return page_of(rows(), read_reference(reference_path()), reps=500)


def test_page_has_a_cell_per_record_and_a_run_per_invocation(page):
    cells = main_cells(page) + [c for s in page["variants"] for row in s.rows for c in row["cells"] if c is not None]
    assert len(cells) == len(page["records"]) == n_records(rows())
    assert len(page["runs"]) == 2  # the stamped sweep, and rows stored before provenance existed
    assert page["runs"][0]["git_commit"] == "abc123" and page["runs"][1]["command"] is None
    assert page["domains"] == ["minigrid", "panda_reach"]
    for c in cells:
        assert c.interval.low <= c.mean <= c.interval.high
        assert c.runs and all(0 <= i < len(page["runs"]) for i in c.runs)
    assert {tuple(c.runs) for c in cells} == {(0, 1)}  # seeds 0-2 by the stamped sweep, 3-4 from before


def test_main_boards_show_methods_by_their_published_names_and_variants_by_label(page):
    assert {c.label for s in page["sections"] for c in s.columns} == {"BC-GRAIL", "GRAQL"}
    assert [c.label for s in page["variants"] for c in s.columns] == ["BC-GRAIL · kl", "BC-GRAIL · kl"]
    assert [s.title for s in page["variants"]] == ["minigrid: BC-GRAIL variants", "panda_reach: BC-GRAIL variants"]
    assert all(r["kind"] in ("canonical", "variant") for r in page["records"]) and not page["archive"]


def test_ties_are_every_method_cell_overlapping_the_best(page):
    for s in page["sections"] + page["variants"]:
        for row in s.rows:
            present = [c for c in row["cells"] if c is not None]
            best = max(present, key=lambda c: c.mean)
            assert best.best
            for c in present:
                assert c.best == (c.interval.low <= best.interval.high and best.interval.low <= c.interval.high)
    # BC-GRAIL (0.8) mostly stands clear of GRAQL (0.6).
    flags = [(page["records"][c.record]["column"], c.best) for c in main_cells(page)]
    share = {name: np.mean([best for label, best in flags if label == name]) for name in ("BC-GRAIL", "GRAQL")}
    assert share["BC-GRAIL"] > 0.5 and share["GRAQL"] < 0.5


def test_domain_summary_iqm_and_probability_of_improvement(page):
    minigrid = next(s for s in page["summaries"] if s.domain == "minigrid")
    assert minigrid.names == ["BC-GRAIL", "GRAQL"]  # canonical configurations only: BC-GRAIL · kl is a variant
    assert minigrid.strata == 9 and minigrid.all_strata == {"BC-GRAIL": 9, "GRAQL": 9}
    assert minigrid.strata_text == ["MiniGrid-Biased (prefix) at 20%, 30%, 40%",
                                    "MiniGrid-Optimal (subset) at 10%, 20%, 30%",
                                    "MiniGrid-Optimal-4Goals (subset) at 10%, 20%, 30%"]
    assert minigrid.iqm["BC-GRAIL"].point > minigrid.iqm["GRAQL"].point
    p, q = minigrid.poi[("BC-GRAIL", "GRAQL")], minigrid.poi[("GRAQL", "BC-GRAIL")]
    assert p.point == pytest.approx(1 - q.point) and p.point > 0.8
    assert minigrid.best == {"BC-GRAIL"}


def test_summaries_compare_methods_on_the_strata_they_share_and_name_the_gaps():
    strata = {"a": {1: [0.5], 2: [0.6], 3: [0.7]}, "b": {2: [0.1], 3: [0.2]}, "c": {9: [0.3]}}
    names, shared, left_out = common_strata(strata)
    assert names == ["a", "b"] and shared == {2, 3} and left_out == ["c"]
    # Methods on few strata that overlap no one else leave themselves out, not the larger group they miss.
    many = {"a": {1: [0.5], 2: [0.5]}, "b": {1: [0.5], 2: [0.5]}, "c": {1: [0.5], 2: [0.5]},
            "d": {k: [0.5] for k in range(3, 9)}, "e": {k: [0.5] for k in range(3, 9)}}
    assert common_strata(many) == (["a", "b", "c"], {1, 2}, ["d", "e"])
    many["e"][1] = [0.5]  # a tie on size goes to the group sharing more strata
    assert common_strata({k: many[k] for k in "bde"}) == (["d", "e"], set(range(3, 9)), ["b"])
    # ... unless the other shares more tasks: two tasks at one level beat one task at five levels.
    levels = {"p": {("T1", "subset", 0.02): [0.5], ("T2", "subset", 0.02): [0.5]},
              "q": {("T1", "subset", 0.02): [0.5], ("T2", "subset", 0.02): [0.5]},
              "r": {("T3", "prefix", x): [0.5] for x in (0.1, 0.3, 0.5, 0.7, 1.0)},
              "s": {("T3", "prefix", x): [0.5] for x in (0.1, 0.3, 0.5, 0.7, 1.0)}}
    assert common_strata(levels) == (["p", "q"], set(levels["p"]), ["r", "s"])


def test_methods_the_largest_comparison_leaves_out_are_ranked_in_one_of_their_own():
    # The paper's four methods on its task (stratum 1); five methods, two of them the paper's, on another suite's.
    strata = {"bc": {1: [0.5], 2: [0.5], 3: [0.5]}, "draco": {1: [0.5], 2: [0.5], 3: [0.5]},
              "gail": {1: [0.5]}, "airl": {1: [0.5]},
              "graml": {2: [0.5], 3: [0.5]}, "gc-draco": {2: [0.5], 3: [0.5]}, "gc-graml": {2: [0.5], 3: [0.5]}}
    assert comparison_groups(strata) == [(["bc", "draco", "gc-draco", "gc-graml", "graml"], {2, 3}),
                                         (["airl", "bc", "draco", "gail"], {1})]
    assert comparison_groups({"a": {1: [0.5]}, "b": {1: [0.5]}}) == [(["a", "b"], {1})]  # one group: one summary
    # A method run on more strata is aggregated over the shared ones only, and the others' gap is named.
    task = "GRAIL/MiniGrid-Optimal-6Goals-v0"
    config_json, hashed = stored_config(task, "bc")
    extra = [ResultRow(task, "bc", "mse", hashed, seed, 0.1, "subset", 0.0, 0.0, 0.0, 0.0, 6, 0, 1.5, 40.0,
                       config_json, "{}") for seed in range(3)]
    minigrid = next(s for s in page_of(rows() + extra)["summaries"] if s.domain == "minigrid")
    assert minigrid.all_strata == {"BC-GRAIL": 10, "GRAQL": 9} and minigrid.strata == 9
    assert minigrid.gaps_text == {"GRAQL": "MiniGrid-Optimal-6Goals (subset) at 10%"}
    plain = next(s for s in page_of(rows())["summaries"] if s.domain == "minigrid")
    assert minigrid.iqm["BC-GRAIL"].point == plain.iqm["BC-GRAIL"].point  # the extra zeros do not count
    assert plain.gaps_text == {}


def test_paper_values_appear_beside_canonical_columns_on_the_default_protocol(page):
    papered = [r for r in page["records"] if r["paper_f1"] is not None]
    assert papered and all(r["protocol"] == make_task(r["task"]).protocol_label for r in papered)
    assert {r["column"] for r in papered} == {"BC-GRAIL", "GRAQL"}  # not beside the variant BC-GRAIL · kl
    places = {r["task"]: r["paper_place"] for r in papered}
    assert places["GRAIL/MiniGrid-Optimal-v0"] in ("inside", "above", "below")  # the appendix gives intervals
    assert places["GRAIL/MiniGrid-Biased-v0"] is None  # the text gives a range only


def test_a_superseded_default_is_archived_and_a_variant_named():
    page = page_of(rows() + superseded(rows()) + stay_variant(rows()))
    archived = {e["config"].label.split(" · ")[0] for e in page["archive"]}
    assert archived == {"BC-GRAIL"} and sorted(t for e in page["archive"] for t in e["tasks"]) == sorted(
        t.removeprefix("GRAIL/") for t in TASKS)  # one entry per stored hash, which names its tasks
    for entry in page["archive"]:
        assert entry["config"].changes_text == "ent_weight unset" and entry["seeds"] == (0, 1, 2, 3, 4)
        assert entry["runs"] == [0, 1] and entry["rows"] == 5 * sum(len(TASKS[f"GRAIL/{t}"]) for t in entry["tasks"])
    # Out of every board and summary: the archived runs scored 0.1, the canonical ones about 0.8.
    archived_ids = {r["id"] for r in page["records"] if r["kind"] == "archived"}
    shown = {c.record for s in page["sections"] + page["variants"] for row in s.rows for c in row["cells"] if c}
    assert archived_ids and not archived_ids & shown
    assert {c.label for s in page["sections"] for c in s.columns} == {"BC-GRAIL", "GRAQL"}
    minigrid = next(s for s in page["summaries"] if s.domain == "minigrid")
    assert minigrid.names == ["BC-GRAIL", "GRAQL"] and minigrid.mean["BC-GRAIL"] > 0.6
    variants = {c.label for s in page["variants"] for c in s.columns}
    assert variants == {"BC-GRAIL · kl", "BC-GRAIL · off_support stay"}


def every_page(page: dict) -> dict[str, str]:
    """The index's HTML and each domain page's, by file name."""
    return {"index.html": render(page), **{p.file: render(page, domain=p.domain) for p in page["pages"]}}


def test_same_rows_same_page():
    first = every_page(page_of(rows()))
    assert first == every_page(page_of(rows()))
    assert list(first) == ["index.html", "minigrid.html", "panda_reach.html"]


def test_each_domain_page_holds_its_own_boards_and_the_index_links_them(page):
    for p in page["pages"]:
        assert {s.domain for s in p.sections + p.variants} == {p.domain}
    assert sum(len(p.sections) for p in page["pages"]) == len(page["sections"])
    index = render(page)
    assert "section class=\"board\"" not in index and 'href="minigrid.html#s0"' in index
    minigrid = render(page, domain="minigrid")
    assert 'id="summary"' not in minigrid and 'href="index.html#run-' in minigrid  # runs are listed on the index
    taken: set[str] = set()
    from grail_bench.report.html import _page_file

    names = [_page_file(d, taken) for d in ("MiniGrid", "</script>", "index", "minigrid", "")]
    assert names == ["minigrid.html", "script.html", "index-2.html", "minigrid-2.html", "domain.html"]


def test_embedded_json_escapes_markup():
    text = json_for_script({"name": "</script><!--<b>&amp;"})
    assert not {"<", ">", "&"} & set(text)
    assert json.loads(text) == {"name": "</script><!--<b>&amp;"}


def test_embedded_details_cannot_close_the_script(page):
    embedded = []
    for name, html in every_page(page).items():
        assert "bc</script>" not in html
        for ref in ('src="http', "src='http", 'href="http', "href='http", "url(http", "@import"):
            assert ref not in html  # nothing loads from the network
        tag = '<script type="application/json" id="records">'
        if name != "index.html":  # the index has no board, so no details
            start = html.index(tag) + len(tag)
            embedded += [r["id"] for r in json.loads(html[start:html.index("</script>", start)])]
    assert sorted(embedded) == sorted(c.record for c in main_cells(page))  # each main-board cell, on its page


def test_the_page_stays_small_whatever_the_records_hold(page):
    """Full records, fits and figures live beside the page: it embeds only what a cell's details need."""
    for html in every_page(page).values():
        assert len(html.encode()) < 200_000 < MAX_PAGE_BYTES
        assert '"task_params"' not in html and "<svg" not in html  # records.json and figures/ hold them
    assert page["figures"] and all(name.startswith("figures/") for name in page["figures"])


def test_details_embed_thinned_curves_and_rounded_values():
    """Long training curves (a fit logs thousands of points) do not grow the page: each is thinned and rounded."""
    from grail_bench.report.html import CURVE_POINTS

    page = page_of(rows(seeds=2), fits=fit_rows([1 / (i + 3) for i in range(20_000)]))
    (shown,) = [p.fits for p in page["pages"] if p.fits]
    (key,) = shown
    loss = shown[key]["curves"]["0"]["loss"]
    assert len(loss) == CURVE_POINTS and loss[0] == 0.333 and loss[-1] == pytest.approx(1 / 20_002, rel=1e-3)
    assert len(page["fits"][key]["curves"]["0"]["loss"]) == 20_000  # fits.json keeps every point
    assert all(len(html.encode()) < 200_000 for html in every_page(page).values())


def test_online_and_open_set_runs_get_tables_of_their_own(page):
    assert page["studies"] == []  # none stored, none shown
    with_studies = page_of(rows(seeds=2), online=online_rows(), open_set=open_set_rows())
    online, open_set = with_studies["studies"]
    assert (online["id"], open_set["id"]) == ("online", "open-set")
    assert [r["recognizer"] for r in online["rows"]] == ["bc", "graql"]  # one row per recognizer over 3 seeds
    assert with_studies["figures"][online["figure"]].startswith("<svg") and open_set["figure"] is None
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
    assert (out / "index.html").stat().st_size > 0 and list((out / "figures").glob("s*.svg"))
    assert sorted(p.name for p in out.glob("*.html")) == ["index.html", "minigrid.html", "panda_reach.html"]
    records = (out / "records.json").read_text()
    assert len(json.loads(records)) == n_records(rows(seeds=2)) == len(records.splitlines()) - 2  # a record a line
    # Written again without PandaReach's rows: its stale page goes, a page the site did not write stays.
    (out / "notes.html").write_text("<p>my own page</p>")
    with ResultsStore(tmp_path / "minigrid.sqlite") as store:
        store.add([r for r in rows(seeds=2) if "Panda" not in r.task])
    result = CliRunner().invoke(app, ["leaderboard", "--store", str(tmp_path / "minigrid.sqlite"), "--no-ceiling",
                                      "--html", str(out)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.glob("*.html")) == ["index.html", "minigrid.html", "notes.html"]
    assert "BC-GRAIL" in (out / "index.html").read_text()
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


@pytest.fixture(scope="module")
def odd_site(tmp_path_factory) -> Path:
    """A page with a superseded bc configuration, a named variant of bc, and plugins named like markup."""
    out = tmp_path_factory.mktemp("odd-site")
    few = rows(seeds=2)
    write_site(board(few + superseded(few) + stay_variant(few) + odd_names(few)), out)
    return out / "index.html"


def canonical(rs: list[ResultRow]) -> list[ResultRow]:
    """The rows of the methods' canonical configurations in :func:`rows` (bc/kl is a variant)."""
    return [r for r in rs if (r.recognizer, r.scorer) in (("bc", "mse"), ("graql", "kl"))]


@pytest.fixture(scope="module")
def served(odd_site):
    """The odd site's folder served over HTTP on the loopback, at its MiniGrid page (a variant's details are read
    from beside it)."""
    import functools
    import http.server
    import threading

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args) -> None:  # noqa: ANN002
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Quiet, directory=str(odd_site.parent)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_port}/minigrid.html"
    server.shutdown()
    server.server_close()


def domain_pages(site: Path) -> list[Path]:
    """The site's domain pages (every page but the index)."""
    return sorted(p for p in site.parent.glob("*.html") if p.name != "index.html")


def open_page(browser, site: Path | str, **context):
    ctx = browser.new_context(viewport={"width": 1300, "height": 900}, **context)
    page = ctx.new_page()
    errors, requests = [], []
    page.on("console", lambda msg: errors.append(msg.text) if msg.type == "error" else None)
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on("request", lambda req: requests.append(req.url))
    page.goto(site if isinstance(site, str) else site.as_uri())
    page.wait_for_load_state("load")
    return page, errors, requests


def loaded(image) -> bool:
    """Whether a (lazily loaded) figure loads once scrolled to."""
    image.scroll_into_view_if_needed()
    for _ in range(300):  # polled from here: the page's CSP forbids the eval a wait_for_function polls with
        if image.evaluate("i => i.complete"):
            break
        image.page.wait_for_timeout(100)
    return image.evaluate("i => i.naturalWidth") > 0


def test_page_loads_offline_without_errors(browser, site, tmp_path):
    page, errors, requests = open_page(browser, site)
    assert errors == []
    assert requests and all(url.startswith(("file://", "data:")) for url in requests)
    assert page.title() == "grail-bench leaderboard"
    assert page.locator("td.cell").count() == 0 and page.locator("form#filters").is_visible()
    assert page.locator("#boards a[href='minigrid.html']").count() == 1
    page.context.close()
    cells = board_cells = embedded = 0
    for path in domain_pages(site):
        page, errors, requests = open_page(browser, path)
        assert errors == [] and all(url.startswith(("file://", "data:")) for url in requests)
        assert page.title() == f"grail-bench leaderboard: {path.stem}"
        cells += page.locator("td.cell").count()  # main boards and (folded) variants
        board_cells += page.locator("section.board td.cell").count()
        # variants' details are fetched on demand
        embedded += page.evaluate("JSON.parse(document.getElementById('records').textContent).length")
        figures = page.locator("section.board figure img")
        assert all(loaded(figures.nth(i)) for i in range(figures.count()))  # beside the page
        if path.stem == "minigrid":
            assert figures.count() and page.locator("form#filters").is_visible()
            shot = tmp_path / "leaderboard.png"
            page.screenshot(path=str(shot), full_page=True)
            assert shot.stat().st_size > 10_000
        page.context.close()
    assert cells == n_records(rows()) and board_cells == embedded == n_records(canonical(rows()))


def column_values(page, table, col: int) -> list[float | None]:
    texts = table.locator("tbody tr").evaluate_all(
        f"rows => rows.map(r => r.cells[{col}].getAttribute('data-value'))")
    return [float(t) if t else None for t in texts]


def test_sorting_a_column_reorders_rows(browser, site):
    page, errors, _ = open_page(browser, site.parent / "minigrid.html")
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
    page, errors, _ = open_page(browser, site)  # the index: summaries by domain, other modes' tables by recognizer
    page.select_option("select[name=domain]", "panda_reach")
    visible = page.locator(".domain-summary:visible")
    assert visible.count() == 1 and visible.first.get_attribute("data-domain") == "panda_reach"
    page.select_option("select[name=domain]", "")
    page.select_option("select[name=recognizer]", "graql")
    assert page.locator("section.study tbody tr:visible").count() == 2  # graql's online and open-set rows
    assert page.locator("section.study tr[data-recognizer=bc]:visible").count() == 0
    page.select_option("select[name=recognizer]", "")
    assert page.locator("section.study tbody tr:visible").count() == 4
    assert errors == []
    page.context.close()
    page, errors, _ = open_page(browser, site.parent / "minigrid.html")  # a domain's boards by regime, recognizer
    assert page.locator("select[name=domain]").count() == 0
    page.select_option("select[name=regime]", "biased")
    assert page.locator("section.board:visible").count() == 1
    assert page.locator("section.board:visible tbody tr").count() == len(TASKS["GRAIL/MiniGrid-Biased-v0"])
    page.select_option("select[name=regime]", "")
    page.select_option("select[name=recognizer]", "graql")
    minigrid = [r for r in rows() if "Panda" not in r.task]
    assert page.locator("td.cell:visible").count() == n_records([r for r in minigrid if r.recognizer == "graql"])
    assert page.locator("td.cell[data-recognizer=bc]:visible").count() == 0
    page.select_option("select[name=recognizer]", "")
    assert page.locator("td.cell:visible").count() == n_records(canonical(minigrid))  # variants stay folded
    page.locator("details.variant-board summary").first.click()
    assert page.locator("details.variant-board td.cell:visible").count() == n_records(
        [r for r in minigrid if r.scorer == "kl" and r.recognizer == "bc"])
    assert errors == []
    page.context.close()
    panda_rows = len({(r.task, r.protocol, r.observability) for r in rows() if "Panda" in r.task})
    page, errors, _ = open_page(browser, site.parent / "panda_reach.html")
    assert page.locator("section.board:visible tbody tr").count() == panda_rows
    page.context.close()


def test_online_table_sorts_by_value(browser, site):
    page, errors, _ = open_page(browser, site)
    table = page.locator("section#online table")
    col = table.locator("thead th").all_inner_texts().index("step accuracy")
    table.locator("thead th").nth(col).click()
    assert column_values(page, table, col) == pytest.approx([0.8, 0.6])
    table.locator("thead th").nth(col).click()
    assert column_values(page, table, col) == pytest.approx([0.6, 0.8])
    assert loaded(page.locator("section#online figure img"))
    assert errors == []
    page.context.close()


def test_cell_links_to_its_run(browser, site):
    page, _, _ = open_page(browser, site.parent / "minigrid.html")
    page.locator("td.cell a").first.click()
    page.wait_for_load_state("load")
    target = page.evaluate("location.hash")
    assert page.url.split("#")[0].endswith("/index.html")  # runs are listed once, on the index
    assert target.startswith("#run-") and page.locator(f"{target}").is_visible()
    assert "grail-bench run" in page.locator("#run-0").inner_text()
    page.context.close()


def test_a_cell_shows_its_confusion_imitation_and_curves_on_demand(browser, site):
    page, errors, _ = open_page(browser, site.parent / "minigrid.html")
    assert not page.locator("#details").is_visible()
    index = page.evaluate("JSON.parse(document.getElementById('records').textContent).find(r => r.task === "
                          "'GRAIL/MiniGrid-Optimal-v0' && r.column === 'BC-GRAIL' && r.observability === 0.1).id")
    page.locator(f"td.cell[data-record='{index}'] button.diag").click()
    panel = page.locator("#details")
    assert panel.is_visible() and "BC-GRAIL" in page.locator("#details-title").inner_text()
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
    assert page.locator("#summary table").first.is_visible() and page.locator("#claims").is_visible()
    assert not page.locator("form#filters").is_visible()  # nothing to filter with, so not shown
    page.context.close()
    cells = 0
    for path in domain_pages(site):
        page, errors, _ = open_page(browser, path, java_script_enabled=False)
        cells += page.locator("td.cell").count()
        assert page.locator("td.cell").first.is_visible()
        assert not page.locator("form#filters").is_visible()
        assert page.locator("button.diag:visible").count() == 0  # details need the script: no dead buttons
        assert page.locator("figure img").count() >= (path.stem == "minigrid")
        page.context.close()
    assert cells == n_records(rows())


def test_profiles_and_calibration_show_offline(browser, tmp_path):
    from grail_bench.stats.metrics import reliability_bins

    task = "GRAIL/MiniGrid-Optimal-v0"
    records = [offline_record(task, "bc", lv, (0.9, 1.0), scorer="mse") for lv in (0.1, 0.2, 0.3)]
    records += [offline_record(task, "graql", lv, (0.5, 0.7), scorer="kl") for lv in (0.1, 0.2, 0.3)]
    records.append(offline_record(task, "bc", 0.1, (0.8, 0.9), scorer="loglik",
                                  reliability=reliability_bins([0.9, 0.6], [True, False])))
    write_site(leaderboard.build([], None, 50, records=records), tmp_path)
    page, errors, requests = open_page(browser, tmp_path / "index.html")
    page.locator("#profiles-box summary").click()
    assert loaded(page.locator("#profiles img")) and loaded(page.locator("#calibration img"))
    assert "loglik" in page.locator("#calibration table").inner_text()
    assert "optimality gap" in page.locator("#summary").inner_text()
    assert errors == [] and all(url.startswith(("file://", "data:")) for url in requests)
    page.context.close()


def test_first_screen_shows_every_methods_summary_and_the_claims(browser, site):
    page, errors, _ = open_page(browser, site)
    height = page.viewport_size["height"]
    for domain, methods in (("minigrid", {"BC-GRAIL", "GRAQL"}), ("panda_reach", {"BC-GRAIL"})):
        summary = page.locator(f".domain-summary[data-domain={domain}]")
        assert set(summary.locator("tbody td:first-child").all_inner_texts()) == methods
        assert summary.bounding_box()["y"] < height
    claims = page.locator("#claims table").first  # the canonical configurations; the variants folded after
    assert claims.locator("tbody tr").count() >= 1 and claims.bounding_box()["y"] < height
    assert "verdict" in claims.locator("thead").inner_text()
    assert errors == []
    page.context.close()


def test_no_main_board_header_carries_a_hash(browser, site):
    import re

    headers = []
    for path in domain_pages(site):
        page, _, _ = open_page(browser, path)
        headers += page.locator("section.board thead th").all_inner_texts()
        page.context.close()
    hashes = {r.config_hash for r in rows()}
    assert not [h for h in headers if re.search(r"[0-9a-f]{6}", h) or any(x[:6] in h for x in hashes)]
    assert {"BC-GRAIL", "GRAQL"} <= set(headers) and "BC-GRAIL · kl" not in headers


def test_published_page_stays_small(site):
    for path in site.parent.glob("*.html"):  # records.json, fits.json and figures/ hold the rest
        assert path.stat().st_size < 200_000 < MAX_PAGE_BYTES


PUBLISHED = Path(__file__).resolve().parents[1] / "leaderboard" / "site" / "index.html"


@pytest.mark.skipif(not PUBLISHED.exists(), reason="no published page in this checkout")
def test_the_published_page_reads_as_a_ranking(browser):
    """leaderboard/site as published: under its size limit; its first screen, every domain's summary of canonical
    methods and the claims; no main-board header names a configuration by hash."""
    import re

    assert all(p.stat().st_size < MAX_PAGE_BYTES for p in PUBLISHED.parent.glob("*.html"))
    page, errors, _ = open_page(browser, PUBLISHED)
    height = page.viewport_size["height"]
    summaries = page.locator(".domain-summary")
    assert summaries.count() >= 3 and summaries.first.bounding_box()["y"] < height
    methods = set(summaries.locator("tbody td:first-child").all_inner_texts())
    assert {"BC-GRAIL", "GAIL-GRAIL", "AIRL-GRAIL", "GRAQL", "DRACO"} <= methods
    assert not any("·" in m or "archived" in m for m in methods)  # canonical configurations only
    claims = page.locator("#claims table").first
    # Below the summaries (8 comparisons for 5 domains: a domain's methods that share no stratum with all the others
    # get a comparison of their own), within the second screen; the "Claims" link is on the first.
    assert claims.bounding_box()["y"] < 2 * height and "verdict" in claims.locator("thead").inner_text()
    assert errors == []
    page.context.close()
    for path in domain_pages(PUBLISHED):
        page, errors, _ = open_page(browser, path)
        headers = page.locator("section.board thead th").all_inner_texts()
        assert headers and not [h for h in headers if re.search(r"\b[0-9a-f]{6,}\b", h)]
        assert errors == []
        page.context.close()


def test_superseded_and_variant_configurations_on_the_page(browser, odd_site):
    page, errors, _ = open_page(browser, odd_site)
    archive = page.locator("#archive table").inner_text()
    assert "BC-GRAIL · archived" in archive and "ent_weight unset" in archive
    assert "archived" not in page.locator("#summary").inner_text()
    iqm = page.locator(".domain-summary[data-domain=minigrid] tr[data-recognizer=bc] td").nth(1)
    assert float(iqm.inner_text()) > 0.6  # the superseded runs (F1 0.1) do not count
    assert errors == []
    page.context.close()
    page, errors, _ = open_page(browser, odd_site.parent / "minigrid.html")
    assert "archived" not in " ".join(page.locator("section.board thead th").all_inner_texts())
    variants = page.locator("#variants details summary").all_inner_texts()  # named while folded
    variants = " ".join(variants)
    assert "BC-GRAIL · off_support stay" in variants and "BC-GRAIL · kl" in variants
    assert errors == []
    page.context.close()


def test_names_like_markup_render_escaped_and_the_page_still_works(browser, served):
    page, errors, _ = open_page(browser, served)
    assert errors == []
    boards = {name: page.locator("details.variant-board").filter(has=page.locator("summary", has_text=name))
              for name in ODD_NAMES}
    for name, board in boards.items():
        assert board.count() == 1
        board.locator("summary").click()
        assert board.locator("thead th").last.inner_text().startswith(name)  # shown as text, not parsed as markup
    assert page.locator("script").count() == 3  # the two JSON blocks and the page's own script
    # Filters: the plugin named "</script>" has its option and its cells.
    page.select_option("select[name=recognizer]", "</script>")
    assert page.locator("#variants td.cell:visible").count() == len(TASKS["GRAIL/MiniGrid-Optimal-v0"])
    page.select_option("select[name=recognizer]", "")
    # Sorting the odd column, then its details.
    board = boards["<!--<script>"]
    col = board.locator("thead th").count() - 1
    board.locator("thead th").nth(col).click()
    assert board.locator("thead th").nth(col).get_attribute("aria-sort") == "descending"
    board.locator("td.cell button.diag").first.click()
    page.locator("#details-title", has_text="script").wait_for()  # a locator: the page's CSP forbids eval
    assert "<!--<script>" in page.locator("#details-title").inner_text()  # read from records.json
    assert page.locator("#details svg.heatmap").count() == 1  # its confusion
    assert errors == []
    page.context.close()


def test_a_variants_details_from_a_local_file_say_how_to_read_them(browser, odd_site):
    page, errors, _ = open_page(browser, odd_site.parent / "minigrid.html")
    button = page.locator("details.variant-board td.cell button.diag").first
    button.evaluate("b => { b.closest('details').open = true; }")  # unfold the board that holds it
    button.click()
    page.locator("#details").wait_for(state="visible")  # a locator: the page's CSP forbids eval
    assert "serve this folder" in page.locator("#details").inner_text()
    page.context.close()
