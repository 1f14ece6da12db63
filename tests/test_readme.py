"""The Python examples of the README and of the docs site's pages work when pasted.

Every ```python block of README.md and of docs/ (Getting started, the guides and every other page) runs in a
fresh interpreter in an empty folder. A block that needs long training is marked by the line
``<!-- test: skip (why) -->`` right before its fence and is not run; the marker must give a reason. A block
marked ``<!-- test: after the shell block above -->`` runs after the page's previous ```bash block (which makes
its files; run with this interpreter's ``grail-bench`` first on PATH, its store in the folder). Blocks with the
same code (the README repeats a guide's example) run once.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"(?:^(?:(<!-- test: skip(?: \((?P<why>[^)]*)\))? -->)|(?P<after><!-- test: after the shell block "
                   r"above -->))\n)?^```python\n(?P<code>.*?)^```", re.S | re.M)
SHELL = re.compile(r"^```bash\n(?P<code>.*?)^```", re.S | re.M)


def _blocks() -> list:
    seen: set[str] = set()
    params = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for i, match in enumerate(FENCE.finditer(text)):
            code = match["code"]
            if code in seen:
                continue
            seen.add(code)
            setup = ""
            if match["after"]:
                shells = list(SHELL.finditer(text, 0, match.start()))
                assert shells, f"{page.name}: no shell block before a block marked to run after one"
                setup = shells[-1]["code"]
            marks = [pytest.mark.skip(reason=match["why"] or "marked skip")] if match.group(1) else []
            params.append(pytest.param(code, setup, id=f"{page.relative_to(ROOT)}:{i}", marks=marks))
    return params


BLOCKS = _blocks()


def test_readme_and_guides_have_examples():
    ids = [p.id for p in BLOCKS]
    assert sum(i.startswith("README.md") for i in ids) >= 2
    assert any(i.startswith("docs/guides/") for i in ids)


def test_skip_marker_is_recognised_and_needs_a_reason():
    text = "<!-- test: skip (trains for an hour) -->\n```python\nx = 1\n```\n```python\ny = 2\n```\n"
    found = [(m.group(1) is not None, m["why"], m["code"]) for m in FENCE.finditer(text)]
    assert found == [(True, "trains for an hour", "x = 1\n"), (False, None, "y = 2\n")]
    after = "```bash\ntouch f\n```\n<!-- test: after the shell block above -->\n```python\nz = 3\n```\n"
    assert [(m["after"] is not None, m["code"]) for m in FENCE.finditer(after)] == [(True, "z = 3\n")]
    for page in PAGES:  # a marker without a reason, or not right before a python fence, is a mistake
        for line in re.findall(r"^<!-- test: skip.*$", page.read_text(encoding="utf-8"), re.M):
            assert re.fullmatch(r"<!-- test: skip \([^)]+\) -->", line), f"{page.name}: {line}"


@pytest.mark.slow
@pytest.mark.parametrize("code, setup", BLOCKS)
def test_example_block_runs(code, setup, tmp_path):
    if "class MyRecognizer" in code and "register_recognizer" not in code:  # a definition: check it works as one
        code += ("\nimport grail_bench\nassert isinstance(MyRecognizer(), grail_bench.Recognizer)\n"
                 "from grail_bench.recognizers import register_recognizer\nregister_recognizer('mine', MyRecognizer)\n"
                 "(record, *_) = grail_bench.evaluate('GRAIL/MiniGrid-Biased-v0', ['mine'], seeds=1)\n"
                 "assert record.recognizer == 'mine' and record.scorer == 'default'\n")
    if setup:
        env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
               "GRAIL_BENCH_STORE": str(tmp_path / "store.sqlite")}
        made = subprocess.run(["bash", "-e", "-c", setup], capture_output=True, text=True, cwd=tmp_path, env=env,
                              timeout=300)
        assert made.returncode == 0, made.stderr
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
