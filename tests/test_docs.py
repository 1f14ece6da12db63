"""The documentation site builds with ``mkdocs build --strict``, and its generated pages say what the code does.

The build writes into a temporary folder only; the repository is left as it was.
"""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from grail_bench.task import task_ids

ROOT = Path(__file__).resolve().parents[1]


def _text(page: Path) -> str:
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8"))).split())


def _tree() -> set[str]:
    return {str(p.relative_to(ROOT)) for p in ROOT.iterdir()}


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("docs") / "site"
    before = _tree()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
           "NO_MKDOCS_2_WARNING": "1"}
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
                           str(ROOT / "mkdocs.yml"), "--site-dir", str(out)],
                          cwd=out.parent, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-4000:]
    assert _tree() == before, "the docs build wrote into the repository"
    return out


def test_every_page_of_the_nav_is_built(site: Path):
    nav = re.findall(r":\s*([\w/-]+)\.md\s*$|^\s*-\s*([\w/-]+)\.md\s*$",
                     (ROOT / "mkdocs.yml").read_text(encoding="utf-8"), re.M)
    pages = [a or b for a, b in nav]
    assert len(pages) >= 25
    for page in pages:
        folder = site / (page.removesuffix("index") if page.endswith("index") else page)
        assert (folder / "index.html").is_file(), page


def test_task_catalogue_lists_every_registered_task(site: Path):
    text = _text(site / "reference" / "tasks" / "index.html")
    missing = [task for task in task_ids() if task not in text]
    assert not missing, missing[:5]
    assert f"{len(task_ids())} tasks from" in text


def test_cli_reference_documents_every_command_and_its_options(site: Path):
    text = _text(site / "reference" / "cli" / "index.html")
    for command in ("run", "reproduce", "leaderboard", "ceiling", "export", "inspect", "study", "tasks", "list"):
        assert f"grail-bench {command}" in text, command
    assert "--observability" in text and "--workers" in text


def test_api_reference_is_rendered_from_docstrings(site: Path):
    text = _text(site / "reference" / "api" / "index.html")
    for name in ("make_task", "evaluate", "make_recognizer", "observe", "bayes_ceiling", "ResultsStore"):
        assert name in text, name
    assert "Return the" in text  # a docstring's text, not only the names


def test_changelog_page_includes_changelog_md(site: Path):
    first = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8").split("\n## ")[1].splitlines()[0]
    assert first.strip("[]") in _text(site / "changelog" / "index.html")


def test_results_pages_show_the_published_figures(site: Path):
    pages = [site / "results" / name / "index.html" for name in ("minigrid", "beyond", "breadth")]
    pages.append(site / "guides" / "budgets" / "index.html")
    for page in pages:
        sources = re.findall(r'<img[^>]+src="([^"]+\.png)"', page.read_text(encoding="utf-8"))
        assert sources, page
        for src in sources:
            figure = (page.parent / src).resolve()
            assert figure.is_file() and figure.stat().st_size > 1000, src
            published = ROOT / "leaderboard" / figure.relative_to((site / "results" / "figures").resolve())
            assert figure.read_bytes() == published.read_bytes()


def test_the_recognizer_guide_is_generated_from_the_contracts_docstrings(site: Path):
    import inspect

    from grail_bench.core import trajectory
    from grail_bench.recognizers import contract

    text = _text(site / "guides" / "recognizer-plugin" / "index.html")
    words = re.sub(r"\W+", "", text)  # markup splits the text around code
    documented = [contract.Recognizer.fit, contract.Recognizer.score, trajectory.Trajectory, trajectory.goal_horizon]
    documented += [getattr(contract.OptionalCapabilities, n) for n, f in vars(contract.OptionalCapabilities).items()
                   if inspect.isfunction(f) and not n.startswith("_")]
    firsts = [inspect.getdoc(obj).split("\n\n")[0] for obj in documented]
    firsts.append(inspect.getdoc(trajectory).split("**Training demonstrations")[1].split("\n\n")[0])  # the padding
    for first in firsts:
        plain = re.sub(r":\w+:`(?:~(?:\w+\.)*)?([\w.]+)`", r"\1", first)  # as the roles hook shows them
        assert re.sub(r"\W+", "", plain) in words, plain[:80]
    raw = (site / "guides" / "recognizer-plugin" / "index.html").read_text(encoding="utf-8")
    for name in contract.OptionalCapabilities.__annotations__:  # every optional attribute has its entry
        assert f'id="grail_bench.recognizers.contract.OptionalCapabilities.{name}"' in raw, name
    assert not re.search(r":(class|func|meth|attr|mod):", text)  # Sphinx roles read as code


def test_sphinx_roles_read_as_code_on_every_generated_page(site: Path):
    for page in ("reference/api", "guides/recognizer-plugin"):
        assert not re.search(r":(class|func|meth|attr|mod):<code>", (site / page / "index.html").read_text("utf-8"))


def test_an_included_results_file_links_its_figures_where_the_site_serves_them(tmp_path: Path):
    """SHIFTS.md links ``shifts-slip.png`` beside it; included in a Results page, the link points at the figure the
    figures hook serves (``results/figures/<path under leaderboard/>``); other links stay as they are."""
    import importlib.util
    from types import SimpleNamespace

    spec = importlib.util.spec_from_file_location("include_hook", ROOT / "docs" / "_hooks" / "include.py")
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    (tmp_path / "leaderboard" / "open-questions").mkdir(parents=True)
    (tmp_path / "leaderboard" / "open-questions" / "SHIFTS.md").write_text(
        "Figure: [`shifts-slip.png`](shifts-slip.png), [paper](https://example.org/f.png)\n")
    (tmp_path / "NOTES.md").write_text("[x](x.png)\n")
    page = SimpleNamespace(file=SimpleNamespace(src_uri="results/open-questions.md"))
    config = {"config_file_path": str(tmp_path / "mkdocs.yml")}
    text = hook.on_page_markdown("<!-- include-if-present: leaderboard/open-questions/SHIFTS.md -->\n"
                                 "<!-- include: NOTES.md -->", page, config, None)
    assert "[`shifts-slip.png`](figures/open-questions/shifts-slip.png)" in text
    assert "(https://example.org/f.png)" in text and "[x](x.png)" in text
