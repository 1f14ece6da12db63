"""The README's Python examples work when pasted."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)


def test_readme_has_examples():
    assert len(BLOCKS) >= 2


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_block_runs(index, tmp_path):
    code = BLOCKS[index]
    if "class MyRecognizer" in code:  # a definition: check it satisfies the protocol
        code += ("\nimport grail_bench\nassert isinstance(MyRecognizer(), grail_bench.Recognizer)\n"
                 "from grail_bench.recognizers import register_recognizer\nregister_recognizer('mine', MyRecognizer)\n"
                 "(record, *_) = grail_bench.evaluate('GRAIL/MiniGrid-Biased-v0', ['mine'], seeds=1)\n"
                 "assert record.recognizer == 'mine' and record.scorer == 'default'\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
