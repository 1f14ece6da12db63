"""MkDocs hook: ``<!-- include: PATH -->`` on a page is replaced by that file of the repository.

PATH is relative to the folder of ``mkdocs.yml`` (so the site builds from any working directory); the
Changelog page includes ``CHANGELOG.md`` this way. A missing file fails the build. ``<!-- include-if-present:
PATH -->`` includes a file that may not exist yet (results a script writes, not yet published): when it is
missing, a note says so instead. A file under ``leaderboard/`` links its figures by name (``[x](shifts-slip.png)``,
beside it): those links are pointed at the figures the ``figures`` hook serves (``results/figures/...``).
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path
from typing import Any

INCLUDE = re.compile(r"^<!-- include(?P<optional>-if-present)?: (?P<path>[^ ]+) -->$", re.M)
#: A link to a figure beside the file: ``](name.png)``.
FIGURE_LINK = re.compile(r"\]\((?P<name>[\w.-]+\.png)\)")
#: Where the ``figures`` hook serves ``leaderboard/**/*.png`` (its ``PREFIX``).
FIGURES = "results/figures"


def _included(root: Path, match: re.Match[str], page: str) -> str:
    path = root / match["path"]
    if match["optional"] and not path.is_file():
        return f'!!! note "Not published yet"\n    `{match["path"]}` is not in the repository yet.\n'
    text = path.read_text(encoding="utf-8")
    folder = Path(match["path"]).parent.parts
    if folder[:1] != ("leaderboard",):
        return text
    served = posixpath.relpath(posixpath.join(FIGURES, *folder[1:]), posixpath.dirname(page) or ".")
    return FIGURE_LINK.sub(lambda m: f"]({served}/{m['name']})", text)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace each include marker with the named file's text (or, optional and missing, a note)."""
    root = Path(config["config_file_path"]).parent
    return INCLUDE.sub(lambda m: _included(root, m, page.file.src_uri), markdown)
