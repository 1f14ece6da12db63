"""MkDocs hook: ``<!-- include: PATH -->`` on a page is replaced by that file of the repository.

PATH is relative to the folder of ``mkdocs.yml`` (so the site builds from any working directory); the
Changelog page includes ``CHANGELOG.md`` this way. A missing file fails the build.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

INCLUDE = re.compile(r"^<!-- include: (?P<path>[^ ]+) -->$", re.M)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace each include marker with the named file's text."""
    root = Path(config["config_file_path"]).parent
    return INCLUDE.sub(lambda m: (root / m["path"]).read_text(encoding="utf-8"), markdown)
