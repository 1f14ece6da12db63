"""The Python examples of the README and of the docs site's pages work when pasted.

Every ```python block of README.md and of docs/ (Getting started, the guides and every other page) runs in a
fresh interpreter in an empty folder. A block that needs long training is marked by the line
``<!-- test: skip (why) -->`` right before its fence and is not run; the marker must give a reason. Blocks
with the same code (the README repeats a guide's example) run once.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"(?:^(<!-- test: skip(?: \((?P<why>[^)]*)\))? -->)\n)?^```python\n(?P<code>.*?)^```", re.S | re.M)


def _blocks() -> list:
    seen: set[str] = set()
    params = []
    for page in PAGES:
        for i, match in enumerate(FENCE.finditer(page.read_text(encoding="utf-8"))):
            code = match["code"]
            if code in seen:
                continue
            seen.add(code)
            marks = [pytest.mark.skip(reason=match["why"] or "marked skip")] if match.group(1) else []
            params.append(pytest.param(code, id=f"{page.relative_to(ROOT)}:{i}", marks=marks))
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
    for page in PAGES:  # a marker without a reason, or not right before a python fence, is a mistake
        for line in re.findall(r"^<!-- test: skip.*$", page.read_text(encoding="utf-8"), re.M):
            assert re.fullmatch(r"<!-- test: skip \([^)]+\) -->", line), f"{page.name}: {line}"


@pytest.mark.slow
@pytest.mark.parametrize("code", BLOCKS)
def test_example_block_runs(code, tmp_path):
    if "class MyRecognizer" in code and "register_recognizer" not in code:  # a definition: check it works as one
        code += ("\nimport grail_bench\nassert isinstance(MyRecognizer(), grail_bench.Recognizer)\n"
                 "from grail_bench.recognizers import register_recognizer\nregister_recognizer('mine', MyRecognizer)\n"
                 "(record, *_) = grail_bench.evaluate('GRAIL/MiniGrid-Biased-v0', ['mine'], seeds=1)\n"
                 "assert record.recognizer == 'mine' and record.scorer == 'default'\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
