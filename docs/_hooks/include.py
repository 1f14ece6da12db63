"""MkDocs hook: ``<!-- include: PATH -->`` on a page is replaced by that file of the repository.

PATH is relative to the folder of ``mkdocs.yml`` (so the site builds from any working directory); the
Changelog page includes ``CHANGELOG.md`` this way. A missing file fails the build. ``<!-- include-if-present:
PATH -->`` includes a file that may not exist yet (results a script writes, not yet published): when it is
missing, a note says so instead.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

INCLUDE = re.compile(r"^<!-- include(?P<optional>-if-present)?: (?P<path>[^ ]+) -->$", re.M)


def _included(root: Path, match: re.Match[str]) -> str:
    path = root / match["path"]
    if match["optional"] and not path.is_file():
        return f'!!! note "Not published yet"\n    `{match["path"]}` is not in the repository yet.\n'
    return path.read_text(encoding="utf-8")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace each include marker with the named file's text (or, optional and missing, a note)."""
    root = Path(config["config_file_path"]).parent
    return INCLUDE.sub(lambda m: _included(root, m), markdown)
